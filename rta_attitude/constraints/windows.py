"""Scheduled windows: a pointing constraint that applies only in time windows, as a time-varying barrier.

A window [t0, t1] of a cone (sign s = +1 keep_out, -1 keep_in; theta the boresight's angle to the target,
alpha the half-angle) asks for s (theta - alpha) >= 0 for t in [t0, t1] (docs/windows.md derives what
follows). The physical h is s (theta - alpha) inside a window and +inf outside (nothing to keep). The
filter enforces, from the ramp's start t_on to t1, the time-varying HOCBF

    Psi_0 = s (theta - alpha) + rho(t) - margin,   rho(t) = r max(0, t0 - t)
    Psi_1 = s theta_dot + rho_dot + k1 Psi_0,      BC = s theta_ddot(u) + k1 (s theta_dot + rho_dot) + k2 Psi_1

rho relaxes the cone before the window by r per second of lead, so the barrier tightens at the slew rate r
and reaches the cone itself at t0: with Psi_0 >= 0 held, the boresight is where it must be when the window
opens. r (`ramp_rate`) is a fraction (`filter.window_slew_fraction`) of the rate the vehicle can turn a
boresight at, (1 - zoh_margin) omega_max less the target's own motion (n + |n_f|). Any rotation axis is
within the per-axis rate limit at omega_max, and the angular acceleration to reach r takes r / a_min
(a_min: the smallest per-axis acceleration U_i |G_i|), a fraction of a second for the paper's 6U.

The rows switch on at t_on = t0 - rho_on / r (`ramp_start`), with rho_on = pi + margin + robust +
(r + theta_dot_max) / k1 and theta_dot_max = sqrt(3) omega_max + n + |n_f| (|theta_dot| <= |omega| + the
target's rate): then Psi_0 >= (r + theta_dot_max) / k1 > 0 and Psi_1 >= 0 whatever the state, so the
barrier starts inside its own safe set and the invariance argument of the HOCBF holds from t_on. At t0 rho_dot
jumps from -r to 0 (Psi_1 jumps up by r: safer); after t1 the rows switch off. Where windows follow each
other, the earliest one not yet ended is enforced (its rho is the smaller).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rta_attitude.config.schema import Config, PointingConstraint
from rta_attitude.jit import LEAF

OFF, RAMP, INSIDE = 0, 1, 2
"""Where a time is for a cone's windows: no row (before the ramp, between windows, after the last); the
ramp ahead of a window; inside a window (or a cone without windows)."""


def target_rate_bound(cfg: Config) -> float:
    """Bound on a target direction's inertial turn rate, rad/s: the mean motion and the Hill frame's rate."""
    env = cfg.environment
    return env.mean_motion_rad_s + (env.mean_motion_rad_s if env.rotating_hill else 0.0)


def ramp_rate(cfg: Config, cone: PointingConstraint) -> float:
    """r, rad/s: how fast a window's barrier tightens (module docstring); 0 for a cone without windows.

    Raises:
        ValueError: the vehicle cannot turn a boresight faster than the target moves.
    """
    if not cone.windows_s:
        return 0.0
    slew = (1.0 - cfg.filter.zoh_margin) * cfg.limits.omega_max_rad_s - target_rate_bound(cfg)
    if not slew > 0.0:
        raise ValueError(f"constraints.pointing.{cone.name}: the rate limit leaves no slew against the target's "
                         f"motion ({math.degrees(slew):.3g} deg/s)")
    return cfg.filter.window_slew_fraction * slew


def ramp_start(cfg: Config, cone: PointingConstraint, start_s: float) -> float:
    """t_on, s: when the barrier of the window starting at start_s switches on (module docstring)."""
    from rta_attitude.constraints.base import measurement_errors
    from rta_attitude.constraints.margins import sampled_data_margin

    r = ramp_rate(cfg, cone)
    g = cone.gains
    theta_dot_max = math.sqrt(3.0) * cfg.limits.omega_max_rad_s + target_rate_bound(cfg)
    margin = sampled_data_margin(cfg, cone.name)
    robust = 0.0
    if cfg.filter.preset == "robust" and cfg.sensors.enabled:  # the measurement-robust term's largest value
        e = measurement_errors(cfg)
        robust = float(e["err_att_rad"]) + (2.0 * theta_dot_max + float(e["err_omega_rad_s"])) / g.k1
    rho_on = math.pi + margin + robust + (r + theta_dot_max) / g.k1
    return start_s - rho_on / r


@numba.njit(**LEAF, inline="always")
def window_at(e: np.void, t_s: float) -> tuple[int, float, float]:
    """(OFF, RAMP or INSIDE; rho; rho_dot) of cone e (CONE_DTYPE) at time t_s (module docstring)."""
    if e.n_windows == 0:
        return INSIDE, 0.0, 0.0
    for w in range(e.n_windows):
        if t_s > e.window_end_s[w]:
            continue
        if t_s >= e.window_start_s[w]:
            return INSIDE, 0.0, 0.0
        if t_s >= e.window_on_s[w]:
            return RAMP, e.ramp_rad_s * (e.window_start_s[w] - t_s), -e.ramp_rad_s
        return OFF, 0.0, 0.0
    return OFF, 0.0, 0.0


def window_phase(cone: PointingConstraint, cfg: Config, t_s: float) -> str:
    """'off', 'ramp' or 'inside' at t_s: the Python face of `window_at` (reports, tests)."""
    if not cone.windows_s:
        return "inside"
    for start, end in cone.windows_s:
        if t_s > end:
            continue
        if t_s >= start:
            return "inside"
        return "ramp" if t_s >= ramp_start(cfg, cone, start) else "off"
    return "off"


__all__ = ["INSIDE", "OFF", "RAMP", "ramp_rate", "ramp_start", "target_rate_bound", "window_at", "window_phase"]
