"""Attitude exclusion zone: the +i_B sensor stays >= FOV/2 + beta away from the sun.

    h_EZ = theta_EZ - FOV/2 - beta      (rad; relative degree 2, enforced as a HOCBF)

theta_EZ = angle(+i_B, r_S). Safest at theta_EZ = pi (sensor anti-sun), where arccos is singular.
"""

from __future__ import annotations

from dataclasses import dataclass

from oracles.constraints.base import Array, BarrierValues, Context, sampled_data_margin, second_order_condition
from oracles.constraints.pointing import sun_pointing
from oracles.model import SENSOR_AXIS_BODY
from rta_attitude.config.schema import BarrierGains, Config


@dataclass(frozen=True)
class ExclusionZone:
    """Sun keep-out cone of the sensor boresight."""

    gains: BarrierGains
    limit_rad: float
    """FOV/2 + beta, rad."""
    margin_rad: float = 0.0
    """Sampled-data margin kept by the barrier (robust preset), rad."""
    name: str = "exclusion_zone"
    relative_degree: int = 2

    @classmethod
    def from_config(cls, cfg: Config) -> ExclusionZone:
        return cls(cfg.barriers["exclusion_zone"], cfg.limits.exclusion_angle_rad,
                   sampled_data_margin(cfg, "exclusion_zone"))

    def safety_value(self, ctx: Context) -> Array:
        return sun_pointing(ctx, SENSOR_AXIS_BODY).theta - self.limit_rad

    def evaluate(self, ctx: Context) -> BarrierValues:
        p = sun_pointing(ctx, SENSOR_AXIS_BODY)
        h = p.theta - self.limit_rad
        psi0 = h - self.margin_rad
        psi1, drift, gain = second_order_condition(psi0, p.theta_dot, p.theta_ddot_drift, p.theta_ddot_gain,
                                                   self.gains)
        return BarrierValues(h, psi0, psi1, drift, gain)
