"""Battery charge: E >= E_min.

    h_batt   = E - E_min                       (J; relative degree 3)
    Psi_batt = E - E_min - delta2 theta_SI     (theta_SI: sun incidence on the +k_B panel, [0, pi])

Psi_batt has relative degree 2 and is enforced as a HOCBF.
    E_dot  = P_peak max(0, cos theta_SI) - P_out,   E_ddot = P_peak [cos theta_SI > 0] d/dt cos theta_SI.
Singular (arccos) at theta_SI = 0 (panel on the sun, the safest attitude) and pi.
"""

from __future__ import annotations

from dataclasses import dataclass

from oracles.constraints.base import Array, BarrierValues, Context, sampled_data_margin, second_order_condition
from oracles.constraints.pointing import sun_pointing
from oracles.model import net_power, panel_normal
from rta_attitude.config.schema import BarrierGains, Config
from rta_attitude.dynamics.state import ENERGY

FLOAT32_HALF_ULP = 2.0**-24
"""Largest relative rounding error of a float32 (round to nearest)."""


@dataclass(frozen=True)
class Battery:
    """Lower battery-energy limit through the panel-angle-augmented barrier."""

    gains: BarrierGains
    delta2_J_rad: float
    E_min_J: float
    margin_J: float = 0.0
    """Margin kept by the barrier (robust preset): sampled-data, plus the read energy's error (BatteryState's
    charge is a float32: half an ulp, at most 2^-24 of E, where E is below E_min), J."""
    name: str = "battery"
    relative_degree: int = 2

    @classmethod
    def from_config(cls, cfg: Config) -> Battery:
        read = FLOAT32_HALF_ULP * cfg.limits.energy_min_J if cfg.filter.preset == "robust" else 0.0
        return cls(cfg.barriers["battery"], cfg.augmentation.delta2_J_rad, cfg.limits.energy_min_J,
                   sampled_data_margin(cfg, "battery") + read)

    def safety_value(self, ctx: Context) -> Array:
        return ctx.x[..., ENERGY] - self.E_min_J

    def evaluate(self, ctx: Context) -> BarrierValues:
        p = sun_pointing(ctx, panel_normal(ctx.cfg))
        h = ctx.x[..., ENERGY] - self.E_min_J
        E_dot = net_power(p.cos, ctx.cfg)
        E_ddot = ctx.cfg.power.peak_W * (p.cos > 0) * p.cos_dot
        d2 = self.delta2_J_rad
        psi0 = h - self.margin_J - d2 * p.theta
        psi1, drift, gain = second_order_condition(psi0, E_dot - d2 * p.theta_dot, E_ddot - d2 * p.theta_ddot_drift,
                                                   -d2 * p.theta_ddot_gain, self.gains)
        return BarrierValues(h, psi0, psi1, drift, gain)
