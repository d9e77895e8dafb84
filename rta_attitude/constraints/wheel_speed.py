"""Wheel speed, per wheel i: |psi_i| <= psi_max.

With `limits.wheel_speed_relative_to_body` the limit is on the rotor's speed relative to the body, |psi_i +
a_i . omega| <= psi_max (a_i its spin axis; psi is the rotor's inertial rate: docs/conventions.md). h judges
that speed; the rows below keep |psi_i| <= psi_max - omega_max max_i |a_i|_1 (c.psi_max_rad_s,
`Config.psi_keep_rad_s`), which implies it while the rate rows keep |omega_j| <= omega_max: a 3e-5 share of the
wheels' range here, for rows that stay exact (psi is linear over a hold; omega is not).

    h  = psi_max^2 - psi_i^2                (rad^2/s^2; relative degree 1, CBF)
    BC = -2 psi_i u_i + k1 h + bias >= 0

Sampled data (`robust` preset): psi is exactly linear over a held step, so the one-step-ahead
bound |psi_i + u_i dt| <= (1 - zoh_margin) psi_max (`zoh_interval`) keeps the limit at and between
samples.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import speed_limit_row
from rta_attitude.jit import LEAF


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int) -> float:
    """psi_max^2 - v^2 (rad^2/s^2), v = psi_axis (wheel `axis`), or with the limit relative to the body the
    rotor's speed relative to it, psi_axis + a_axis . omega; negative = the wheel is too fast."""
    if c.wheel_speed_relative:
        a = c.wheel_axes
        if a[axis, axis] == 1.0:  # on its body axis (the arithmetic of a wheel per axis)
            v = x[7 + axis] + x[4 + axis]
        else:
            v = x[7 + axis] + (a[0, axis] * x[4] + a[1, axis] * x[5] + a[2, axis] * x[6])
        return c.psi_limit_rad_s**2 - v * v
    return c.psi_limit_rad_s**2 - x[7 + axis] ** 2


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int, t: np.void) -> None:
    """h and the CBF row of one wheel into table t."""
    i = c.row_psi + axis  # psi_dot = u: gain 1, no drift
    speed_limit_row(t, i, axis, x[7 + axis], c.psi_max_rad_s, c.err_psi_rad_s, 1.0, 0.0, c.gains[i])


@numba.njit(**LEAF)
def wheel_speed_error(c: np.void, axis: int) -> float:
    """One reading's error bound on a wheel's speed, rad/s: the tachometer's plus the actuator's over a hold
    (c: the constraint record; 0 without sensor errors). The gatekeeper's rollout margins and its backup
    law's psi_hold use it."""
    return c.err_psi_rad_s + c.err_u_rad_s2[axis] * c.dt_s


@numba.njit(**LEAF)
def zoh_interval(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int) -> tuple[float, float]:
    """(lower, upper) on u_axis, rad/s^2, keeping |psi_axis(t + dt)| <= (1 - zoh_margin) psi_max."""
    # measurement-robust (0 without sensor errors): the tachometer's error now, the actuator's over the hold
    return hold_bounds(x[7 + axis], c.psi_max_rad_s, c.zoh_margin, c.err_psi_rad_s, c.dt_s * c.err_u_rad_s2[axis],
                       c.dt_s)


@numba.njit(**LEAF, inline="always")
def hold_bounds(psi: float, psi_max: float, zoh_margin: float, err_psi: float, err_hold: float, dt: float
                ) -> tuple[float, float]:
    """(lower, upper) on a wheel's acceleration, rad/s^2, keeping its speed psi within (1 - zoh_margin) psi_max
    after a hold of dt (psi is exactly linear over it), err_psi and err_hold (rad/s) clear of it: the tachometer's
    error now and the actuator's over the hold (0 without sensor errors)."""
    limit = (1.0 - zoh_margin) * psi_max - err_psi - err_hold
    return (-limit - psi) / dt, (limit - psi) / dt
