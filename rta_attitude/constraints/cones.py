"""Pointing constraints: every cone of the configuration, keep-out or keep-in, as rows of one table.

For cone j (CONE_DTYPE: boresight e in body axes, a target r, half-angle alpha, sign s = +1 for keep_out
(the boresight stays outside the cone) and -1 for keep_in (inside it)):

    theta = angle(e, r_B)                              rad (`geometry.pointing`; r_B the target in body axes)
    h     = s (theta - alpha)                          the physical safety value (rad; +inf outside a window)
    Psi_0 = h + rho(t) - margin - robust               margin: the robust preset's sampled-data allowance;
                                                       robust: the measurement-robust term (0 without errors)
    Psi_1 = s theta_dot + rho_dot + k1 Psi_0
    BC    = s theta_ddot(u) + k1 (s theta_dot + rho_dot) + k2 Psi_1 + bias >= 0      (relative degree 2, HOCBF)

rho, rho_dot: 0 for a cone without windows; a window's ramp otherwise (`windows`). theta and its rates come
from `geometry.pointing` for any body axis and target (`geometry.target`: the sun with its beta angle, the
Earth, the orbit normal, the velocity, a vector fixed in Hill or in the inertial frame). The safest attitudes
(theta = 0 for a keep-in, pi for a keep-out) are arccos poles: there the angle is held stationary (the pole
guard), and the HOCBF reduces to k1 k2 h > 0.

The paper's exclusion zone is the keep-out cone of the +i_B sensor about the sun (alpha = 40 deg), its
communication the keep-in cone of the +j_B antenna about the Earth (alpha = 90 deg): two entries of the
default configuration, computed here exactly as the paper's formulas (test/test_equivalence.py).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import angle_rate_error, hard, second_order
from rta_attitude.constraints.geometry import angle, pointing, target
from rta_attitude.constraints.windows import INSIDE, OFF, RAMP, window_at
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]


@numba.njit(**LEAF, inline="always")
def signed_h(e: np.void, theta: float) -> float:
    """h of cone e (CONE_DTYPE) at the boresight's angle theta to its target: s (theta - alpha), rad."""
    return e.angle_rad - theta if e.keep_in else theta - e.angle_rad


@numba.njit(**LEAF, inline="always")
def cone_h(j: int, x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, ramped: bool) -> float:
    """The physical h of cone j at state x and time t_s (rad; +inf outside its windows; negative = violated);
    with ramped, ahead of a window its time-varying barrier h + rho(t) instead (`windows`: what the filter
    keeps from the ramp's start, so that h >= 0 when the window opens). ctx: `geometry.context(x, p, False,
    ctx)` has run."""
    e = c.cones[j]
    rho = 0.0
    if e.n_windows > 0:
        phase, rho, _ = window_at(e, t_s)
        if phase != INSIDE and not (ramped and phase == RAMP):
            return math.inf
    r, _, _ = target(e.target, e.vector, x, p, False, ctx)
    h = signed_h(e, angle(e.axis[0], e.axis[1], e.axis[2], r))
    return h + rho if e.n_windows > 0 else h  # (h itself without windows: h + 0.0 would turn -0.0 into 0.0)


@numba.njit(**LEAF)
def safety(x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, rollout: bool, out: Array) -> None:
    """The physical h of every cone into out[0 .. n_cones - 1] (context has run on x). With rollout, what the
    gatekeeper's rollouts keep: +inf for a cone that does not bind hard (`base.hard`), without computing it,
    and ahead of a window the ramped barrier (`cone_h`): a plan that leaves the ramp is one the filter's
    barrier would stop, and it would reach the window outside the cone."""
    for j in range(c.n_cones):
        out[j] = math.inf if rollout and not hard(c, j) else cone_h(j, x, t_s, p, c, ctx, rollout)


@numba.njit(**LEAF)
def _off(tab: np.void, i: int) -> None:
    """Row i switched off (outside its windows): h = +inf, a condition that holds whatever u is."""
    tab.h[i] = math.inf
    tab.psi0[i] = math.inf
    tab.psi1[i] = math.inf
    tab.drift[i] = 0.0
    tab.gain[i, 0] = tab.gain[i, 1] = tab.gain[i, 2] = 0.0


@numba.njit(**LEAF)
def rows(x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, tab: np.void) -> None:
    """h, the HOCBF levels and the barrier row of every cone into table tab, rows 0 .. n_cones - 1
    (`geometry.context(x, p, True, ctx)` has run)."""
    for j in range(c.n_cones):
        e = c.cones[j]
        g = c.gains[j]
        phase, rho, rho_dot = window_at(e, t_s)
        if phase == OFF:
            _off(tab, j)
            continue
        r, rd, rdd = target(e.target, e.vector, x, p, True, ctx)
        _, _, th, th_dot, th_ddot, g0, g1, g2 = pointing(e.axis[0], e.axis[1], e.axis[2], r, rd, rdd, ctx,
                                                         c.sin_pole_guard)
        robust = c.err_att_rad + angle_rate_error(math.sin(th), x, c) / g.k1  # 0 without sensor errors
        if e.keep_in:
            h = e.angle_rad - th
            tab.h[j] = h if phase == INSIDE else math.inf
            second_order(tab, j, h + rho - g.margin - robust, -th_dot + rho_dot, -th_ddot, g)
            tab.gain[j, 0], tab.gain[j, 1], tab.gain[j, 2] = -g0, -g1, -g2
        else:
            h = th - e.angle_rad
            tab.h[j] = h if phase == INSIDE else math.inf
            second_order(tab, j, h + rho - g.margin - robust, th_dot + rho_dot, th_ddot, g)
            tab.gain[j, 0], tab.gain[j, 1], tab.gain[j, 2] = g0, g1, g2


@numba.njit(**LEAF)
def angles(x: Array, p: np.void, c: np.void, ctx: np.void, out: Array) -> None:
    """theta of every cone (its boresight's angle to its target) into out[0 .. n_cones - 1], rad (context has
    run on x)."""
    for j in range(c.n_cones):
        e = c.cones[j]
        r, _, _ = target(e.target, e.vector, x, p, False, ctx)
        out[j] = angle(e.axis[0], e.axis[1], e.axis[2], r)


__all__ = ["angles", "cone_h", "rows", "safety", "signed_h"]
