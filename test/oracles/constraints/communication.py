"""Communication: the +j_B antenna stays within FOV/2 of the ground station (the Earth, -x Hill).

    h_comm = FOV/2 - theta_GS      (rad; relative degree 2, HOCBF; the paper's slacked constraint)

Safest at theta_GS = 0 (antenna at Earth), where arccos is singular.
"""

from __future__ import annotations

from dataclasses import dataclass

from oracles.constraints.base import Array, BarrierValues, Context, sampled_data_margin, second_order_condition
from oracles.constraints.pointing import earth_pointing
from oracles.model import ANTENNA_AXIS_BODY
from rta_attitude.config.schema import BarrierGains, Config


@dataclass(frozen=True)
class Communication:
    """Antenna-to-ground-station pointing cone."""

    gains: BarrierGains
    limit_rad: float
    """FOV/2, rad."""
    margin_rad: float = 0.0
    """Sampled-data margin kept by the barrier (robust preset), rad."""
    name: str = "communication"
    relative_degree: int = 2

    @classmethod
    def from_config(cls, cfg: Config) -> Communication:
        return cls(cfg.barriers["communication"], cfg.limits.comm_angle_rad,
                   sampled_data_margin(cfg, "communication"))

    def safety_value(self, ctx: Context) -> Array:
        return self.limit_rad - earth_pointing(ctx, ANTENNA_AXIS_BODY).theta

    def evaluate(self, ctx: Context) -> BarrierValues:
        p = earth_pointing(ctx, ANTENNA_AXIS_BODY)
        h = self.limit_rad - p.theta
        psi0 = h - self.margin_rad
        psi1, drift, gain = second_order_condition(psi0, -p.theta_dot, -p.theta_ddot_drift, -p.theta_ddot_gain,
                                                   self.gains)
        return BarrierValues(h, psi0, psi1, drift, gain)
