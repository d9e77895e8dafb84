"""Angular rate, per body axis i: |omega_i| <= omega_max.

    h  = omega_max^2 - omega_i^2                              (rad^2/s^2; relative degree 1, CBF)
    BC = -2 omega_i (f_omega,i + G_i u_i) + k1 h + bias >= 0  G_i = D / J_i, f_omega = omega_dot at u = 0

Sampled data (the `robust` preset): under a zero-order hold over dt the CBF above does not keep
|omega_i| <= omega_max (at omega_i = 0 its gradient vanishes, and one held step can change omega_i by
2 omega_max). With the paper's model, `zoh_interval` gives the interval of u_i that keeps the
one-step-ahead rate omega_i + (f_omega,i + G_i u_i) dt inside (1 - zoh_margin) omega_max; omega is
near-linear over a step, so the limit then holds between samples too.

With the gyrostat model that is not so: the wheels' gyroscopic torque s D omega x psi / J couples the
axes (a command on axis j turns omega_j, and with it the torque on axis i, within the hold; at
|psi| ~ 500 rad/s the coupling's rate D psi / J_i is ~1 rad/s). `zoh_rows` then replaces the per-axis
interval by coupled rows, affine in u, at ZOH_CHECKS times tau of the hold (docs/gyrostat.md):

    omega(tau) = E(tau) omega + Phi(tau) (e0 + G u) + r(tau),   E = exp(Omega tau),  Phi = int_0^tau E
    Omega = s D J^-1 [. x psi]  (the wheel term, linear in omega at the sample's psi)
    e0    = f_omega - Omega omega (Euler's and the gravity-gradient torque at the sample)
    |r_i(tau)| <= sqrt(sum_a J_a L_a^2 / J_i) tau^2 / 2   (E keeps omega^T J omega; L_a bounds de_a/dt)
    |E omega + Phi (e0 + G u)|_i <= (1 - zoh_margin) omega_max - |r_i| - B_i h^2 / 8

B_i bounds |omega_i''| over the hold and h is the spacing of the check points, so omega_i stays
inside (1 - zoh_margin) omega_max between them too (the first spacing dt/8: B h^2/8 there is at most
what the margin leaves).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import ZOH_CHECKS, speed_limit_row
from rta_attitude.dynamics.spacecraft import euler_bound, euler_rate_bound, wheel_vector
from rta_attitude.jit import LEAF


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int) -> float:
    """omega_max^2 - omega_axis^2 (rad^2/s^2); negative = too fast."""
    return c.omega_max_rad_s**2 - x[4 + axis] ** 2


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int, t: np.void) -> None:
    """h and the CBF row of one axis into table t."""
    i = c.row_omega + axis
    speed_limit_row(t, i, axis, x[4 + axis], c.omega_max_rad_s, c.err_omega_axis_rad_s, ctx.control_gain[axis],
                    ctx.omega_drift[axis], c.gains[i])
    if not ctx.diagonal:  # omega_dot_axis = drift + G_axis . u: every wheel turns every axis
        for a in range(3):
            t.gain[i, a] = -2.0 * x[4 + axis] * ctx.control_matrix[axis, a]


@numba.njit(**LEAF)
def zoh_interval(ctx: np.void, x: NDArray[np.float64], c: np.void, axis: int) -> tuple[float, float]:
    """(lower, upper) on u_axis, rad/s^2, keeping |omega_axis(t + dt)| <= (1 - zoh_margin) omega_max."""
    dt = c.dt_s
    cg = ctx.control_gain[axis]
    # measurement-robust (0 without sensor errors): the gyro's error now, the actuator's over the hold
    limit = (1.0 - c.zoh_margin) * c.omega_max_rad_s - c.err_omega_axis_rad_s - abs(cg) * dt * c.err_u_rad_s2[axis]
    limit -= dt * ctx.inertia_err[axis]  # the inertia's uncertainty over the hold (0 without one)
    w_free = x[4 + axis] + ctx.omega_drift[axis] * dt
    ua = (limit - w_free) / (cg * dt)
    ub = (-limit - w_free) / (cg * dt)
    return (ua, ub) if ua < ub else (ub, ua)


ZOH_TIMES = (0.125, 0.25, 0.5, 0.75, 1.0)
"""Check points of `zoh_rows`, fractions of the hold (ZOH_CHECKS of them)."""
ZOH_SPACING = (0.125, 0.25, 0.25, 0.25, 0.25)
"""The longer of the two intervals next to each check point (the next hold starts with 1/8), fractions."""
ZOH_SERIES_TERMS = 30
"""Terms of the exp(Omega tau) series: |Omega| tau <= D psi / J_min dt ~ 1.6 here, 1.6^30 / 31! ~ 1e-28."""


@numba.njit(**LEAF)
def _hold_series(ctx: np.void, tau: float) -> None:
    """ctx.zoh_sum = sum_n (Omega tau)^n / (n + 1)! (Phi = tau sum, E = I + Omega tau sum)."""
    Om, S, T, N = ctx.zoh_omega, ctx.zoh_sum, ctx.zoh_term, ctx.zoh_next
    for r in range(3):
        for q in range(3):
            S[r, q] = 1.0 if r == q else 0.0
            T[r, q] = S[r, q]
    for n in range(1, ZOH_SERIES_TERMS):
        f = tau / (n + 1)
        for r in range(3):
            for q in range(3):
                N[r, q] = (T[r, 0] * Om[0, q] + T[r, 1] * Om[1, q] + T[r, 2] * Om[2, q]) * f
        for r in range(3):
            for q in range(3):
                T[r, q] = N[r, q]
                S[r, q] += N[r, q]


@numba.njit(**LEAF)
def zoh_rows(ctx: np.void, x: NDArray[np.float64], c: np.void, p: np.void, t: np.void) -> None:
    """The coupled zero-order-hold rate rows of state x into t (zoh_rows, zoh_axis, zoh_gain, zoh_lo,
    zoh_hi): in the robust preset, with the rate constraint on and the gyrostat model (p); else none."""
    t.zoh_rows = 0
    if not (c.robust and (p.wheel_gyroscopic or not p.diagonal) and c.gains[c.row_omega].enabled):
        return
    if not p.diagonal:
        _general_zoh_rows(ctx, x, c, p, t)
        return
    dt = c.dt_s
    J = p.inertia_kgm2
    D = p.wheel_inertia_kgm2
    sD = p.torque_sign * D
    G = ctx.control_gain
    U = c.u_max_rad_s2
    w_max = c.omega_max_rad_s
    # Omega w = s D J^-1 (w x psi) at the sample's psi
    p0, p1, p2 = x[7], x[8], x[9]
    Om = ctx.zoh_omega
    Om[0, 0], Om[0, 1], Om[0, 2] = 0.0, sD * p2 / J[0], -sD * p1 / J[0]
    Om[1, 0], Om[1, 1], Om[1, 2] = -sD * p2 / J[1], 0.0, sD * p0 / J[1]
    Om[2, 0], Om[2, 1], Om[2, 2] = sD * p1 / J[2], -sD * p0 / J[2], 0.0
    w = ctx.omega
    # e0 = f_omega - Omega w: Euler and gravity gradient at the sample
    e0_0 = ctx.omega_drift[0] - (Om[0, 1] * w[1] + Om[0, 2] * w[2])
    e0_1 = ctx.omega_drift[1] - (Om[1, 0] * w[0] + Om[1, 2] * w[2])
    e0_2 = ctx.omega_drift[2] - (Om[2, 0] * w[0] + Om[2, 1] * w[1])
    # bounds over the hold: |w_a| <= W_a, |psi_a| <= P_a, |u_a| <= U_a, |w_a'| <= A_a
    ew = c.err_omega_rad_s  # the true rate is within this of the measured one (0 without sensor errors)
    W0, W1, W2 = max(abs(w[0]) + ew, w_max), max(abs(w[1]) + ew, w_max), max(abs(w[2]) + ew, w_max)
    P0, P1, P2 = abs(p0) + U[0] * dt, abs(p1) + U[1] * dt, abs(p2) + U[2] * dt
    k = 3.0 * p.mean_motion_rad_s * p.mean_motion_rad_s if p.gravity_gradient else 0.0
    d0, d1, d2 = abs(J[1] - J[2]), abs(J[2] - J[0]), abs(J[0] - J[1])
    w_rel = math.sqrt(W0 * W0 + W1 * W1 + W2 * W2) + abs(p.frame_rate_rad_s)
    A0 = (d0 * W1 * W2 + D * (W1 * P2 + W2 * P1) + 0.5 * k * d0) / J[0] + abs(G[0]) * U[0]
    A1 = (d1 * W2 * W0 + D * (W2 * P0 + W0 * P2) + 0.5 * k * d1) / J[1] + abs(G[1]) * U[1]
    A2 = (d2 * W0 * W1 + D * (W0 * P1 + W1 * P0) + 0.5 * k * d2) / J[2] + abs(G[2]) * U[2]
    # B_i >= |w_i''| (the rate of f_omega,i); L_a >= |de_a/dt| (e without the frozen wheel term)
    B0 = (d0 * (A1 * W2 + W1 * A2) + D * (A1 * P2 + W1 * U[2] + A2 * P1 + W2 * U[1]) + 2.0 * k * d0 * w_rel) / J[0]
    B1 = (d1 * (A2 * W0 + W2 * A0) + D * (A2 * P0 + W2 * U[0] + A0 * P2 + W0 * U[2]) + 2.0 * k * d1 * w_rel) / J[1]
    B2 = (d2 * (A0 * W1 + W0 * A1) + D * (A0 * P1 + W0 * U[1] + A1 * P0 + W1 * U[0]) + 2.0 * k * d2 * w_rel) / J[2]
    L0 = (d0 * (A1 * W2 + W1 * A2) + D * (W1 * U[2] + W2 * U[1]) + 2.0 * k * d0 * w_rel) / J[0]
    L1 = (d1 * (A2 * W0 + W2 * A0) + D * (W2 * U[0] + W0 * U[2]) + 2.0 * k * d1 * w_rel) / J[1]
    L2 = (d2 * (A0 * W1 + W0 * A1) + D * (W0 * U[1] + W1 * U[0]) + 2.0 * k * d2 * w_rel) / J[2]
    energy = J[0] * L0 * L0 + J[1] * L1 * L1 + J[2] * L2 * L2
    _rows_over_the_hold(ctx, c, t, (e0_0, e0_1, e0_2), (energy / J[0], energy / J[1], energy / J[2]), (B0, B1, B2))


@numba.njit(**LEAF)
def _general_zoh_rows(ctx: np.void, x: NDArray[np.float64], c: np.void, p: np.void, t: np.void) -> None:
    """`zoh_rows` in general: with products of inertia or wheels off the body axes (and with either plant model:
    every wheel turns every axis, so the per-axis interval no longer applies). The same construction with the
    tensor J, J^-1, the full G and the wheels' speeds along the body axes psi_b = A psi:

        Omega = s D J^-1 [. x psi_b]   (0 in the paper's model)
        A_i >= |omega_dot_i|, B_i >= |omega_ddot_i|, L_i >= |de_i/dt|: `general_rate_bounds`
        |r_i| <= sqrt((J^-1)_ii sum_ab |J_ab| L_a L_b) tau^2 / 2   (E keeps w^T J w: J Omega is skew)"""
    dt = c.dt_s
    J, Ji, G = p.inertia_matrix, p.inertia_inverse, ctx.control_matrix
    gyro = p.wheel_gyroscopic != 0
    D = p.wheel_inertia_kgm2 if gyro else 0.0
    sD = p.torque_sign * D
    U = c.u_max_rad_s2
    w_max = c.omega_max_rad_s
    Aw = p.wheel_axes
    p0, p1, p2 = ((wheel_vector(p, x, 0), wheel_vector(p, x, 1), wheel_vector(p, x, 2)) if gyro
                  else (0.0, 0.0, 0.0))
    # Omega w = s D J^-1 (w x psi_b); w x psi_b = C w
    Om = ctx.zoh_omega
    for i in range(3):
        Om[i, 0] = sD * (-Ji[i, 1] * p2 + Ji[i, 2] * p1)
        Om[i, 1] = sD * (Ji[i, 0] * p2 - Ji[i, 2] * p0)
        Om[i, 2] = sD * (-Ji[i, 0] * p1 + Ji[i, 1] * p0)
    w = ctx.omega
    e0 = (ctx.omega_drift[0] - (Om[0, 0] * w[0] + Om[0, 1] * w[1] + Om[0, 2] * w[2]),
          ctx.omega_drift[1] - (Om[1, 0] * w[0] + Om[1, 1] * w[1] + Om[1, 2] * w[2]),
          ctx.omega_drift[2] - (Om[2, 0] * w[0] + Om[2, 1] * w[1] + Om[2, 2] * w[2]))
    ew = c.err_omega_rad_s
    W = (max(abs(w[0]) + ew, w_max), max(abs(w[1]) + ew, w_max), max(abs(w[2]) + ew, w_max))
    # |psi_b| over the hold: sum_i |A_ji| (|psi_i| + U_i dt); |psi_b'| <= sum_i |A_ji| U_i
    Ub = ctx.zoh_term[0]  # scratch (`_hold_series` overwrites it after)
    Pb = ctx.zoh_term[1]
    for j in range(3):
        Ub[j] = abs(Aw[j, 0]) * U[0] + abs(Aw[j, 1]) * U[1] + abs(Aw[j, 2]) * U[2]
        Pb[j] = (abs(Aw[j, 0]) * (abs(x[7]) + U[0] * dt) + abs(Aw[j, 1]) * (abs(x[8]) + U[1] * dt)
                 + abs(Aw[j, 2]) * (abs(x[9]) + U[2] * dt)) if gyro else 0.0
    P = (Pb[0], Pb[1], Pb[2])
    k = 3.0 * p.mean_motion_rad_s * p.mean_motion_rad_s if p.gravity_gradient else 0.0
    w_rel = math.sqrt(W[0] * W[0] + W[1] * W[1] + W[2] * W[2]) + abs(p.frame_rate_rad_s)
    out = ctx.zoh_next  # scratch (no allocation; `_hold_series` reuses it after)
    general_rate_bounds(J, Ji, G, D, W[0], W[1], W[2], P[0], P[1], P[2], U, Ub, c.accel_limit_rad_s2, k, w_rel, 0.0,
                        out)
    Bs = (out[1, 0], out[1, 1], out[1, 2])
    Ls = (out[2, 0], out[2, 1], out[2, 2])
    energy = 0.0
    for a in range(3):
        for b in range(3):
            energy += abs(J[a, b]) * Ls[a] * Ls[b]
    _rows_over_the_hold(ctx, c, t, e0, (energy * Ji[0, 0], energy * Ji[1, 1], energy * Ji[2, 2]), Bs)


@numba.njit(**LEAF)
def general_rate_bounds(J: NDArray[np.float64], Ji: NDArray[np.float64], G: NDArray[np.float64], D: float, W0: float,
                        W1: float, W2: float, P0: float, P1: float, P2: float, U: NDArray[np.float64],
                        Ub: NDArray[np.float64], cap: NDArray[np.float64], k: float, w_rel: float, dJ: float,
                        out: NDArray[np.float64]) -> None:
    """In general (products of inertia, wheels off the body axes), bounds per axis over a hold with u held in the
    box U, for |w_a| <= W_a and the wheels' speeds along the body axes |psi_b,a| <= P_a, |psi_b,a'| <= Ub_a
    (psi_b = A psi; D = 0: the paper's model), into the rows of out (3, 3):

        A_i >= |omega_dot_i|  = sum_j |J^-1_ij| (E_j + D |w x psi_b|_j + k E1_j) + min(sum_j |G_ij| U_j, cap_i)
        B_i >= |omega_ddot_i| = sum_j |J^-1_ij| (E'_j + 2 k w_rel E1_j + D |(w x psi_b)'|_j)
        L_i >= |de_i/dt|: B_i without the wheel term's frozen part (D |w' x psi_b|)

    cap_i: the QP's angular-acceleration row |(G u)_i| <= b_i (`filter.qp.assemble`), which every command these
    bounds serve keeps. E_j, E'_j: `config.inertia.euler_bound`, `euler_rate_bound`; the gravity gradient
    k r x J r with |r_k| <= 1 (E1: the Euler bound at unit rates), its rate 2 w_rel E1 (w_rel: the body's rate
    to the Hill frame). dJ > 0: for every inertia J + dJ with |dJ| <= dJ (its Euler and gravity-gradient torques
    grow by at most dJ |w|^2 and k dJ, their rates by 2 dJ |w| |w_dot| and 2 k w_rel dJ; Ji and G are then bounds on
    every such vehicle's |J^-1| and |G|, `margins.axis_rate_bounds`). The
    per-state bounds of `zoh_rows` (dJ = 0) and the worst case of `margins.axis_rate_bounds` (k = 0, every W and P
    at the limits) both take them from here."""
    W = (W0, W1, W2)
    P = (P0, P1, P2)
    w2 = W0 * W0 + W1 * W1 + W2 * W2
    for j in range(3):  # the torques' bounds, body axes, N m (out[2] as scratch)
        b, d = (j + 1) % 3, (j + 2) % 3
        out[2, j] = (euler_bound(J, W0, W1, W2, j) + D * (W[b] * P[d] + W[d] * P[b])
                     + k * euler_bound(J, 1.0, 1.0, 1.0, j))
        if dJ > 0.0:
            out[2, j] += dJ * (w2 + k)
    for i in range(3):
        a_i = 0.0
        g_i = 0.0
        for j in range(3):
            a_i += abs(Ji[i, j]) * out[2, j]
            g_i += abs(G[i, j]) * U[j]
        out[0, i] = a_i + min(g_i, cap[i])
    A = (out[0, 0], out[0, 1], out[0, 2])
    for j in range(3):  # the torques' rates: with the wheel term (out[1]) and without its frozen part (out[2])
        b, d = (j + 1) % 3, (j + 2) % 3
        eul = euler_rate_bound(J, W0, W1, W2, A[0], A[1], A[2], j) + 2.0 * k * w_rel * euler_bound(J, 1.0, 1.0, 1.0, j)
        if dJ > 0.0:
            eul += 2.0 * dJ * (math.sqrt(w2 * (A[0] * A[0] + A[1] * A[1] + A[2] * A[2])) + k * w_rel)
        out[1, j] = eul + D * (A[b] * P[d] + W[b] * Ub[d] + A[d] * P[b] + W[d] * Ub[b])
        out[2, j] = eul + D * (W[b] * Ub[d] + W[d] * Ub[b])
    rb = (out[1, 0], out[1, 1], out[1, 2])
    rl = (out[2, 0], out[2, 1], out[2, 2])
    for i in range(3):
        out[1, i] = abs(Ji[i, 0]) * rb[0] + abs(Ji[i, 1]) * rb[1] + abs(Ji[i, 2]) * rb[2]
        out[2, i] = abs(Ji[i, 0]) * rl[0] + abs(Ji[i, 1]) * rl[1] + abs(Ji[i, 2]) * rl[2]


@numba.njit(**LEAF, inline="always")
def _phi_g(ctx: np.void, tau: float, i: int, a: int) -> float:
    """(Phi G)_ia = tau (S G)_ia over the hold (ctx.zoh_sum = S): G_a where diagonal, else the full G."""
    if ctx.diagonal:
        return tau * ctx.zoh_sum[i, a] * ctx.control_gain[a]
    return _general_phi_g(ctx, tau, i, a)


@numba.njit(**LEAF)
def _general_phi_g(ctx: np.void, tau: float, i: int, a: int) -> float:
    """`_phi_g` in general."""
    S, G = ctx.zoh_sum, ctx.control_matrix
    return tau * (S[i, 0] * G[0, a] + S[i, 1] * G[1, a] + S[i, 2] * G[2, a])


@numba.njit(**LEAF)
def _rows_over_the_hold(ctx: np.void, c: np.void, t: np.void, e0: tuple[float, float, float],
                        energy_axis: tuple[float, float, float], B: tuple[float, float, float]) -> None:
    """The ZOH_ROWS rows of `zoh_rows` into t from ctx.zoh_omega (Omega), the torques e0 at the sample, the
    remainder's bound squared per axis (energy_axis_i: |r_i| <= sqrt(energy_axis_i) tau^2 / 2) and B_i >=
    |omega_i''| over the hold: at each check point E = I + Omega tau S, Phi = tau S,

        |E omega + Phi (e0 + G u)|_i <= (1 - zoh_margin) omega_max - |r_i| - B_i h^2 / 8 - robust_i

    with robust_i the measurement-robust |E delta_omega|_i + |Phi G delta_u|_i and |Phi e|_i of the inertia's
    error e (`base.inertia_error`; each 0 without sensor errors or an uncertainty)."""
    dt = c.dt_s
    Om, S, w = ctx.zoh_omega, ctx.zoh_sum, ctx.omega
    limit = (1.0 - c.zoh_margin) * c.omega_max_rad_s
    ew_axis, eu = c.err_omega_axis_rad_s, c.err_u_rad_s2
    row = 0
    for m in range(ZOH_CHECKS):
        tau = ZOH_TIMES[m] * dt
        h = ZOH_SPACING[m] * dt
        _hold_series(ctx, tau)
        for i in range(3):
            ew = w[i]
            robust = 0.0
            for a in range(3):
                oms = tau * (Om[i, 0] * S[0, a] + Om[i, 1] * S[1, a] + Om[i, 2] * S[2, a])
                ew += oms * w[a]
                robust += abs((1.0 if a == i else 0.0) + oms) * ew_axis + abs(_phi_g(ctx, tau, i, a)) * eu[a]
                robust += abs(tau * S[i, a]) * ctx.inertia_err[a]
            free = ew + tau * (S[i, 0] * e0[0] + S[i, 1] * e0[1] + S[i, 2] * e0[2])
            slack = limit - math.sqrt(energy_axis[i]) * 0.5 * tau * tau - B[i] * h * h / 8.0 - robust
            t.zoh_axis[row] = i
            for a in range(3):
                t.zoh_gain[row, a] = _phi_g(ctx, tau, i, a)
            t.zoh_lo[row] = -slack - free
            t.zoh_hi[row] = slack - free
            row += 1
    t.zoh_rows = row
