"""Lockstep batch simulation of many runs: the single-run loop of `simulation.ClosedLoop`, vectorised.

One step of N runs (states held column-wise, "structure of arrays", shape (19, N)):

    rows      BC_i(x, u) = drift_i + gain_i . u of every constraint (a port of `constraints`)
    box       U, intersected with the one-step ZOH bounds in the `robust` preset (`AsifFilter.box`)
    fast path u0 = clip(u_des, lo, hi) where it meets every row (`AsifFilter.filter_batch`)
    QP        the others, all at once: an exact dual active-set solver (Goldfarb-Idnani) for the
              projection QP  min 1/2 |z - z0|^2  s.t.  l <= C z <= u,  vectorised over the batch
    fallback  failed QPs: the `soften` QPs (built by `AsifFilter.qp`) solved together per shape;
              other policies through `AsifFilter._solve_state` state by state
    plant     u -> tau -> u, saturation, RK4 with `cfg.substeps` substeps (`simulation.integrate`)
    checks    h of every constraint at every sample and every substep

Every array operation is the one the single-run code performs, in the same order, so a run inside
the batch reproduces `ClosedLoop.run` bit for bit (the tests check it against the core functions and
against whole runs). The QP solver is the one exception a batch cannot share with proxsuite's
per-state loop cheaply (proxsuite takes ~100 us per 4-variable QP here, and ~45 % of Monte Carlo
state-steps need the QP): `ActiveSetFilter` is `AsifFilter` with this solver, so the single-run
path can use it too, and `solver="proxsuite"` runs the batch through `AsifFilter.filter_batch`
unchanged (bit-identical with `simulate`, several times slower).

Dual active-set method for H = I (Goldfarb & Idnani 1983, Math. Prog. 27): start at z0; add the
most violated one-sided row p; step along the projection of its normal onto the null space of the
active normals, dropping a row when its multiplier reaches zero, until p is active; repeat until
nothing is violated (optimal) or a violated row cannot be reached (infeasible). The active rows are
orthonormalised (modified Gram-Schmidt, twice) rather than put in a Gram matrix: the slacked row
differs from its barrier row only by a 1e-6 slack column, and normal equations would square that
conditioning. The optimum is polished on its active set with iterative refinement. Every sum runs in
index order, so zero-padded rows and variables (the batch) give the same numbers as the compact
problem of one state (`AsifFilter.qp`); states whose compact QP has another number of variables (a
slacked row left out) go through the core path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import model
from .asif import (
    BIG,
    CODE_FALLBACK,
    CODE_SOLVED,
    MIN_ROW_NORM,
    AsifFilter,
    QpProblem,
)
from .constraints import BarrierTable
from .params import CONSTRAINT_NAMES, Config
from .state import ENERGY, OMEGA, PSI, STATE_SIZE, TEMP, THETA_S

Array = NDArray[np.float64]

SOLVERS: tuple[str, ...] = ("active-set", "proxsuite")
"""QP solvers of the batch: the vectorised exact active-set method, or proxsuite state by state."""

FEASIBILITY_TOL = 1e-12
"""A one-sided row n.z >= b counts as violated when n.z - b < -FEASIBILITY_TOL max(1, |b|)."""
DEPENDENCE_TOL = 1e-16
"""|projected normal|^2 below this (or a full active set): the new row depends on the active rows
(normals have unit norm)."""
RATIO_TOL = 1e-12
"""Active-row coefficients r_j above this take part in the dual step-length test."""
MAX_ACTIVE_SET_ITER = 100
POLISH_ROUNDS = 3
"""Polish-and-resume rounds of the active-set solver."""
REFINEMENT_STEPS = 2
"""Iterative-refinement steps of the final solve on the active set (the Gram matrix squares the
conditioning of nearly parallel rows)."""
"""Iterations of the active-set solver before a QP is declared failed."""
SCREEN_MARGIN = 1e-6
"""Angle constraints between samples: cosines this far inside the safe side skip the exact arccos."""

STATUS_SOLVED = "ACTIVE_SET_SOLVED"
STATUS_INFEASIBLE = "ACTIVE_SET_INFEASIBLE"
STATUS_MAX_ITER = "ACTIVE_SET_MAX_ITER"

_EZ, _COMM, _TEMP, _BATT = 0, 1, 2, 3
"""Row indices in CONSTRAINT_NAMES order (omega_x/y/z 4..6, psi_x/y/z 7..9)."""


# ----------------------------------------------------------------------------- active-set QP solver
def _dot_seq(a: Array, b: Array) -> Array:
    """sum_i a[..., i] b[..., i], summed in index order (zero padding leaves it unchanged)."""
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * b[..., i]
    return out


def _active_qr(Nn: Array, sel: NDArray[np.int64], act: NDArray[np.int64]
               ) -> tuple[Array, Array, Array, NDArray[np.bool_]]:
    """Active normals NA (K, s, n) of the problems sel (zero in empty slots), NA = R Q with Q's rows orthonormal
    (modified Gram-Schmidt, twice) and R (K, s, s) lower triangular (identity on empty slots);
    and the slot mask (K, s). Orthogonalising keeps the conditioning of nearly parallel rows
    (the slacked row differs from its barrier only by the 1/sqrt(p) slack column), which a Gram
    matrix would square."""
    K, n = sel.size, Nn.shape[2]
    s = act.shape[1]
    used = act >= 0
    NA = Nn[sel[:, None], np.where(used, act, 0)] * used[..., None]
    Q = np.zeros((K, s, n))
    R = np.zeros((K, s, s))
    R[:, np.arange(s), np.arange(s)] = 1.0
    # slots beyond the largest active set hold zero rows: skipping them changes no number
    for j in range(int(used.sum(axis=1).max(initial=0))):
        v = NA[:, j]
        for _ in range(2):
            for i in range(j):
                c = _dot_seq(v, Q[:, i])
                R[:, j, i] += c
                v = v - c[:, None] * Q[:, i]
        nv = np.sqrt(_dot_seq(v, v))
        good = used[:, j] & (nv > 0.0)
        R[:, j, j] = np.where(used[:, j], nv, 1.0)
        Q[:, j] = np.where(good[:, None], v / np.where(good, nv, 1.0)[:, None], 0.0)
    return NA, Q, R, used


def _project(v: Array, Q: Array, s_used: int) -> tuple[Array, Array]:
    """(v minus its components along Q's first s_used rows, those components (K, s)); two passes."""
    coef = np.zeros((v.shape[0], Q.shape[1]))
    for _ in range(2):
        for i in range(s_used):
            c = _dot_seq(v, Q[:, i])
            coef[:, i] += c
            v = v - c[:, None] * Q[:, i]
    return v, coef


def _solve_lower(R: Array, rhs: Array, s: int) -> Array:
    """Forward substitution R w = rhs on the first s slots, R (K, s', s') lower triangular."""
    w = np.zeros_like(rhs)
    for j in range(s):
        v = rhs[:, j]
        for i in range(j):
            v = v - R[:, j, i] * w[:, i]
        w[:, j] = v / R[:, j, j]
    return w


def _solve_upper_t(R: Array, rhs: Array, s: int) -> Array:
    """Back substitution R^T y = rhs on the first s slots, R (K, s', s') lower triangular."""
    y = np.zeros_like(rhs)
    for i in range(s - 1, -1, -1):
        v = rhs[:, i]
        for j in range(i + 1, s):
            v = v - R[:, j, i] * y[:, j]
        y[:, i] = v / R[:, i, i]
    return y


def solve_projection_qp(C: Array, lower: Array, upper: Array, z0: Array,
                        max_iter: int = MAX_ACTIVE_SET_ITER
                        ) -> tuple[Array, Array, NDArray[np.int8], NDArray[np.int64]]:
    """Exact solution of K projection QPs  min 1/2 |z - z0|^2  s.t.  lower <= C z <= upper.

    Bounds at +-`asif.BIG` (or beyond) are absent. Rows should have unit norm (as `AsifFilter.qp`
    makes them); zero rows with absent bounds are inert, so problems of different sizes can share
    one zero-padded batch and give the same numbers as alone.

    Args:
        C: constraint rows (K, m, n).
        lower, upper: bounds (K, m).
        z0: unconstrained minimiser (K, n).
        max_iter: iterations before giving up.

    Returns:
        (z (K, n), multipliers (K, m) with proxsuite's sign convention (negative on an active lower
        bound, positive on an active upper bound), code (K,) 0 solved / 1 infeasible / 2 too many
        iterations, iterations (K,)).
    """
    C = np.asarray(C, dtype=float)
    K, m, n = C.shape
    Nn = np.concatenate([C, -C], axis=1)  # one-sided: n_j . z >= b_j
    has = np.concatenate([lower > -BIG / 2, upper < BIG / 2], axis=1)
    b = np.where(has, np.concatenate([lower, -upper], axis=1), -np.inf)
    tol = FEASIBILITY_TOL * np.maximum(1.0, np.abs(np.where(has, b, 0.0)))
    z = np.array(z0, dtype=float, copy=True)
    act = np.full((K, n), -1, dtype=np.int64)
    y = np.zeros((K, n))
    p = np.full(K, -1, dtype=np.int64)
    yp = np.zeros(K)
    code = np.full(K, -1, dtype=np.int8)
    iters = np.zeros(K, dtype=np.int64)
    pending = np.ones(K, dtype=bool)
    mult = np.zeros((K, m))
    for _round in range(POLISH_ROUNDS):
        for _ in range(max_iter):
            run = np.flatnonzero(code < 0)
            if run.size == 0:
                break
            iters[run] += 1
            ph1 = run[p[run] < 0]
            if ph1.size:
                if ph1.size == K:  # all of them (the first iteration): no copies
                    Cz = _dot_seq(C, z[:, None, :])
                    s = np.concatenate([Cz - lower, upper - Cz], axis=1)
                    viol = (s < -tol) & has
                else:
                    Cz = _dot_seq(C[ph1], z[ph1][:, None, :])
                    s = np.concatenate([Cz - lower[ph1], upper[ph1] - Cz], axis=1)
                    viol = (s < -tol[ph1]) & has[ph1]
                for slot in range(n):
                    a = act[ph1, slot]
                    has_slot = np.flatnonzero(a >= 0)
                    viol[has_slot, a[has_slot]] = False
                score = np.where(viol, s, np.inf)
                j = np.argmin(score, axis=1)
                found = viol[np.arange(ph1.size), j]
                code[ph1[~found]] = 0
                p[ph1[found]] = j[found]
                yp[ph1[found]] = 0.0
            ph2 = run[(code[run] < 0) & (p[run] >= 0)]
            if ph2.size == 0:
                continue
            _NA, Qa, Ra, used = _active_qr(Nn, ph2, act[ph2])
            s_used = int(used.sum(axis=1).max(initial=0))
            npv = Nn[ph2, p[ph2]]
            zd, coef = _project(npv, Qa, s_used)
            r = _solve_upper_t(Ra, coef, s_used) * used
            zz = _dot_seq(zd, zd)
            dep = (zz <= DEPENDENCE_TOL) | np.all(used, axis=1)
            sp = _dot_seq(npv, z[ph2]) - b[ph2, p[ph2]]
            t2 = np.where(dep, np.inf, -sp / np.where(dep, 1.0, zz))
            pos = used & (r > RATIO_TOL)
            ratio = np.where(pos, y[ph2] / np.where(pos, r, 1.0), np.inf)
            ell = np.argmin(ratio, axis=1)
            t1 = ratio[np.arange(ph2.size), ell]
            t = np.minimum(t1, t2)
            stuck = np.isinf(t)
            code[ph2[stuck]] = 1
            go = ~stuck
            k, tg = ph2[go], t[go]
            step = np.where(dep[go], 0.0, tg)
            z[k] = z[k] + step[:, None] * zd[go]
            y[k] = y[k] - tg[:, None] * r[go]
            yp[k] = yp[k] + tg
            full = t2[go] <= t1[go]
            add = k[full]
            slot = np.sum(act[add] >= 0, axis=1)
            act[add, slot] = p[add]
            y[add, slot] = yp[add]
            p[add] = -1
            drop, ld = k[~full], ell[go][~full]
            last = np.sum(act[drop] >= 0, axis=1) - 1
            act[drop, ld] = act[drop, last]
            y[drop, ld] = y[drop, last]
            act[drop, last] = -1
            y[drop, last] = 0.0
        code[code < 0] = 2
        # polish the optimal ones on their active set (z = z0 + N_A^T y, N_A z = b_A), with
        # iterative refinement; resume the method where that leaves a row violated
        ok = np.flatnonzero((code == 0) & pending)  # a polished problem keeps its numbers
        pending[ok] = False
        if ok.size == 0:
            break
        NA, Qa, Ra, used = _active_qr(Nn, ok, act[ok])
        s_used = int(used.sum(axis=1).max(initial=0))
        bA = np.where(used, b[ok[:, None], np.where(used, act[ok], 0)], 0.0)
        w = np.zeros((ok.size, n))
        zo = z0[ok]
        for _ in range(1 + REFINEMENT_STEPS if s_used else 0):
            w = w + _solve_lower(Ra, bA - _dot_seq(NA, zo[:, None, :]), s_used) * used
            zo = z0[ok]
            for i in range(s_used):
                zo = zo + w[:, i, None] * Qa[:, i]
        z[ok] = zo
        y[ok] = _solve_upper_t(Ra, w, s_used) * used
        Cz = _dot_seq(C[ok], zo[:, None, :])
        viol = (np.concatenate([Cz - lower[ok], upper[ok] - Cz], axis=1) < -tol[ok]) & has[ok]
        for slot in range(n):
            a_ = act[ok, slot]
            has_slot = np.flatnonzero(a_ >= 0)
            viol[has_slot, a_[has_slot]] = False
        again = ok[viol.any(axis=1)]
        if again.size == 0 or _round == POLISH_ROUNDS - 1:
            break
        code[again] = -1
        pending[again] = True
    ok = np.flatnonzero(code == 0)
    if ok.size:
        rows = np.where(act[ok] >= 0, act[ok], 0)
        sign = np.where(rows < m, -1.0, 1.0)
        np.add.at(mult, (np.repeat(ok, n), (rows % m).ravel()), (sign * y[ok] * (act[ok] >= 0)).ravel())
    return z, mult, code, iters


class ActiveSetFilter(AsifFilter):
    """`AsifFilter` whose QP solver is `solve_projection_qp` instead of proxsuite.

    The batch runner (`BatchSimulator(solver="active-set")`) solves the same QPs with the same
    function, so a single run with this filter and a run inside the batch are identical.
    """

    def solve(self, problem: QpProblem) -> tuple[Array | None, Array, str, int]:
        """Solve and verify (as `AsifFilter.solve`). Returns (z or None, multipliers, status, iterations)."""
        if not np.array_equal(problem.H, np.eye(problem.H.shape[0])):
            raise ValueError("ActiveSetFilter solves projection QPs only (H = I)")
        z, mult, code, iters = solve_projection_qp(problem.C[None], problem.lower[None], problem.upper[None],
                                                   -problem.g[None])
        ok = code == 0
        ok &= _rows_hold(problem.C[None], problem.lower[None], problem.upper[None], z, self.options.check_tolerance)
        status = (STATUS_SOLVED, STATUS_INFEASIBLE, STATUS_MAX_ITER)[int(code[0])]
        if code[0] == 0 and not ok[0]:
            status += "_CHECK_FAILED"
        return (z[0] if ok[0] else None), mult[0], status, int(iters[0])


def _rows_hold(C: Array, lower: Array, upper: Array, z: Array, tol: float) -> NDArray[np.bool_]:
    """(K,) True where z (K, n) meets every row of (C, lower, upper) to tol and is finite."""
    Cz = _dot_seq(C, z[:, None, :])
    return np.all(np.isfinite(z), axis=1) & np.all((Cz >= lower - tol) & (Cz <= upper + tol), axis=1)


# ----------------------------------------------------------------------------- constraint rows (SoA)
_Vec = tuple["Array | None", "Array | None", "Array | None"]
"""A 3-vector of (N,) arrays; None is an exact zero (skipped in sums, as x + 0 == x)."""


def _sum(*terms: Array | None) -> Array | None:
    out = None
    for t in terms:
        if t is not None:
            out = t if out is None else out + t
    return out


def _mul(a: Array | float | None, b: Array | None) -> Array | None:
    return None if a is None or b is None else a * b


def _neg(a: Array | None) -> Array | None:
    return None if a is None else -a


def _dot(a: _Vec, b: _Vec) -> Array | None:
    return _sum(_mul(a[0], b[0]), _mul(a[1], b[1]), _mul(a[2], b[2]))


def _sub(a: Array | None, b: Array | None) -> Array | None:
    if b is None:
        return a
    return -b if a is None else a - b


def _cross(a: _Vec, b: _Vec) -> _Vec:
    return (_sub(_mul(a[1], b[2]), _mul(a[2], b[1])), _sub(_mul(a[2], b[0]), _mul(a[0], b[2])),
            _sub(_mul(a[0], b[1]), _mul(a[1], b[0])))


def _axis(v: tuple[float, float, float]) -> _Vec:
    """A unit body axis as a _Vec of scalars (1.0, -1.0) and exact zeros (None)."""
    return tuple(None if c == 0.0 else float(c) for c in v)  # type: ignore[return-value]


def _theta(axis: tuple[float, float, float], r_B: _Vec) -> Array:
    """Angle between a unit body axis and r_B, as `_Rows.pointing_body` computes it."""
    e = _axis(axis)
    m = _cross(e, r_B)
    like = next(v for v in r_B if v is not None)
    return np.arctan2(np.sqrt(_z(_dot(m, m), like)), _z(_dot(e, r_B), like))


@dataclass
class _Pointing:
    cos: Array
    cos_dot: Array
    theta: Array
    theta_dot: Array
    theta_ddot_drift: Array
    theta_ddot_gain: tuple[Array, Array, Array]


def _z(a: Array | None, like: Array) -> Array:
    return np.zeros_like(like) if a is None else a


class _Rows:
    """Barrier rows of a batch, column-wise: a port of constraints.* in the same operation order."""

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.J = cfg.spacecraft.J
        self.cg = cfg.spacecraft.control_gain
        self.n = cfg.environment.mean_motion_rad_s
        self.sin_guard = np.sin(cfg.filter.pole_guard_rad)

    def context(self, X: Array) -> dict[str, object]:
        q1, q2, q3, q4 = X[0], X[1], X[2], X[3]
        s11, s22, s33, s44 = q1 * q1, q2 * q2, q3 * q3, q4 * q4
        A = [[s11 - s22 - s33 + s44, 2.0 * (q1 * q2 + q3 * q4), 2.0 * (q1 * q3 - q2 * q4)],
             [2.0 * (q1 * q2 - q3 * q4), -s11 + s22 - s33 + s44, 2.0 * (q2 * q3 + q1 * q4)],
             [2.0 * (q1 * q3 + q2 * q4), 2.0 * (q2 * q3 - q1 * q4), -s11 - s22 + s33 + s44]]
        w1, w2, w3 = X[4], X[5], X[6]
        J1, J2, J3 = self.J
        wd = ((J2 - J3) * w2 * w3 / J1, (J3 - J1) * w3 * w1 / J2, (J1 - J2) * w1 * w2 / J3)
        th = X[THETA_S]
        cs, sn = np.cos(th), np.sin(th)
        n = self.n
        sun = (cs, sn, None)
        sun_dot = (-n * -sn, -n * cs, None)
        sun_ddot = (-(n**2) * cs, -(n**2) * sn, None)
        return {"A": A, "w": (w1, w2, w3), "wd": wd, "sun": sun, "sun_dot": sun_dot, "sun_ddot": sun_ddot}

    @staticmethod
    def _rotate(A: list[list[Array]], t: _Vec) -> _Vec:
        return tuple(_sum(_mul(A[i][0], t[0]), _mul(A[i][1], t[1]), _mul(A[i][2], t[2]))  # type: ignore[return-value]
                     for i in range(3))

    def pointing(self, ctx: dict[str, object], axis: tuple[float, float, float], target: _Vec,
                 target_dot: _Vec, target_ddot: _Vec) -> _Pointing:
        """`constraints.pointing.pointing` for a Hill-frame target."""
        A = ctx["A"]
        return self.pointing_body(ctx, axis, self._rotate(A, target), self._rotate(A, target_dot),  # type: ignore[arg-type]
                                  self._rotate(A, target_ddot))  # type: ignore[arg-type]

    def pointing_body(self, ctx: dict[str, object], axis: tuple[float, float, float], r_B: _Vec, rd_B: _Vec,
                      rdd_B: _Vec) -> _Pointing:
        """`constraints.pointing.pointing` with the target and its rates already in body axes."""
        w: _Vec = ctx["w"]  # type: ignore[assignment]
        wd: _Vec = ctx["wd"]  # type: ignore[assignment]
        e = _axis(axis)
        m = _cross(e, r_B)
        c = _dot(e, r_B)
        c_dot = _sum(_dot(w, m), _dot(e, rd_B))
        wxr = _cross(w, r_B)
        c_dd_drift = _sum(_dot(wd, m), _dot(w, _cross(e, (_neg(wxr[0]), _neg(wxr[1]), _neg(wxr[2])))),
                          _mul(2.0, _dot(w, _cross(e, rd_B))), _dot(e, rdd_B))
        like: Array = w[0]  # type: ignore[assignment]
        c, c_dot, c_dd_drift = _z(c, like), _z(c_dot, like), _z(c_dd_drift, like)
        gain = tuple(_z(_mul(m[i], self.cg[i]), like) for i in range(3))
        sin_raw = np.sqrt(_z(_dot(m, m), like))
        theta = np.arctan2(sin_raw, c)
        away = sin_raw > self.sin_guard
        s = np.where(away, sin_raw, 1.0)
        theta_dot = np.where(away, -c_dot / s, 0.0)
        th_dd_drift = np.where(away, -c_dd_drift / s - c * c_dot**2 / s**3, 0.0)
        th_dd_gain = (np.where(away, -gain[0] / s, 0.0), np.where(away, -gain[1] / s, 0.0),
                      np.where(away, -gain[2] / s, 0.0))
        return _Pointing(c, c_dot, theta, theta_dot, th_dd_drift, th_dd_gain)

    def evaluate(self, X: Array) -> tuple[Array, Array, Array]:
        """(h (N, m), drift (N, m), gain (N, m, 3)) of states X (19, N), equal to ConstraintSet.evaluate."""
        cfg = self.cfg
        N = X.shape[1]
        ctx = self.context(X)
        h = np.empty((N, 10))
        drift = np.empty((N, 10))
        gain = np.zeros((N, 10, 3))
        A = ctx["A"]
        zero: _Vec = (None, None, None)

        def second(i: int, psi0: Array, d1: Array, dd: Array, g: tuple[Array, Array, Array], k: str) -> None:
            gains = cfg.barriers[k]
            psi1 = d1 + gains.k1 * psi0
            drift[:, i] = dd + gains.k1 * d1 + gains.k2 * psi1 + gains.bias
            for a in range(3):
                gain[:, i, a] = g[a]

        def margin(group: str) -> float:
            # constraints.base.sampled_data_margin: HOCBFs keep h >= margin in the robust preset
            return float(getattr(cfg.barriers[group], "margin", 0.0)) if cfg.filter.preset == "robust" else 0.0

        sun, sun_dot, sun_ddot = ctx["sun"], ctx["sun_dot"], ctx["sun_ddot"]
        # exclusion zone: +i_B to the sun
        p = self.pointing(ctx, tuple(model.SENSOR_AXIS_BODY), sun, sun_dot, sun_ddot)  # type: ignore[arg-type]
        hz = p.theta - cfg.limits.exclusion_angle_rad
        h[:, _EZ] = hz
        second(_EZ, hz - margin("exclusion_zone"), p.theta_dot, p.theta_ddot_drift, p.theta_ddot_gain,
               "exclusion_zone")
        # communication: +j_B to the Earth [-1, 0, 0] (A r_E = -A[:, 0], exactly)
        r_E: _Vec = (-A[0][0], -A[1][0], -A[2][0])  # type: ignore[index]
        pc = self.pointing_body(ctx, tuple(model.ANTENNA_AXIS_BODY), r_E, zero, zero)
        hc = cfg.limits.comm_angle_rad - pc.theta
        h[:, _COMM] = hc
        g_c = tuple(-g for g in pc.theta_ddot_gain)
        second(_COMM, hc - margin("communication"), -pc.theta_dot, -pc.theta_ddot_drift, g_c,  # type: ignore[arg-type]
               "communication")
        # temperature: -j_B face, sun and Earth incidence
        th, env = cfg.thermal, cfg.environment
        ps = self.pointing(ctx, tuple(model.THERMAL_FACE_NORMAL_BODY), sun, sun_dot, sun_ddot)  # type: ignore[arg-type]
        pe = self.pointing_body(ctx, tuple(model.THERMAL_FACE_NORMAL_BODY), r_E, zero, zero)
        T = X[TEMP]
        heat_capacity = th.mass_kg * th.specific_heat_J_kgK
        T_dot = model.thermal_fluxes(ps.cos, pe.cos, T, cfg) / heat_capacity
        solar = th.absorptivity * th.area_m2 * env.solar_constant_W_m2
        earth_coeff = (solar * env.albedo_factor
                       + env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * env.earth_temperature_K**4)
        earth_on = (pe.cos > 0) if th.clamp_view_factor else np.ones_like(pe.cos, dtype=bool)
        T_ddot = (solar * (ps.cos > 0) * ps.cos_dot
                  + earth_coeff * env.earth_view_factor * earth_on * pe.cos_dot
                  - 4 * env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * T**3 * T_dot) / heat_capacity
        aug = cfg.augmentation
        d0, d1 = aug.delta0_K_rad, aug.delta1_K_rad
        sun_on = ps.theta < np.pi / 2
        earth_in = pe.theta < np.pi / 2
        ht = cfg.limits.temperature_max_K - T
        h[:, _TEMP] = ht
        psi0 = (ht - margin("temperature") - d0 * np.maximum(0.0, np.pi / 2 - ps.theta)
                - d1 * np.maximum(0.0, np.pi / 2 - pe.theta))
        psi0_dot = -T_dot + d0 * sun_on * ps.theta_dot + d1 * earth_in * pe.theta_dot
        psi0_dd = -T_ddot + d0 * sun_on * ps.theta_ddot_drift + d1 * earth_in * pe.theta_ddot_drift
        g_t = tuple(d0 * sun_on * ps.theta_ddot_gain[a] + d1 * earth_in * pe.theta_ddot_gain[a] for a in range(3))
        second(_TEMP, psi0, psi0_dot, psi0_dd, g_t, "temperature")  # type: ignore[arg-type]
        # battery: +k_B panel to the sun
        pb = self.pointing(ctx, tuple(model.PANEL_NORMAL_BODY), sun, sun_dot, sun_ddot)  # type: ignore[arg-type]
        hb = X[ENERGY] - cfg.limits.energy_min_J
        h[:, _BATT] = hb
        E_dot = model.net_power(pb.cos, cfg)
        E_ddot = cfg.power.peak_W * (pb.cos > 0) * pb.cos_dot
        d2 = aug.delta2_J_rad
        second(_BATT, hb - margin("battery") - d2 * pb.theta, E_dot - d2 * pb.theta_dot,
               E_ddot - d2 * pb.theta_ddot_drift, tuple(-d2 * g for g in pb.theta_ddot_gain),  # type: ignore[arg-type]
               "battery")
        # angular rate and wheel speed (relative degree 1)
        go, gp = cfg.barriers["omega"], cfg.barriers["psi"]
        w_max2 = cfg.limits.omega_max_rad_s**2
        p_max2 = cfg.limits.psi_max_rad_s**2
        wd = ctx["wd"]
        for a in range(3):
            w = X[OMEGA.start + a]
            hw = w_max2 - w**2
            h[:, 4 + a] = hw
            gain[:, 4 + a, a] = -2.0 * w * self.cg[a]
            drift[:, 4 + a] = -2.0 * w * wd[a] + go.k1 * hw + go.bias  # type: ignore[index]
            ps_ = X[PSI.start + a]
            hp = p_max2 - ps_**2
            h[:, 7 + a] = hp
            gain[:, 7 + a, a] = -2.0 * ps_
            drift[:, 7 + a] = gp.k1 * hp + gp.bias
        return h, drift, gain

    def box(self, X: Array, ctx: dict[str, object], u_max: Array, robust: bool) -> tuple[Array, Array]:
        """(lo, hi) (N, 3) as `AsifFilter.box`."""
        N = X.shape[1]
        lo = np.broadcast_to(-u_max, (N, 3)).copy()
        hi = np.broadcast_to(u_max, (N, 3)).copy()
        if robust:
            cfg = self.cfg
            dt = cfg.filter.sample_time_s
            margin = cfg.filter.zoh_margin
            zlo = np.full((N, 3), -np.inf)
            zhi = np.full((N, 3), np.inf)
            wd = ctx["wd"]
            if cfg.barriers["omega"].enabled:
                limit = (1.0 - margin) * cfg.limits.omega_max_rad_s
                for a in range(3):
                    w_free = X[OMEGA.start + a] + wd[a] * dt  # type: ignore[index]
                    cg = float(self.cg[a])
                    a_ = (limit - w_free) / (cg * dt)
                    b_ = (-limit - w_free) / (cg * dt)
                    zlo[:, a] = np.maximum(zlo[:, a], np.minimum(a_, b_))
                    zhi[:, a] = np.minimum(zhi[:, a], np.maximum(a_, b_))
            if cfg.barriers["psi"].enabled:
                limit = (1.0 - margin) * cfg.limits.psi_max_rad_s
                for a in range(3):
                    psi = X[PSI.start + a]
                    zlo[:, a] = np.maximum(zlo[:, a], (-limit - psi) / dt)
                    zhi[:, a] = np.minimum(zhi[:, a], (limit - psi) / dt)
            new_lo, new_hi = np.maximum(lo, zlo), np.minimum(hi, zhi)
            bad = new_lo > new_hi
            edge = np.where(zhi < lo, lo, hi)
            lo = np.where(bad, edge, new_lo)
            hi = np.where(bad, edge, new_hi)
        return lo, hi


# ----------------------------------------------------------------------------- plant (SoA RK4)
class _Plant:
    """`simulation.integrate` on states held column-wise, same operations in the same order."""

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.J1, self.J2, self.J3 = cfg.spacecraft.inertia_kgm2
        self.cg = cfg.spacecraft.control_gain
        self.n = cfg.environment.mean_motion_rad_s
        self.heat_capacity = cfg.thermal.mass_kg * cfg.thermal.specific_heat_J_kgK

    def derivative(self, Y: Array, cs: Array, sn: Array, cgu: Array) -> Array:
        """d/dt of Y = [q1 q2 q3 q4 w1 w2 w3 T E] (9, N) as model.state_derivative."""
        q1, q2, q3, q4, w1, w2, w3, T, _E = Y
        K = np.empty_like(Y)
        mul, add = np.multiply, np.add
        mul(0.5, q4 * w1 - q3 * w2 + q2 * w3, out=K[0])
        mul(0.5, q3 * w1 + q4 * w2 - q1 * w3, out=K[1])
        mul(0.5, -q2 * w1 + q1 * w2 + q4 * w3, out=K[2])
        mul(-0.5, q1 * w1 + q2 * w2 + q3 * w3, out=K[3])
        J1, J2, J3 = self.J1, self.J2, self.J3
        add((J2 - J3) * w2 * w3 / J1, cgu[0], out=K[4])
        add((J3 - J1) * w3 * w1 / J2, cgu[1], out=K[5])
        add((J1 - J2) * w1 * w2 / J3, cgu[2], out=K[6])
        a10, a11 = 2.0 * (q1 * q2 - q3 * q4), -q1 * q1 + q2 * q2 - q3 * q3 + q4 * q4
        a20, a21 = 2.0 * (q1 * q3 + q2 * q4), 2.0 * (q2 * q3 - q1 * q4)
        cos_sun = -(a10 * cs + a11 * sn)
        np.divide(model.thermal_fluxes(cos_sun, a10, T, self.cfg), self.heat_capacity, out=K[7])
        K[8] = model.net_power(a20 * cs + a21 * sn, self.cfg)
        return K

    def integrate(self, Y: Array, psi: Array, th: Array, u: Array, dt_s: float, substeps: int,
                  on_substep: Callable[[int, Array, Array, Array, Array, Array], None] | None = None
                  ) -> tuple[Array, Array, Array]:
        """Hold u (3, N) over dt_s; returns (Y, psi, theta_S) at t + dt. After each substep j,
        on_substep(j, Y, psi, theta_S, cos theta_S, sin theta_S) sees the state."""
        h_s = dt_s / substeps
        cgu = np.stack([self.cg[a] * u[a] for a in range(3)])
        kp = 0.0 + u
        psi_inc = (h_s / 6.0) * (kp + 2.0 * kp + 2.0 * kp + kp)
        kth = -self.n
        half, full = 0.5 * h_s, h_s
        th_inc = (h_s / 6.0) * (kth + 2.0 * kth + 2.0 * kth + kth)
        c1, s1 = np.cos(th), np.sin(th)
        for j in range(substeps):
            th2 = th + half * kth
            th4 = th + full * kth
            c2, s2 = np.cos(th2), np.sin(th2)
            c4, s4 = np.cos(th4), np.sin(th4)
            k1 = self.derivative(Y, c1, s1, cgu)
            k2 = self.derivative(Y + half * k1, c2, s2, cgu)
            k3 = self.derivative(Y + half * k2, c2, s2, cgu)
            k4 = self.derivative(Y + full * k3, c4, s4, cgu)
            Y = Y + (h_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            q = Y[0:4]
            Y[0:4] = q / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
            psi = psi + psi_inc
            th = th + th_inc
            if j < substeps - 1 or on_substep is not None:
                c1, s1 = np.cos(th), np.sin(th)
            if on_substep is not None:
                on_substep(j, Y, psi, th, c1, s1)
        return Y, psi, th


# ----------------------------------------------------------------------------- the batch simulator
@dataclass
class BatchOutcome:
    """Per-run results of a batch (N runs, m = 10 constraints in CONSTRAINT_NAMES order).

    Attributes:
        violated_samples: (N, m) h < 0 at some sample t_k (the paper's criterion).
        violated_substeps: (N, m) h < 0 at some sample or RK4 substep.
        first_violation_s: (N, m) earliest sample or substep time with h < 0, NaN if none.
        min_h_samples: (N, m) smallest h over the samples.
        qp_steps, fallback_steps, qp_failures: (N,) steps that needed the QP, that ended in the
            fallback, and whose first QP failed.
        max_comm_slack: (N,) largest |delta| of the slacked constraints (rad for communication).
        x_final: (N, 19) state at the end.
        trajectory: (N, steps + 1, 19) states at the samples if recorded, else None.
    """

    violated_samples: NDArray[np.bool_]
    violated_substeps: NDArray[np.bool_]
    first_violation_s: Array
    min_h_samples: Array
    qp_steps: NDArray[np.int64]
    fallback_steps: NDArray[np.int64]
    qp_failures: NDArray[np.int64]
    max_comm_slack: Array
    x_final: Array
    trajectory: Array | None = None


class BatchSimulator:
    """N runs of the closed loop with RTA and u_des = 0 (no primary controller), in lockstep.

    Args:
        cfg: configuration (preset, gains, substeps).
        solver: 'active-set' (vectorised, `ActiveSetFilter` semantics) or 'proxsuite' (the core
            `AsifFilter.filter_batch`, state by state; bit-identical with `simulate`, slow).
    """

    def __init__(self, cfg: Config, solver: str = "active-set") -> None:
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        self.cfg = cfg
        self.solver = solver
        self.filter: AsifFilter = ActiveSetFilter(cfg) if solver == "active-set" else AsifFilter(cfg)
        self.rows = _Rows(cfg)
        self.plant = _Plant(cfg)
        self.enabled: NDArray[np.bool_] = self.filter.enabled.astype(bool)
        self.slacked = self.filter.slacked
        self.slack_rows = np.flatnonzero(self.slacked)
        self.n_var = 3 + self.slack_rows.size
        self.slack_scale = np.array([1.0 / np.sqrt(self.filter.slack_weights[i]) for i in self.slack_rows])

    # ------------------------------------------------------------------ filter
    def _filter(self, X: Array) -> tuple[Array, NDArray[np.int8], NDArray[np.bool_], Array]:
        """`AsifFilter.filter_batch` for u_des = 0: u (N, 3), status codes, first-QP-failed flags,
        slack (N, m)."""
        N = X.shape[1]
        if self.solver == "proxsuite":
            res = self.filter.filter_batch(np.ascontiguousarray(X.T), np.zeros((N, 3)))
            failed = (res.fallback != "") & (res.fallback != "non_finite_u_des") & (res.fallback != "invalid_state")
            return res.u, res.status, failed, res.slack
        # as filter_batch: states are checked, their quaternion normalised
        q = X[0:4]
        with np.errstate(all="ignore"):
            q_norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        valid = np.all(np.isfinite(X), axis=0) & (q_norm > 0.5) & (q_norm < 1.5)
        Xf = X.copy()
        Xf[0:4] = np.where(valid, q / np.where(valid, q_norm, 1.0), 0.0)
        if not valid.all():
            Xf[:, ~valid] = self.filter._safe_placeholder[:, None]
        with np.errstate(all="ignore"):
            ctx = self.rows.context(Xf)
            h, drift, gain = self.rows.evaluate(Xf)
            lo, hi = self.rows.box(Xf, ctx, self.filter.u_max, self.filter.robust)
        valid &= (np.all(np.isfinite(drift), axis=1) & np.all(np.isfinite(gain), axis=(1, 2))
                  & np.all(np.isfinite(lo), axis=1) & np.all(np.isfinite(hi), axis=1))
        if not valid.all():
            bad = ~valid
            lo[bad], hi[bad] = -self.filter.u_max, self.filter.u_max
            drift[bad], gain[bad] = 0.0, 0.0
        gnorm = np.linalg.norm(gain, axis=-1)
        depends = gnorm > MIN_ROW_NORM
        u_target = np.zeros((N, 3))
        u0 = np.clip(u_target, lo, hi)
        bc0 = drift + np.einsum("nmk,nk->nm", gain, u0)
        tol = self.filter.options.check_tolerance
        need = self.enabled & depends & (bc0 < -tol * np.maximum(1.0, gnorm))
        solve = np.flatnonzero(need.any(axis=-1) & valid)
        u = u0.copy()
        status = np.zeros(N, dtype=np.int8)
        failed = np.zeros(N, dtype=bool)
        slack = np.zeros((N, 10))
        if solve.size:
            self._solve(solve, drift, gain, gnorm, lo, hi, u_target, u, status, failed, slack, h)
        if not valid.all():  # not a state: the wheels hold their speed, as filter_batch
            u[~valid] = 0.0
            status[~valid] = CODE_FALLBACK
        return u, status, failed, slack

    def _solve(self, idx: NDArray[np.int64], drift: Array, gain: Array, gnorm: Array, lo: Array, hi: Array,
               u_target: Array, u: Array, status: NDArray[np.int8], failed: NDArray[np.bool_], slack: Array,
               h: Array) -> None:
        """Vectorised QPs of the states idx, laid out as `AsifFilter.qp` but zero-padded."""
        K, n = idx.size, self.n_var
        rows_in = self.enabled & (gnorm[idx] > MIN_ROW_NORM)  # (K, 10)
        # a slacked row left out changes the number of variables: leave those to the core path
        regular = np.all(rows_in[:, self.slack_rows], axis=1) if self.slack_rows.size else np.ones(K, bool)
        C = np.zeros((K, 13, n))
        lower = np.full((K, 13), -BIG)
        upper = np.full((K, 13), BIG)
        C[:, :10, :3] = gain[idx]
        for k, i in enumerate(self.slack_rows):
            C[:, i, 3 + k] = self.slack_scale[k]
        norms = np.sqrt(_dot_seq(C[:, :10], C[:, :10]))
        norms = np.where(rows_in, norms, 1.0)
        C[:, :10] = np.where(rows_in[..., None], C[:, :10] / norms[..., None], 0.0)
        lower[:, :10] = np.where(rows_in, -drift[idx] / norms, -BIG)
        C[:, 10:, :3] = np.eye(3)
        lower[:, 10:], upper[:, 10:] = lo[idx], hi[idx]
        z0 = np.zeros((K, n))
        g = -u_target[idx]  # the QP aims at u_des itself (g = -u_des), not its clip
        z0[:, :3] = -g
        z, _mult, code, _ = solve_projection_qp(C, lower, upper, z0)
        ok = (code == 0) & _rows_hold(C, lower, upper, z, self.filter.options.check_tolerance) & regular
        good = idx[ok]
        u[good] = np.clip(z[ok, :3], lo[good], hi[good])
        status[good] = CODE_SOLVED
        for k, i in enumerate(self.slack_rows):
            slack[good, i] = self.slack_scale[k] * z[ok, 3 + k]
        bad = idx[~ok]
        if bad.size == 0:
            return
        if self.filter.options.fallback == "soften":
            # these QPs failed exactly as AsifFilter.solve would on the same numbers: go straight
            # to the softened QPs, built by AsifFilter.qp and solved together per shape
            self._soften(idx[~ok & regular], drift, gain, h, lo, hi, u_target, u, status, failed, slack)
            bad = idx[~regular]
        for j in bad:
            # the core path: same QP, same solver, then the fallback policy
            row = BarrierTable(h[j], h[j], h[j], drift[j], gain[j])
            before = self.filter.counters.solver_failures
            u[j], slack[j], _i, status[j], _s, _it, _f = self.filter._solve_state(row, lo[j], hi[j], u_target[j],
                                                                                  True)
            failed[j] = self.filter.counters.solver_failures > before

    def _soften(self, idx: NDArray[np.int64], drift: Array, gain: Array, h: Array, lo: Array, hi: Array,
                u_target: Array, u: Array, status: NDArray[np.int8], failed: NDArray[np.bool_],
                slack: Array) -> None:
        """`AsifFilter._solve_state` after a failed QP with the 'soften' policy, for many states."""
        f = self.filter
        problems = []
        for j in idx:
            row = BarrierTable(h[j], h[j], h[j], drift[j], gain[j])
            problems.append(f.qp(row, lo[j], hi[j], u_target[j], soften=True))
        f.counters.solver_failures += idx.size
        failed[idx] = True
        status[idx] = CODE_FALLBACK
        groups: dict[tuple[int, ...], list[int]] = {}
        for k, pr in enumerate(problems):
            groups.setdefault(pr.C.shape, []).append(k)
        for ks in groups.values():
            C = np.stack([problems[k].C for k in ks])
            lower = np.stack([problems[k].lower for k in ks])
            upper = np.stack([problems[k].upper for k in ks])
            z0 = np.stack([-problems[k].g for k in ks])
            z, _mult, code, _it = solve_projection_qp(C, lower, upper, z0)
            ok = (code == 0) & _rows_hold(C, lower, upper, z, f.options.check_tolerance)
            for k, good, zk in zip(ks, ok, z):
                j = idx[k]
                f.counters.fallbacks += 1
                if not good:
                    u[j] = np.clip(u_target[j], lo[j], hi[j])
                    continue
                pr = problems[k]
                u[j] = np.clip(zk[:3], lo[j], hi[j])
                for name in pr.row_names[:-3]:
                    i = self.filter.names.index(name)
                    if i in pr.slack_index:
                        slack[j, i] = pr.slack_scale[pr.slack_index[i]] * zk[pr.slack_index[i]]

    # ------------------------------------------------------------------ checks between samples
    def _substep_h(self, Y: Array, psi: Array, th: Array, cs: Array, sn: Array,
                   flagged: NDArray[np.bool_]) -> tuple[NDArray[np.int64], Array]:
        """Runs that may newly violate a constraint at a substep state, and their h (k, m), the rows
        of `ConstraintSet.safety_values` computed the same way. A cheap screen (cosines and plain
        comparisons, SCREEN_MARGIN on the safe side) picks the candidates; constraints already
        flagged in a run (flagged (N, m)) need no second look."""
        cfg = self.cfg
        L = cfg.limits
        q1, q2, q3, q4 = Y[0], Y[1], Y[2], Y[3]
        c_ez = (q1 * q1 - q2 * q2 - q3 * q3 + q4 * q4) * cs + 2.0 * (q1 * q2 + q3 * q4) * sn  # +i_B . r_S
        c_gs = 2.0 * (q3 * q4 - q1 * q2)  # +j_B . r_E
        near = (c_ez > math.cos(L.exclusion_angle_rad) - SCREEN_MARGIN) & ~flagged[:, _EZ]
        near |= (c_gs < math.cos(L.comm_angle_rad) + SCREEN_MARGIN) & ~flagged[:, _COMM]
        near |= (Y[7] > L.temperature_max_K - SCREEN_MARGIN) & ~flagged[:, _TEMP]
        near |= (Y[8] < L.energy_min_J + SCREEN_MARGIN) & ~flagged[:, _BATT]
        near |= np.any((np.abs(Y[4:7]) > L.omega_max_rad_s * (1.0 - SCREEN_MARGIN)) & ~flagged[:, 4:7].T, axis=0)
        near |= np.any((np.abs(psi) > L.psi_max_rad_s * (1.0 - SCREEN_MARGIN)) & ~flagged[:, 7:10].T, axis=0)
        sel = np.flatnonzero(near)
        if sel.size == 0:
            return sel, np.zeros((0, 10))
        X = np.zeros((STATE_SIZE, sel.size))
        X[0:7] = Y[0:7, sel]
        X[PSI] = psi[:, sel]
        X[TEMP], X[ENERGY], X[THETA_S] = Y[7, sel], Y[8, sel], th[sel]
        return sel, self.safety_values(X)

    def _sample_h(self, X: Array) -> Array:
        """h (N, m) at the samples as ClosedLoop records them (safety_values of the plant state)."""
        if self.solver == "proxsuite":
            return self.filter.constraints.safety_values(np.ascontiguousarray(X.T))
        return self.safety_values(X)

    def safety_values(self, X: Array) -> Array:
        """Physical h (N, m) of states X (19, N), as `ConstraintSet.safety_values` (the angles by
        the same operations as `_Rows.pointing_body`, without the derivatives)."""
        L = self.cfg.limits
        h = np.empty((X.shape[1], 10))
        q1, q2, q3, q4 = X[0], X[1], X[2], X[3]
        s11, s22, s33, s44 = q1 * q1, q2 * q2, q3 * q3, q4 * q4
        A0 = (s11 - s22 - s33 + s44, 2.0 * (q1 * q2 - q3 * q4), 2.0 * (q1 * q3 + q2 * q4))  # column 0
        A1 = (2.0 * (q1 * q2 + q3 * q4), -s11 + s22 - s33 + s44, 2.0 * (q2 * q3 - q1 * q4))  # column 1
        th = X[THETA_S]
        cs, sn = np.cos(th), np.sin(th)
        r_S: _Vec = tuple(A0[i] * cs + A1[i] * sn for i in range(3))  # type: ignore[assignment]
        r_E: _Vec = (-A0[0], -A0[1], -A0[2])
        h[:, _EZ] = _theta(tuple(model.SENSOR_AXIS_BODY), r_S) - L.exclusion_angle_rad  # type: ignore[arg-type]
        h[:, _COMM] = L.comm_angle_rad - _theta(tuple(model.ANTENNA_AXIS_BODY), r_E)  # type: ignore[arg-type]
        h[:, _TEMP] = L.temperature_max_K - X[TEMP]
        h[:, _BATT] = X[ENERGY] - L.energy_min_J
        for a in range(3):
            h[:, 4 + a] = L.omega_max_rad_s**2 - X[OMEGA.start + a] ** 2
            h[:, 7 + a] = L.psi_max_rad_s**2 - X[PSI.start + a] ** 2
        return h

    # ------------------------------------------------------------------ run
    def run(self, x0: Array, duration_s: float, record: bool = False,
            progress: Callable[[int], None] | None = None) -> BatchOutcome:
        """Simulate every run for duration_s.

        Args:
            x0: initial states (N, 19); the Clohessy-Wiltshire entries must be zero (they are
                unforced, constrain nothing and stay zero).
            duration_s: run length, s (steps of filter.sample_time_s).
            record: keep the states at every sample (N, steps + 1, 19) for comparisons.
            progress: called with the number of steps done after each step.
        """
        cfg = self.cfg
        x0 = np.asarray(x0, dtype=float)
        if x0.ndim != 2 or x0.shape[1] != STATE_SIZE:
            raise ValueError(f"x0 must be (N, {STATE_SIZE}), got {x0.shape}")
        if np.any(x0[:, 13:] != 0.0):
            raise ValueError("x0: the Clohessy-Wiltshire entries must be zero in a batch run")
        dt = cfg.filter.sample_time_s
        steps = round(duration_s / dt)
        N = x0.shape[0]
        X = np.ascontiguousarray(x0.T)
        Y = X[[0, 1, 2, 3, 4, 5, 6, TEMP, ENERGY]].copy()
        psi, th = X[PSI].copy(), X[THETA_S].copy()
        viol_s = np.zeros((N, 10), dtype=bool)
        viol_sub = np.zeros((N, 10), dtype=bool)
        first = np.full((N, 10), np.nan)
        min_h = np.full((N, 10), np.inf)
        qp_steps = np.zeros(N, dtype=np.int64)
        fb_steps = np.zeros(N, dtype=np.int64)
        qp_fail = np.zeros(N, dtype=np.int64)
        max_slack = np.zeros(N)
        traj = np.zeros((N, steps + 1, STATE_SIZE)) if record else None
        if traj is not None:
            traj[:, 0] = x0
        sub_t = dt * np.arange(1, cfg.substeps + 1) / cfg.substeps

        def mark(h: Array, t: float, sample: bool, rows: NDArray[np.int64] | None = None) -> None:
            bad = h < 0
            if rows is None:
                if sample:
                    viol_s[:] |= bad
                new = bad & np.isnan(first)
                first[new] = t
                viol_sub[:] |= bad
            elif bad.any():
                new = bad & np.isnan(first[rows])
                first[rows] = np.where(new, t, first[rows])
                viol_sub[rows] |= bad

        def state(Y: Array, psi: Array, th: Array) -> Array:
            Xs = np.zeros((STATE_SIZE, N))
            Xs[0:7], Xs[PSI], Xs[TEMP], Xs[ENERGY], Xs[THETA_S] = Y[0:7], psi, Y[7], Y[8], th
            return Xs

        for k in range(steps):
            t = k * dt
            Xk = state(Y, psi, th)
            u, status, failed, slack = self._filter(Xk)
            h = self._sample_h(Xk)
            np.minimum(min_h, h, out=min_h)
            mark(h, t, True)
            qp_steps += status > 0
            fb_steps += status == CODE_FALLBACK
            qp_fail += failed
            if self.slack_rows.size:
                np.maximum(max_slack, np.abs(slack[:, self.slack_rows]).max(axis=1), out=max_slack)
            u = model.through_torque_interface(u, cfg)
            lim = cfg.limits.wheel_accel_max_rad_s2
            u = np.clip(np.clip(u, -lim, lim), -lim, lim)  # ClosedLoop saturates, integrate saturates again

            def on_sub(j: int, Ys: Array, ps: Array, ts: Array, cs: Array, sn: Array, t: float = t) -> None:
                if j < cfg.substeps - 1:
                    sel, hs = self._substep_h(Ys, ps, ts, cs, sn, viol_sub)
                    if sel.size:
                        mark(hs, t + sub_t[j], False, sel)

            Y, psi, th = self.plant.integrate(Y, psi, th, np.ascontiguousarray(u.T), dt, cfg.substeps, on_sub)
            if traj is not None:
                traj[:, k + 1] = state(Y, psi, th).T
            if progress is not None:
                progress(k + 1)
        Xn = state(Y, psi, th)
        h_end = self._sample_h(Xn)
        np.minimum(min_h, h_end, out=min_h)
        mark(h_end, steps * dt, True)
        return BatchOutcome(viol_s, viol_sub, first, min_h, qp_steps, fb_steps, qp_fail, max_slack,
                            np.ascontiguousarray(Xn.T), traj)


__all__ = ["SOLVERS", "ActiveSetFilter", "BatchOutcome", "BatchSimulator", "solve_projection_qp"]
assert len(CONSTRAINT_NAMES) == 10  # the row indices above follow CONSTRAINT_NAMES
