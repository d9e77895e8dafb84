"""Angular rate, per body axis i: |omega_i| <= omega_max.

    h = omega_max^2 - omega_i^2        (rad^2/s^2; relative degree 1, CBF)
    BC = -2 omega_i (f_omega,i + G_i u_i) + k1 h + bias,   G_i = sign D / J_i

Sampled data (the `robust` preset): under a zero-order hold over dt the CBF above does not keep
|omega_i| <= omega_max (at omega_i = 0 its gradient vanishes, and one held step can change omega_i
by 2 omega_max). `zoh_bounds` gives the interval of u_i that keeps the one-step-ahead rate
omega_i + (f_omega,i + G_i u_i) dt inside (1 - margin) omega_max; omega is near-linear over a step, so
the limit then holds between samples too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracles.constraints.base import Array, BarrierValues, Context
from rta_attitude.config.schema import BarrierGains, Config
from rta_attitude.dynamics.state import AXES, OMEGA


@dataclass(frozen=True)
class AngularRate:
    """Rate limit on one body axis."""

    gains: BarrierGains
    axis: int
    omega_max_rad_s: float
    control_gain: float
    """G_i = sign D / J_i."""
    name: str = "omega"
    relative_degree: int = 1

    @classmethod
    def from_config(cls, cfg: Config, axis: int) -> AngularRate:
        return cls(cfg.barriers["omega"], axis, cfg.limits.omega_max_rad_s,
                   float(cfg.spacecraft.control_gain[axis]), name=f"omega_{AXES[axis]}")

    def safety_value(self, ctx: Context) -> Array:
        return self.omega_max_rad_s**2 - ctx.x[..., OMEGA.start + self.axis] ** 2

    def evaluate(self, ctx: Context) -> BarrierValues:
        w = ctx.omega[..., self.axis]
        h = self.omega_max_rad_s**2 - w**2
        gain = np.zeros((*ctx.batch_shape, 3))
        gain[..., self.axis] = -2.0 * w * self.control_gain
        drift = -2.0 * w * ctx.omega_drift[..., self.axis] + self.gains.k1 * h + self.gains.bias
        return BarrierValues(h, h, h, drift, gain)

    def zoh_bounds(self, ctx: Context, dt_s: float, margin: float) -> tuple[Array, Array]:
        """(lower, upper) on u_i (...), rad/s^2, keeping |omega_i(t + dt)| <= (1 - margin) omega_max."""
        w = ctx.omega[..., self.axis]
        w_free = w + ctx.omega_drift[..., self.axis] * dt_s
        limit = (1.0 - margin) * self.omega_max_rad_s
        a = (limit - w_free) / (self.control_gain * dt_s)
        b = (-limit - w_free) / (self.control_gain * dt_s)
        return np.minimum(a, b), np.maximum(a, b)
