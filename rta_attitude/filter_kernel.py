"""The filter's per-state pipeline, compiled (numba): screen, build the QP, solve, read the answer.

One call of the ASIF filter on one state (`asif.AsifFilter` is the Python face of this module):

    prepare    the state is checked (finite, quaternion norm in (0.5, 1.5)) and its quaternion
               normalised; rows and box (`barrier_rows.rows_one`); u0 = clip(u_des, lo, hi) is the
               exact QP solution if it meets every enabled row (the fast path, no solver)
    assemble   the QP of `asif` in the form  min 1/2 |z - z0|^2, lower <= C z <= upper, z = [u; s]:
               rows normalised to unit norm, slack variables scaled (delta = s / sqrt(p))
    solve      the exact dual active-set method (`active_set.solve`), every answer checked against
               the rows (`active_set.rows_hold`)
    fallback   a failed QP: `pass_through` (u0), `hold` (u = 0 clipped to the box), `soften` (the QP
               again with every row slacked; u0 if that fails too) or `raise` (flagged; Python raises)
    finish     BC_i at the final u, which box bounds clipped u

`filter_active_set` runs all of it for one state; `filter_active_set_many` for a batch, so a run
inside a Monte Carlo batch and a single run compute the same numbers by construction. With
`filter.solver: proxsuite`, `asif.AsifFilter` calls `prepare`, `assemble`, `extract` and `finish`
around proxsuite instead.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from . import active_set
from .barrier_rows import N_CONSTRAINTS, P_UMAX1, rows_one

Array = NDArray[np.float64]

BIG = active_set.BIG
"""Stand-in for an infinite bound (proxsuite's convention)."""
MIN_ROW_NORM = 1e-12
"""Rows whose gradient in u is smaller than this do not depend on u and are not sent to the QP."""
ACTIVE_MULTIPLIER = 1e-9
"""A row whose multiplier exceeds this at the solution is active (it shapes u)."""

PREP_INVALID, PREP_PASS, PREP_QP = 0, 1, 2
"""What `prepare` found: not a state, u0 is the answer, the QP is needed."""
CODE_PASS, CODE_SOLVED, CODE_FALLBACK = 0, 1, 2
"""Status of a call (asif.STATUS_NAMES)."""
POLICY_PASS_THROUGH, POLICY_HOLD, POLICY_SOFTEN, POLICY_RAISE = 0, 1, 2, 3
POLICIES: tuple[str, ...] = ("pass_through", "hold", "soften", "raise")
"""Fallback policies in code order (params.FALLBACKS)."""
FB_NONE, FB_NON_FINITE, FB_POLICY, FB_INVALID = 0, 1, 2, 3
"""Why a call fell back: not at all, u_des had non-finite entries, the QP failed, not a state."""

# entries of the int64 info vector of a call
(INFO_STATUS, INFO_SOLVER, INFO_CHECK_FAILED, INFO_ITERATIONS, INFO_FALLBACK, INFO_SOFT_SOLVER,
 INFO_SOFT_CHECK_FAILED, INFO_QP_FAILED, INFO_RAISE, N_INFO) = range(10)  # fmt: skip
"""status code; first solver code (-1: not called); its answer failed the row check; iterations of
all solves; FB_* reason; soften solver code (-1: not tried); its check failed; the first QP failed;
the policy is `raise` and the QP failed."""


@numba.njit(cache=True, error_model="numpy")
def prepare(x_in: Array, u_des: Array, P: Array, enabled: NDArray[np.bool_], tol: float, h: Array, psi0: Array,
            psi1: Array, drift: Array, gain: Array, lo: Array, hi: Array, gnorm: Array, u_target: Array,
            uncontrollable: NDArray[np.bool_]) -> tuple[int, bool]:
    """Rows, box and the fast-path test of one state (outputs filled in place).

    Returns (PREP_* code, u_des finite?). u_target is u_des with non-finite entries set to 0
    (the QP's target). For PREP_INVALID rows are zero and the box is U.
    """
    x = x_in.copy()
    valid = True
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            valid = False
    q_norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]) if valid else 0.0
    if not (0.5 < q_norm < 1.5):
        valid = False
    if valid:
        for i in range(4):
            x[i] = x[i] / q_norm
    else:  # evaluate a harmless placeholder; the call is answered as invalid below
        x[:] = 0.0
        x[3] = 1.0
        x[10] = 273.15
    rows_one(x, P, h, psi0, psi1, drift, gain, lo, hi)
    m = drift.shape[0]
    for i in range(m):
        if not math.isfinite(drift[i]):
            valid = False
        for a in range(3):
            if not math.isfinite(gain[i, a]):
                valid = False
    for a in range(3):
        if not (math.isfinite(lo[a]) and math.isfinite(hi[a])):
            valid = False
    finite_des = True
    for a in range(3):
        if math.isfinite(u_des[a]):
            u_target[a] = u_des[a]
        else:
            u_target[a] = 0.0
            finite_des = False
    if not valid:
        drift[:] = 0.0
        gain[:, :] = 0.0
        gnorm[:] = 0.0
        uncontrollable[:] = False
        for a in range(3):
            lo[a] = -P[P_UMAX1 + a]
            hi[a] = P[P_UMAX1 + a]
        return PREP_INVALID, finite_des
    need = not finite_des
    for i in range(m):
        g0, g1, g2 = gain[i, 0], gain[i, 1], gain[i, 2]
        gnorm[i] = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        depends = gnorm[i] > MIN_ROW_NORM
        uncontrollable[i] = enabled[i] and not depends and drift[i] < 0
        if enabled[i] and depends:
            bc0 = drift[i]
            for a in range(3):
                bc0 += gain[i, a] * min(max(u_target[a], lo[a]), hi[a])
            if bc0 < -tol * max(1.0, gnorm[i]):
                need = True
    return (PREP_QP if need else PREP_PASS), finite_des


@numba.njit(cache=True, error_model="numpy")
def assemble(drift: Array, gain: Array, lo: Array, hi: Array, u_target: Array, enabled: NDArray[np.bool_],
             gnorm: Array, slack_weight: Array, soften: bool, soften_weight: float
             ) -> tuple[Array, Array, Array, Array, NDArray[np.int64], NDArray[np.int64], Array, Array]:
    """The QP of one state: min 1/2 |z - z0|^2 s.t. lower <= C z <= upper, z = [u (3); s].

    Rows of disabled constraints and rows that do not depend on u are left out; each slacked row
    (slack_weight > 0, or every row if soften) gets a variable s with delta = s / sqrt(p). Rows are
    normalised to unit norm; the last three rows are the box.

    Returns (C (r+3, n), lower, upper (r+3,), z0 (n,), row_of (r,) constraint index of each row,
    slack_var (m,) variable of each constraint's slack or -1, scale (n,) delta = scale * s (0 for
    u), norms (r+3,) each row was divided by).
    """
    m = drift.shape[0]
    r = 0
    ns = 0
    for i in range(m):
        if enabled[i] and gnorm[i] > MIN_ROW_NORM:
            r += 1
            if slack_weight[i] > 0 or soften:
                ns += 1
    n = 3 + ns
    C = np.zeros((r + 3, n))
    lower = np.full(r + 3, -BIG)
    upper = np.full(r + 3, BIG)
    norms = np.ones(r + 3)
    row_of = np.empty(r, dtype=np.int64)
    slack_var = np.full(m, -1, dtype=np.int64)
    scale = np.zeros(n)
    k = 0
    v = 3
    for i in range(m):
        if not (enabled[i] and gnorm[i] > MIN_ROW_NORM):
            continue
        row_of[k] = i
        for a in range(3):
            C[k, a] = gain[i, a]
        if slack_weight[i] > 0 or soften:
            p = slack_weight[i] if slack_weight[i] > 0 else soften_weight
            scale[v] = 1.0 / math.sqrt(p)
            C[k, v] = scale[v]
            slack_var[i] = v
            v += 1
        ss = 0.0
        for j in range(n):
            ss += C[k, j] * C[k, j]
        norms[k] = math.sqrt(ss)
        for j in range(n):
            C[k, j] = C[k, j] / norms[k]
        lower[k] = -drift[i] / norms[k]
        k += 1
    for a in range(3):
        C[r + a, a] = 1.0
        lower[r + a] = lo[a]
        upper[r + a] = hi[a]
    z0 = np.zeros(n)
    for a in range(3):
        z0[a] = u_target[a]
    return C, lower, upper, z0, row_of, slack_var, scale, norms


@numba.njit(cache=True, error_model="numpy")
def extract(z: Array, mult: Array, lo: Array, hi: Array, row_of: NDArray[np.int64], slack_var: NDArray[np.int64],
            scale: Array, u: Array, slack: Array, intervening: NDArray[np.bool_]) -> None:
    """u (clipped to the box), slack delta_i and the active rows from a QP solution (in place)."""
    for a in range(3):
        u[a] = min(max(z[a], lo[a]), hi[a])
    for k in range(row_of.shape[0]):
        i = row_of[k]
        intervening[i] = abs(mult[k]) > ACTIVE_MULTIPLIER
        if slack_var[i] >= 0:
            slack[i] = scale[slack_var[i]] * z[slack_var[i]]


@numba.njit(cache=True, error_model="numpy")
def finish(drift: Array, gain: Array, u: Array, lo: Array, hi: Array, u_target: Array, bc: Array,
           box_active: NDArray[np.bool_]) -> None:
    """BC_i at the final u (slack not included) and the axes the box clipped (in place)."""
    for i in range(drift.shape[0]):
        bc[i] = drift[i] + (gain[i, 0] * u[0] + gain[i, 1] * u[1] + gain[i, 2] * u[2])
    for a in range(3):
        box_active[a] = (u[a] <= lo[a] and u_target[a] < lo[a]) or (u[a] >= hi[a] and u_target[a] > hi[a])


@numba.njit(cache=True, error_model="numpy")
def _solve_checked(drift: Array, gain: Array, lo: Array, hi: Array, u_target: Array, enabled: NDArray[np.bool_],
                   gnorm: Array, slack_weight: Array, soften: bool, soften_weight: float, max_iter: int, tol: float,
                   info: NDArray[np.int64], solver_entry: int, check_entry: int
                   ) -> tuple[Array, Array, NDArray[np.int64], NDArray[np.int64], Array, bool]:
    """Assemble, solve with the active-set method and check one QP; the solver code, the check
    result and the iterations go into info. Returns (z, multipliers, row_of, slack_var, scale, ok)."""
    C, lower, upper, z0, row_of, slack_var, scale, _norms = assemble(
        drift, gain, lo, hi, u_target, enabled, gnorm, slack_weight, soften, soften_weight)
    z, mult, code, iters = active_set.solve(C, lower, upper, z0, max_iter)
    ok = code == active_set.CODE_SOLVED and active_set.rows_hold(C, lower, upper, z, tol)
    info[solver_entry] = code
    info[check_entry] = 1 if (code == active_set.CODE_SOLVED and not ok) else 0
    info[INFO_ITERATIONS] += iters
    return z, mult, row_of, slack_var, scale, ok


@numba.njit(cache=True, error_model="numpy")
def filter_active_set(x: Array, u_des: Array, P: Array, enabled: NDArray[np.bool_], slack_weight: Array,
                      tol: float, policy: int, soften_weight: float, max_iter: int,
                      u: Array, h: Array, psi0: Array, psi1: Array, bc: Array, slack: Array,
                      intervening: NDArray[np.bool_], box_active: NDArray[np.bool_],
                      uncontrollable: NDArray[np.bool_], lo: Array, hi: Array, info: NDArray[np.int64]) -> None:
    """One whole filter call with the active-set solver; outputs (and info, N_INFO) filled in place."""
    m = h.shape[0]
    drift = np.empty(m)
    gain = np.empty((m, 3))
    gnorm = np.empty(m)
    u_target = np.empty(3)
    info[:] = 0
    info[INFO_SOLVER] = -1
    info[INFO_SOFT_SOLVER] = -1
    slack[:] = 0.0
    intervening[:] = False
    code, finite_des = prepare(x, u_des, P, enabled, tol, h, psi0, psi1, drift, gain, lo, hi, gnorm, u_target,
                               uncontrollable)
    if code == PREP_INVALID:
        # no barrier can be trusted: the wheels hold their speed (u = 0), keeping the body rates
        u[:] = 0.0
        info[INFO_STATUS] = CODE_FALLBACK
        info[INFO_FALLBACK] = FB_INVALID
        finish(drift, gain, u, lo, hi, u_target, bc, box_active)
        h[:] = np.nan
        psi0[:] = np.nan
        psi1[:] = np.nan
        bc[:] = np.nan
        return
    for a in range(3):
        u[a] = min(max(u_target[a], lo[a]), hi[a])
    if code == PREP_QP:
        z, mult, row_of, slack_var, scale, ok = _solve_checked(
            drift, gain, lo, hi, u_target, enabled, gnorm, slack_weight, False, soften_weight, max_iter, tol, info,
            INFO_SOLVER, INFO_CHECK_FAILED)
        fb = FB_NONE if finite_des else FB_NON_FINITE
        if not ok:
            info[INFO_QP_FAILED] = 1
            fb = FB_POLICY
            if policy == POLICY_RAISE:
                info[INFO_RAISE] = 1
            elif policy == POLICY_SOFTEN:
                z, mult, row_of, slack_var, scale, ok = _solve_checked(
                    drift, gain, lo, hi, u_target, enabled, gnorm, slack_weight, True, soften_weight, max_iter, tol,
                    info, INFO_SOFT_SOLVER, INFO_SOFT_CHECK_FAILED)
            if not ok and policy == POLICY_HOLD:
                for a in range(3):
                    u[a] = min(max(0.0, lo[a]), hi[a])
        if ok:
            extract(z, mult, lo, hi, row_of, slack_var, scale, u, slack, intervening)
        info[INFO_FALLBACK] = fb
        info[INFO_STATUS] = CODE_FALLBACK if fb != FB_NONE else CODE_SOLVED
    else:
        info[INFO_STATUS] = CODE_PASS
    finish(drift, gain, u, lo, hi, u_target, bc, box_active)


@numba.njit(cache=True, error_model="numpy")
def filter_active_set_many(X: Array, U_des: Array, P: Array, enabled: NDArray[np.bool_], slack_weight: Array,
                           tol: float, policy: int, soften_weight: float, max_iter: int,
                           u: Array, h: Array, psi0: Array, psi1: Array, bc: Array, slack: Array,
                           intervening: NDArray[np.bool_], box_active: NDArray[np.bool_],
                           uncontrollable: NDArray[np.bool_], lo: Array, hi: Array, info: NDArray[np.int64]) -> None:
    """`filter_active_set` for states X (N, 19) and commands U_des (N, 3); outputs with a leading N."""
    for k in range(X.shape[0]):
        filter_active_set(X[k], U_des[k], P, enabled, slack_weight, tol, policy, soften_weight, max_iter,
                          u[k], h[k], psi0[k], psi1[k], bc[k], slack[k], intervening[k], box_active[k],
                          uncontrollable[k], lo[k], hi[k], info[k])


@numba.njit(cache=True, error_model="numpy")
def is_stationary(C: Array, lower: Array, upper: Array, z: Array, mult: Array, g: Array, tol: float) -> bool:
    """KKT stationarity of a solver's answer to the QP min 1/2 |z|^2 + g.z (H = I): z + g + C' y = 0
    on the u part, with multipliers of the right signs (measured: proxsuite can report SOLVED at a
    point 6 % worse than the optimum when a p = 1e12 slack is present)."""
    for r in range(C.shape[0]):
        if lower[r] <= -BIG / 2 and mult[r] < -tol:
            return False
        if upper[r] >= BIG / 2 and mult[r] > tol:
            return False
    res2 = 0.0
    g2 = 0.0
    for a in range(3):
        v = z[a] + g[a]
        for r in range(C.shape[0]):
            v += C[r, a] * mult[r]
        res2 += v * v
    for j in range(g.shape[0]):
        g2 += g[j] * g[j]
    return math.sqrt(res2) <= tol * (1.0 + math.sqrt(g2))


__all__ = [
    "ACTIVE_MULTIPLIER", "BIG", "CODE_FALLBACK", "CODE_PASS", "CODE_SOLVED", "MIN_ROW_NORM", "N_CONSTRAINTS",
    "N_INFO", "POLICIES", "assemble", "extract", "filter_active_set", "filter_active_set_many", "finish",
    "is_stationary", "prepare",
]  # fmt: skip
