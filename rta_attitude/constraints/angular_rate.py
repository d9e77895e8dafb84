"""Angular rate, per body axis i: |omega_i| <= omega_max.

    h  = omega_max^2 - omega_i^2                              (rad^2/s^2; relative degree 1, CBF)
    BC = -2 omega_i (f_omega,i + G_i u_i) + k1 h + bias >= 0  G_i = D / J_i, f_omega = omega_dot at u = 0

Sampled data (the `robust` preset): under a zero-order hold over dt the CBF above does not keep
|omega_i| <= omega_max (at omega_i = 0 its gradient vanishes, and one held step can change omega_i by
2 omega_max). `zoh_interval` gives the interval of u_i that keeps the one-step-ahead rate
omega_i + (f_omega,i + G_i u_i) dt inside (1 - zoh_margin) omega_max; omega is near-linear over a
step, so the limit then holds between samples too.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import OMEGA_X
from rta_attitude.jit import LEAF

NAMES = ("omega_x", "omega_y", "omega_z")


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int) -> float:
    """omega_max^2 - omega_axis^2 (rad^2/s^2); negative = too fast."""
    return c.omega_max_rad_s**2 - x[4 + axis] ** 2


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int, t: np.void) -> None:
    """h and the CBF row of one axis into table t."""
    i = OMEGA_X + axis
    g = c.gains[i]
    w = x[4 + axis]
    hw = c.omega_max_rad_s**2 - w * w
    t.h[i] = hw
    t.psi0[i] = hw
    t.psi1[i] = hw
    for a in range(3):
        t.gain[i, a] = 0.0
    t.gain[i, axis] = -2.0 * w * ctx.control_gain[axis]
    t.drift[i] = -2.0 * w * ctx.omega_drift[axis] + g.k1 * hw + g.bias


@numba.njit(**LEAF)
def zoh_interval(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int) -> tuple[float, float]:
    """(lower, upper) on u_axis, rad/s^2, keeping |omega_axis(t + dt)| <= (1 - zoh_margin) omega_max."""
    dt = c.dt_s
    cg = ctx.control_gain[axis]
    limit = (1.0 - c.zoh_margin) * c.omega_max_rad_s
    w_free = x[4 + axis] + ctx.omega_drift[axis] * dt
    ua = (limit - w_free) / (cg * dt)
    ub = (-limit - w_free) / (cg * dt)
    return (ua, ub) if ua < ub else (ub, ua)
