"""A pointing constraint (a cone about a target): the numpy twin of rta_attitude.constraints.cones.

    h     = s (theta - alpha)            s = +1 keep_out, -1 keep_in; theta = angle(boresight, target), rad
    Psi_0 = h + rho(t) - margin          rho = r max(0, t0 - t) ahead of a window, 0 inside (windows only)
    Psi_1 = s theta_dot + rho_dot + k1 Psi_0,   BC = s theta_ddot(u) + k1 (s theta_dot + rho_dot) + k2 Psi_1 + bias

With windows the constraint applies within them (h = +inf outside) and its barrier runs from the ramp's start
t_on to the window's end (before t_on and after the end: no condition, Psi = +inf). The ramp's rate and start
are computed here from their definitions (docs/windows.md), not read from the package.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from oracles.constraints.base import Array, BarrierValues, Context, sampled_data_margin, second_order_condition
from oracles.constraints.pointing import axis_pointing
from rta_attitude.config.schema import BarrierGains, Config, PointingConstraint


def ramp(cone: PointingConstraint, cfg: Config) -> tuple[float, float]:
    """(r, rho_on): the rate at which a window's barrier tightens and the relaxation it starts from. r is
    window_slew_fraction of (1 - zoh_margin) omega_max less the target's turn rate (n; the oracle's Hill frame
    is inertial); rho_on = pi + margin + (r + sqrt(3) omega_max + n) / k1 (no sensor errors here)."""
    n = cfg.environment.mean_motion_rad_s
    r = cfg.filter.window_slew_fraction * ((1.0 - cfg.filter.zoh_margin) * cfg.limits.omega_max_rad_s - n)
    margin = sampled_data_margin(cfg, cone.name)
    rho_on = math.pi + margin + (r + math.sqrt(3.0) * cfg.limits.omega_max_rad_s + n) / cone.gains.k1
    return r, rho_on


@dataclass(frozen=True)
class Cone:
    """One configured pointing constraint."""

    spec: PointingConstraint
    gains: BarrierGains
    margin_rad: float
    ramp_rad_s: float
    rho_on_rad: float
    relative_degree: int = 2

    @property
    def name(self) -> str:
        return self.spec.name

    @classmethod
    def from_config(cls, cfg: Config, spec: PointingConstraint) -> Cone:
        r, rho_on = ramp(spec, cfg) if spec.windows_s else (0.0, 0.0)
        return cls(spec, spec.gains, sampled_data_margin(cfg, spec.name), r, rho_on)

    def _sign(self) -> float:
        return -1.0 if self.spec.kind == "keep_in" else 1.0

    def phase(self, t_s: Array) -> tuple[Array, Array, Array, Array]:
        """(inside a window, barrier on, rho, rho_dot) at times t_s (...)."""
        t = np.asarray(t_s, dtype=float)
        if not self.spec.windows_s:
            ones = np.ones(t.shape, dtype=bool)
            return ones, ones, np.zeros(t.shape), np.zeros(t.shape)
        inside = np.zeros(t.shape, dtype=bool)
        on = np.zeros(t.shape, dtype=bool)
        rho = np.zeros(t.shape)
        rho_dot = np.zeros(t.shape)
        settled = np.zeros(t.shape, dtype=bool)  # an earlier window decided it
        for start, end in self.spec.windows_s:
            t_on = start - self.rho_on_rad / self.ramp_rad_s
            here = ~settled & (t <= end)
            inside |= here & (t >= start)
            ramping = here & (t < start) & (t >= t_on)
            on |= here & (t >= t_on)
            rho = np.where(ramping, self.ramp_rad_s * (start - t), rho)
            rho_dot = np.where(ramping, -self.ramp_rad_s, rho_dot)
            settled |= here
        return inside, on, rho, rho_dot

    def _pointing(self, ctx: Context):  # type: ignore[no-untyped-def]
        return axis_pointing(ctx, np.array(self.spec.boresight_body), self.spec.target,
                             None if self.spec.target_vector is None else np.array(self.spec.target_vector))

    def safety_value(self, ctx: Context) -> Array:
        inside, _, _, _ = self.phase(ctx.t_s)
        h = self._sign() * (self._pointing(ctx).theta - self.spec.half_angle_rad)
        return np.where(inside, h, np.inf)

    def evaluate(self, ctx: Context) -> BarrierValues:
        s = self._sign()
        p = self._pointing(ctx)
        inside, on, rho, rho_dot = self.phase(ctx.t_s)
        h = s * (p.theta - self.spec.half_angle_rad)
        psi0 = h + rho - self.margin_rad
        psi1, drift, gain = second_order_condition(psi0, s * p.theta_dot + rho_dot, s * p.theta_ddot_drift,
                                                   s * p.theta_ddot_gain, self.gains)
        off = ~on
        return BarrierValues(np.where(inside, h, np.inf), np.where(off, np.inf, psi0), np.where(off, np.inf, psi1),
                             np.where(off, 0.0, drift), np.where(off[..., None], 0.0, gain))
