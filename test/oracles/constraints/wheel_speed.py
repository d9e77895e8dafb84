"""Wheel speed, per wheel i: |psi_i| <= psi_max.

    h = psi_max^2 - psi_i^2        (rad^2/s^2; relative degree 1, CBF)
    BC = -2 psi_i u_i + k1 h + bias

Sampled data (`robust` preset): psi is exactly linear over a held step, so the one-step-ahead
bound |psi_i + u_i dt| <= (1 - margin) psi_max keeps the limit at and between samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracles.constraints.base import Array, BarrierValues, Context
from rta_attitude.config.schema import BarrierGains, Config
from rta_attitude.dynamics.state import AXES, PSI


@dataclass(frozen=True)
class WheelSpeed:
    """Speed limit of one reaction wheel."""

    gains: BarrierGains
    axis: int
    psi_max_rad_s: float
    name: str = "psi"
    relative_degree: int = 1

    @classmethod
    def from_config(cls, cfg: Config, axis: int) -> WheelSpeed:
        return cls(cfg.barriers["psi"], axis, cfg.limits.psi_max_rad_s, name=f"psi_{AXES[axis]}")

    def safety_value(self, ctx: Context) -> Array:
        return self.psi_max_rad_s**2 - ctx.x[..., PSI.start + self.axis] ** 2

    def evaluate(self, ctx: Context) -> BarrierValues:
        psi = ctx.x[..., PSI.start + self.axis]
        h = self.psi_max_rad_s**2 - psi**2
        gain = np.zeros((*ctx.batch_shape, 3))
        gain[..., self.axis] = -2.0 * psi
        return BarrierValues(h, h, h, self.gains.k1 * h + self.gains.bias, gain)

    def zoh_bounds(self, ctx: Context, dt_s: float, margin: float) -> tuple[Array, Array]:
        """(lower, upper) on u_i (...), rad/s^2, keeping |psi_i(t + dt)| <= (1 - margin) psi_max."""
        psi = ctx.x[..., PSI.start + self.axis]
        limit = (1.0 - margin) * self.psi_max_rad_s
        return (-limit - psi) / dt_s, (limit - psi) / dt_s
