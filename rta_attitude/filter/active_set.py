"""The exact dual active-set solver of the projection QP for ONE problem, compiled (numba).

The filter's QP is a projection: z0 (n,) is the desired input (wheel accelerations in rad/s^2, plus
slack variables), C (m, n) holds the barrier-condition rows and the box rows, normalised to unit
norm, and

    min 1/2 |z - z0|^2   s.t.   lower <= C z <= upper

with bounds at +-BIG (or beyond +-BIG/2) absent. This module solves one such problem per call in
compiled scalar code (a filter call must take microseconds). It ports the vectorised numpy solver
of commit bcaa5df (`batch.solve_projection_qp`), kept verbatim in test/test_active_set.py as the
reference.

Dual active-set method for H = I (Goldfarb & Idnani 1983, "A numerically stable dual method for
solving strictly convex quadratic programs", Math. Prog. 27, 1-33): every two-sided row is split in
two one-sided rows n_j . z >= b_j (index j < m: the lower bound of row j, n_j = C_j, b_j = lower_j;
index m + j: the upper bound, n = -C_j, b = -upper_j). Start at z0 with no active row; add the most
violated one-sided row p (smallest slack n_p . z - b_p among rows with slack < -FEASIBILITY_TOL
max(1, |b_p|), first index on a tie); step along the projection of n_p onto the null space of the
active normals (primal step, length t2) while the active multipliers move along -r (dual step),
dropping the active row whose multiplier reaches zero first (ratio test over r_j > RATIO_TOL, length
t1) until p is active (t = min(t1, t2)); repeat until nothing is violated (optimal) or a violated row
cannot be reached (no primal and no dual step: infeasible). A dropped slot is refilled by the last
slot, so the active rows always fill slots 0..s-1. When the projected normal is (numerically) zero
(|.|^2 <= DEPENDENCE_TOL, or all n slots taken), p depends on the active rows: only the dual step is
taken.

The active normals are orthonormalised (modified Gram-Schmidt, twice: N_A = R Q, R lower triangular)
rather than put in a Gram matrix: the slacked row differs from its barrier row only by a 1e-6 slack
column, and normal equations would square that conditioning. The factorisation is recomputed from
the active rows at every iteration (n <= 5 here), as the numpy version does. At the optimum the
point is polished on its active set (z = z0 + Q^T w, R w = b_A - N_A z, 1 + REFINEMENT_STEPS steps
of iterative refinement) and the multipliers are y = R^-T w; if the polished point leaves a row
violated, the method resumes from it (at most POLISH_ROUNDS rounds; rare: none in 10,000 random
filter-shaped test problems, 2 in 4,000 built for it with nearly parallel rows through the optimum).

Every decision, tolerance, tie-break and sum (in index order, as the numpy version's `_dot_seq`) is
the one of the numpy version, so a problem gives the same numbers here as there: bit for bit (z,
multipliers, code and iteration count, signs of zeros included) on the ~8,500 test problems
(filter-shaped, dependent and nearly parallel rows, resumed ones, iteration limits). The one
possible difference in principle is the sign of a zero: in a numpy batch, the zero slots that
another problem's larger active set adds to the loops contribute +-0 terms. Compiled with
error_model="numpy": a division by zero gives inf/nan as in numpy instead of raising.

Measured on the filter-shaped problems of the tests (m = 13, n = 4, 3.6 iterations on average;
2-core AMD EPYC VM, after compilation): median ~2.9 us per `solve` call from Python, of which ~1.1 us
is numba's dispatch of the five arguments; ~1.5 us per problem when called from compiled code.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.jit import JIT, LEAF

Array = NDArray[np.float64]

BIG = 1e20
"""An absent bound (as `asif.BIG`): bounds at or beyond +-BIG/2 take no part."""

FEASIBILITY_TOL = 1e-12
"""A one-sided row n.z >= b counts as violated when n.z - b < -FEASIBILITY_TOL max(1, |b|)."""
DEPENDENCE_TOL = 1e-16
"""|projected normal|^2 below this (or a full active set): the new row depends on the active rows
(normals have unit norm)."""
RATIO_TOL = 1e-12
"""Active-row coefficients r_j above this take part in the dual step-length test."""
MAX_ACTIVE_SET_ITER = 100
"""Iterations of the active-set solver before a QP is declared failed."""
POLISH_ROUNDS = 3
"""Polish-and-resume rounds of the active-set solver."""
REFINEMENT_STEPS = 2
"""Iterative-refinement steps of the final solve on the active set (the Gram matrix squares the
conditioning of nearly parallel rows)."""

CODE_SOLVED, CODE_INFEASIBLE, CODE_MAX_ITER = 0, 1, 2
"""Return codes of `solve`: optimal / a violated row cannot be reached / max_iter iterations spent."""



# ----------------------------------------------------------------------------- small kernels
@numba.njit(**LEAF)
def _dot(a: Array, b: Array) -> float:
    """sum_k a[k] b[k] in index order (as the numpy version's `_dot_seq`)."""
    out = a[0] * b[0]
    for k in range(1, a.shape[0]):
        out = out + a[k] * b[k]
    return out


@numba.njit(**LEAF)
def _row_dot(A: Array, i: int, b: Array) -> float:
    """_dot(A[i], b) without the row view (a view costs reference counting)."""
    out = A[i, 0] * b[0]
    for k in range(1, A.shape[1]):
        out = out + A[i, k] * b[k]
    return out


@numba.njit(**LEAF)
def _bound(lower: Array, upper: Array, j: int) -> float:
    """b_j of the one-sided row j (j < m: lower_j, else -upper_{j-m})."""
    m = lower.shape[0]
    return lower[j] if j < m else -upper[j - m]


@numba.njit(**LEAF)
def _normal(C: Array, j: int, out: Array, row: int) -> None:
    """out[row] = n_j, the normal of the one-sided row j (j < m: C_j, else -C_{j-m})."""
    m, n = C.shape
    if j < m:
        for k in range(n):
            out[row, k] = C[j, k]
    else:
        for k in range(n):
            out[row, k] = -C[j - m, k]


@numba.njit(**LEAF)
def _is_active(act: Array, j: int) -> bool:
    for a in act:
        if a == j:
            return True
    return False


@numba.njit(**LEAF)
def _most_violated(C: Array, lower: Array, upper: Array, z: Array, act: NDArray[np.int64]) -> int:
    """The inactive one-sided row with the smallest slack among the violated ones (the first index on
    a tie: lower bounds 0..m-1 before upper bounds m..2m-1), or -1 when none is violated."""
    m = C.shape[0]
    best_lo, j_lo, best_up, j_up = math.inf, -1, math.inf, -1
    for i in range(m):
        has_lo, has_up = lower[i] > -BIG / 2, upper[i] < BIG / 2
        if not (has_lo or has_up):
            continue
        Cz = _row_dot(C, i, z)
        if has_lo:
            s = Cz - lower[i]
            if s < -FEASIBILITY_TOL * max(1.0, abs(lower[i])) and s < best_lo and not _is_active(act, i):
                best_lo, j_lo = s, i
        if has_up:
            s = upper[i] - Cz
            if s < -FEASIBILITY_TOL * max(1.0, abs(-upper[i])) and s < best_up and not _is_active(act, m + i):
                best_up, j_up = s, m + i
    if j_lo >= 0 and (j_up < 0 or best_lo <= best_up):
        return j_lo
    return j_up


@numba.njit(**LEAF)
def _argmin(a: Array) -> int:
    """np.argmin: the first minimum, or the first NaN."""
    k = 0
    for i in range(a.shape[0]):
        if a[i] != a[i]:
            return i
        if a[i] < a[k]:
            k = i
    return k


@numba.njit(**LEAF)
def _active_qr(C: Array, act: NDArray[np.int64], s: int, NA: Array, Q: Array, R: Array, v: Array) -> None:
    """Active normals NA[:s] of the slots 0..s-1, NA = R Q with Q's rows orthonormal (modified
    Gram-Schmidt, twice) and R (n, n) lower triangular (the numpy version's `_active_qr` for one problem)."""
    n = C.shape[1]
    for i in range(n):
        for k in range(n):
            R[i, k] = 0.0
            Q[i, k] = 0.0
            NA[i, k] = 0.0
        R[i, i] = 1.0
    for j in range(s):
        _normal(C, act[j], NA, j)
        for k in range(n):
            v[k] = NA[j, k]
        for _ in range(2):
            for i in range(j):
                c = _row_dot(Q, i, v)
                R[j, i] += c
                for k in range(n):
                    v[k] = v[k] - c * Q[i, k]
        nv = math.sqrt(_dot(v, v))
        R[j, j] = nv
        if nv > 0.0:
            for k in range(n):
                Q[j, k] = v[k] / nv


@numba.njit(**LEAF)
def _solve_lower(R: Array, rhs: Array, s: int, w: Array) -> None:
    """Forward substitution R w = rhs on the first s slots (w zero beyond)."""
    w[:] = 0.0
    for j in range(s):
        v = rhs[j]
        for i in range(j):
            v = v - R[j, i] * w[i]
        w[j] = v / R[j, j]


@numba.njit(**LEAF)
def _solve_upper_t(R: Array, rhs: Array, s: int, y: Array) -> None:
    """Back substitution R^T y = rhs on the first s slots (y zero beyond)."""
    y[:] = 0.0
    for i in range(s - 1, -1, -1):
        v = rhs[i]
        for j in range(i + 1, s):
            v = v - R[j, i] * y[j]
        y[i] = v / R[i, i]


@numba.njit(**LEAF)
def _count(act: NDArray[np.int64]) -> int:
    s = 0
    for a in act:
        if a >= 0:
            s += 1
    return s


# ----------------------------------------------------------------------------- the solver
@numba.njit(**JIT)
def solve(C: Array, lower: Array, upper: Array, z0: Array, max_iter: int) -> tuple[Array, Array, int, int]:
    """Exact solution of  min 1/2 |z - z0|^2  s.t.  lower <= C z <= upper  (one problem).

    Args:
        C: constraint rows (m, n), unit norm (zero rows with absent bounds are inert).
        lower, upper: bounds (m,), +-BIG (or beyond +-BIG/2) where absent.
        z0: unconstrained minimiser (n,).
        max_iter: iterations per round before giving up.

    Returns:
        (z (n,), multipliers (m,) with proxsuite's sign convention (negative on an active lower
        bound, positive on an active upper bound, 0 inactive; all 0 unless solved), code
        CODE_SOLVED / CODE_INFEASIBLE / CODE_MAX_ITER, iterations). KKT at the optimum:
        z - z0 = -C^T multipliers.
    """
    m, n = C.shape
    z = z0.astype(np.float64)  # a copy
    mult = np.zeros(m)
    act = np.full(n, -1, dtype=np.int64)  # one-sided row of each slot; slots 0..s-1 used
    mats = np.empty((3, n, n))
    NA, Q, R = mats[0], mats[1], mats[2]
    vecs = np.zeros((9, n))
    y, v, npv, zd, coef, r, ratio, rhs, w = (vecs[0], vecs[1], vecs[2], vecs[3], vecs[4], vecs[5], vecs[6],
                                             vecs[7], vecs[8])
    wl = np.empty(n)
    p = -1
    yp = 0.0
    code = -1
    iters = 0
    for rnd in range(POLISH_ROUNDS):
        for _ in range(max_iter):
            if code >= 0:
                break
            iters += 1
            if p < 0:
                j = _most_violated(C, lower, upper, z, act)
                if j < 0:
                    code = CODE_SOLVED
                    continue
                p = j
                yp = 0.0
            s = _count(act)
            _active_qr(C, act, s, NA, Q, R, v)
            _normal(C, p, vecs, 2)  # npv
            # zd: n_p minus its components along Q (two passes), coef: those components
            for k in range(n):
                zd[k] = npv[k]
                coef[k] = 0.0
            for _pass in range(2):
                for i in range(s):
                    c = _row_dot(Q, i, zd)
                    coef[i] += c
                    for k in range(n):
                        zd[k] = zd[k] - c * Q[i, k]
            _solve_upper_t(R, coef, s, r)  # r: N_A^T r = the part of n_p in the active span
            zz = _dot(zd, zd)
            dep = zz <= DEPENDENCE_TOL or s == n
            sp = _dot(npv, z) - _bound(lower, upper, p)
            t2 = math.inf if dep else -sp / zz
            for i in range(n):
                ratio[i] = y[i] / r[i] if (i < s and r[i] > RATIO_TOL) else math.inf
            ell = _argmin(ratio)
            t1 = ratio[ell]
            t = math.nan if (t1 != t1 or t2 != t2) else min(t1, t2)
            if math.isinf(t):
                code = CODE_INFEASIBLE
                continue
            step = 0.0 if dep else t
            for k in range(n):
                z[k] = z[k] + step * zd[k]
            for i in range(n):
                y[i] = y[i] - t * r[i]
            yp = yp + t
            if t2 <= t1:  # p becomes active
                act[s] = p
                y[s] = yp
                p = -1
            else:  # drop slot ell, refill it with the last slot
                last = s - 1
                act[ell] = act[last]
                y[ell] = y[last]
                act[last] = -1
                y[last] = 0.0
        if code < 0:
            code = CODE_MAX_ITER
        # polish the optimum on its active set (z = z0 + N_A^T y, N_A z = b_A) with iterative
        # refinement; resume the method where that leaves a row violated
        if code != CODE_SOLVED:
            break
        s = _count(act)
        _active_qr(C, act, s, NA, Q, R, v)
        for i in range(n):
            w[i] = 0.0
        for k in range(n):
            z[k] = z0[k]
        for _ in range(1 + REFINEMENT_STEPS if s else 0):
            for i in range(s):
                rhs[i] = _bound(lower, upper, act[i]) - _row_dot(NA, i, z)
            _solve_lower(R, rhs, s, wl)
            for i in range(s):
                w[i] = w[i] + wl[i]
            for k in range(n):
                z[k] = z0[k]
            for i in range(s):
                for k in range(n):
                    z[k] = z[k] + w[i] * Q[i, k]
        _solve_upper_t(R, w, s, y)
        if _most_violated(C, lower, upper, z, act) < 0 or rnd == POLISH_ROUNDS - 1:
            break
        code = -1
    if code == CODE_SOLVED:
        for i in range(n):
            a = act[i]
            if a >= 0:
                if a < m:
                    mult[a] += -1.0 * y[i]
                else:
                    mult[a - m] += 1.0 * y[i]
    return z, mult, code, iters


@numba.njit(**LEAF)
def rows_hold(C: Array, lower: Array, upper: Array, z: Array, tol: float) -> bool:
    """z (n,) finite and lower - tol <= C z <= upper + tol on every row of C (m, n) (C z summed in index
    order; a NaN anywhere fails)."""
    for k in range(z.shape[0]):
        if not math.isfinite(z[k]):
            return False
    for i in range(C.shape[0]):
        Cz = _row_dot(C, i, z)
        if not (Cz >= lower[i] - tol and Cz <= upper[i] + tol):
            return False
    return True


