"""Active Set Invariance Filter: the minimal change of u_des that keeps every barrier condition.

    min_{u, s}  ||u - u_des||^2 + ||s||^2
    s.t.        BC_i(x, u) + s_i / sqrt(p_i) >= 0     slacked constraints (delta_i = s_i / sqrt(p_i))
                BC_i(x, u)                   >= 0     hard constraints
                lo(x) <= u <= hi(x)                   admissible set U (and, in the `robust` preset,
                                                      the one-step-ahead ZOH bounds on omega and psi)

BC_i(x, u) = drift_i(x) + gain_i(x) . u comes from `rta_attitude.constraints`. The slack is
scaled (cost s^2 instead of p delta^2, p = 1e12 would ruin the Hessian's conditioning), every row
is normalised to unit norm, and every solution proxsuite returns is checked against the rows
before it is used. Fast path: u0 = clip(u_des, lo, hi) is the exact QP solution whenever it meets
every row, so the solver is not called then. If the QP fails, the configured fallback acts:
`pass_through` (the paper: u_des clipped to U), `hold` (u = 0), `soften` (re-solve with every row
slacked, the least-violation command), or `raise` (SolverError).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import proxsuite
from numpy.typing import NDArray

from .constraints import BarrierTable, ConstraintSet
from .errors import SolverError
from .params import Config

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

BIG = 1e20
"""proxsuite's stand-in for an infinite bound."""
MIN_ROW_NORM = 1e-12
"""Rows whose gradient in u is smaller than this do not depend on u and are not sent to the QP."""
ACTIVE_MULTIPLIER = 1e-9
"""A row whose multiplier exceeds this at the solution is active (it shapes u)."""

STATUS_PASS = "pass"
"""u_des (clipped to the box) already met every row: no solve."""
STATUS_SOLVED = "solved"
STATUS_FALLBACK = "fallback"
STATUS_NAMES: tuple[str, ...] = (STATUS_PASS, STATUS_SOLVED, STATUS_FALLBACK)
CODE_PASS, CODE_SOLVED, CODE_FALLBACK = 0, 1, 2


@dataclass(frozen=True)
class FilterResult:
    """What one filter call did, for one state (arrays over constraints follow `names`).

    Attributes:
        u: the command u_act (3,), rad/s^2, always finite and inside the box.
        u_des: the desired command (3,), rad/s^2, as received.
        names: constraint names (m,).
        h, psi0, psi1: physical h and HOCBF levels at x (m,).
        bc: barrier conditions at u (m,); slack is not included.
        slack: delta_i (m,) of slacked constraints (0 elsewhere).
        intervening: (m,) bool, rows active at the solution (they moved u away from u_des).
        box_active: (3,) bool, axes where the box (U or a ZOH bound) clipped u.
        status: 'pass', 'solved' or 'fallback'.
        solver_status: proxsuite's status name, or '' when the solver was not called.
        iterations: solver iterations (0 on the fast path).
        fallback: the fallback policy applied, '' if none.
        uncontrollable: (m,) bool, rows violated whatever u is (gradient in u is zero).
        solve_time_s: wall time of the whole call, s.
    """

    u: Array
    u_des: Array
    names: tuple[str, ...]
    h: Array
    psi0: Array
    psi1: Array
    bc: Array
    slack: Array
    intervening: Array
    box_active: Array
    status: str
    solver_status: str
    iterations: int
    fallback: str
    uncontrollable: Array
    solve_time_s: float

    @property
    def intervened(self) -> bool:
        """True if u differs from u_des because of any row or the box."""
        return bool(self.intervening.any() or self.box_active.any())


@dataclass(frozen=True)
class BatchResult:
    """`FilterResult` fields for a batch of N states, as arrays with a leading N axis.

    status holds codes into STATUS_NAMES (0 pass, 1 solved, 2 fallback).
    """

    u: Array
    h: Array
    psi0: Array
    psi1: Array
    bc: Array
    slack: Array
    intervening: Array
    box_active: Array
    status: NDArray[np.int8]
    solver_status: NDArray[np.str_]
    iterations: NDArray[np.int64]
    fallback: NDArray[np.str_]
    uncontrollable: Array


@dataclass
class FilterCounters:
    """Running totals of a filter's calls (a node publishes these)."""

    calls: int = 0
    fast_path: int = 0
    solved: int = 0
    fallbacks: int = 0
    solver_failures: int = 0
    backup_solves: int = 0
    """Calls in which proxsuite failed and the backup solver was asked."""
    invalid_states: int = 0
    """Calls with a non-finite state or a quaternion norm outside (0.5, 1.5): answered u = 0."""
    by_status: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class QpProblem:
    """The filter's QP in proxsuite's form: min 1/2 z'Hz + g'z, l <= C z <= u, z = [u; s]."""

    H: Array
    g: Array
    C: Array
    lower: Array
    upper: Array
    row_names: tuple[str, ...]
    row_norm: Array
    """Norm each constraint row was divided by (1 for box rows)."""
    slack_index: dict[int, int]
    """Constraint index -> variable index of its slack."""
    slack_scale: Array
    """(n_var,) delta = scale * s for slack variables, 0 for u."""


def solve_with_quadprog(problem: QpProblem) -> tuple[Array, Array, bool]:
    """Exact dual active-set solution (Goldfarb-Idnani, `quadprog`) of the same QP.

    Returns (z, row multipliers in proxsuite's sign convention, solved?). Infeasible problems are
    detected in a finite number of steps (quadprog raises ValueError).
    """
    import quadprog

    C, lower, upper = problem.C, problem.lower, problem.upper
    lo_rows = np.flatnonzero(lower > -BIG / 2)
    up_rows = np.flatnonzero(upper < BIG / 2)
    Cq = np.vstack([C[lo_rows], -C[up_rows]]).T
    bq = np.concatenate([lower[lo_rows], -upper[up_rows]])
    try:
        z, _f, _xu, _it, lag, _act = quadprog.solve_qp(problem.H, -problem.g, Cq, bq, 0)
    except ValueError:
        return np.full(C.shape[1], np.nan), np.zeros(C.shape[0]), False
    mult = np.zeros(C.shape[0])
    mult[lo_rows] -= lag[: len(lo_rows)]
    mult[up_rows] += lag[len(lo_rows):]
    return np.asarray(z, dtype=float), mult, True


class AsifFilter:
    """The ASIF safety filter of one configuration; call `filter(x, u_des)`.

    Not thread-safe (keeps its proxsuite workspaces).
    """

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.constraints = ConstraintSet.from_config(cfg)
        self.names = self.constraints.names
        self.u_max = cfg.u_max_rad_s2
        self.options = cfg.filter
        self.robust = cfg.filter.preset == "robust"
        self.enabled = self.constraints.enabled
        weights = self.constraints.slack_weights
        self.slacked = self.enabled & (weights > 0)
        self.slack_weights = weights
        self.counters = FilterCounters()
        self._safe_placeholder = np.zeros(19)
        self._safe_placeholder[3] = 1.0
        self._safe_placeholder[10] = 273.15
        self._workspaces: dict[tuple[int, int], proxsuite.proxqp.dense.QP] = {}

    # ---------------------------------------------------------------- bounds and rows
    def box(self, x: Array, ctx: object | None = None) -> tuple[Array, Array, Array]:
        """(lo, hi, zoh_infeasible) on u (..., 3): U, intersected with the ZOH bounds if robust.

        Where a ZOH interval misses U entirely, the box shrinks to the edge of U nearest to it
        (the best the actuator can do) and zoh_infeasible is True for that axis.
        """
        lo = np.broadcast_to(-self.u_max, (*np.shape(x)[:-1], 3)).copy()
        hi = np.broadcast_to(self.u_max, (*np.shape(x)[:-1], 3)).copy()
        bad = np.zeros(lo.shape, dtype=bool)
        if self.robust:
            c = ctx if ctx is not None else self.constraints.context(x)
            zlo, zhi = self.constraints.zoh_bounds(c, self.options.sample_time_s, self.options.zoh_margin)  # type: ignore[arg-type]
            new_lo, new_hi = np.maximum(lo, zlo), np.minimum(hi, zhi)
            bad = new_lo > new_hi
            edge = np.where(zhi < lo, lo, hi)
            lo = np.where(bad, edge, new_lo)
            hi = np.where(bad, edge, new_hi)
        return lo, hi, bad

    def evaluate(self, x: Array) -> tuple[BarrierTable, Array, Array, Array]:
        """Barrier table and box (lo, hi, zoh_infeasible) of states x (..., 19)."""
        ctx = self.constraints.context(x)
        table = self.constraints.evaluate(x, ctx)
        lo, hi, bad = self.box(x, ctx)
        return table, lo, hi, bad

    def qp(self, table: BarrierTable, lo: Array, hi: Array, u_des: Array, soften: bool = False) -> QpProblem:
        """The QP of one state (table entries of shape (m,), lo/hi/u_des (3,)).

        Rows of disabled constraints, and rows that do not depend on u, are left out.
        With soften=True every row gets a slack (weight: its own p, or options.soften_weight).
        """
        rows = [i for i in range(len(self.names))
                if self.enabled[i] and np.linalg.norm(table.gain[i]) > MIN_ROW_NORM]
        slack_rows = [i for i in rows if self.slacked[i] or soften]
        n = 3 + len(slack_rows)
        slack_index = {i: 3 + k for k, i in enumerate(slack_rows)}
        scale = np.zeros(n)
        C = np.zeros((len(rows) + 3, n))
        lower = np.full(len(rows) + 3, -BIG)
        upper = np.full(len(rows) + 3, BIG)
        norms = np.ones(len(rows) + 3)
        for r, i in enumerate(rows):
            C[r, :3] = table.gain[i]
            if i in slack_index:
                p = self.slack_weights[i] if self.slacked[i] else self.options.soften_weight
                scale[slack_index[i]] = 1.0 / np.sqrt(p)
                C[r, slack_index[i]] = scale[slack_index[i]]
            norms[r] = np.linalg.norm(C[r])
            C[r] /= norms[r]
            lower[r] = -table.drift[i] / norms[r]
        C[len(rows):, :3] = np.eye(3)
        lower[len(rows):], upper[len(rows):] = lo, hi
        g = np.zeros(n)
        g[:3] = -u_des
        names = (*tuple(self.names[i] for i in rows), "u_x", "u_y", "u_z")
        return QpProblem(np.eye(n), g, C, lower, upper, names, norms, slack_index, scale)

    # ---------------------------------------------------------------- solving
    def _workspace(self, n: int, n_in: int) -> proxsuite.proxqp.dense.QP:
        key = (n, n_in)
        if key not in self._workspaces:
            qp = proxsuite.proxqp.dense.QP(n, 0, n_in)
            s = qp.settings
            s.eps_abs = self.options.eps_abs
            s.eps_rel = 0.0
            s.eps_primal_inf = self.options.eps_primal_inf
            s.eps_dual_inf = self.options.eps_dual_inf
            s.max_iter = self.options.max_iterations
            s.max_iter_in = self.options.max_inner_iterations
            s.verbose = False
            s.initial_guess = proxsuite.proxqp.InitialGuess.NO_INITIAL_GUESS
            self._workspaces[key] = qp
        return self._workspaces[key]

    def solve(self, problem: QpProblem) -> tuple[Array | None, Array, str, int]:
        """Solve with proxsuite, then (if it failed or its answer does not meet the rows) with the
        backup solver; verify. Returns (z or None if unusable, row multipliers, status, iterations).

        Multipliers follow proxsuite's sign convention: > 0 at an active upper bound, < 0 at an
        active lower bound, 0 for inactive rows.
        """
        if self.options.solver == "active_set":
            from .batch import ActiveSetFilter

            return ActiveSetFilter.solve(self, problem)  # type: ignore[arg-type]
        n, n_in = problem.C.shape[1], problem.C.shape[0]
        qp = self._workspace(n, n_in)
        qp.init(problem.H, problem.g, None, None, problem.C, problem.lower, problem.upper)
        qp.solve()
        res = qp.results
        status = res.info.status.name
        z = np.array(res.x, dtype=float)
        mult = np.array(res.z, dtype=float)
        iters = int(res.info.iter)
        ok = (res.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED and self._meets_rows(problem, z)
              and self._is_stationary(problem, z, mult))
        if not ok and res.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED:
            status += "_CHECK_FAILED"
        if not ok and self.options.backup_solver == "quadprog":
            self.counters.backup_solves += 1
            zq, mq, ok_q = solve_with_quadprog(problem)
            status += ">quadprog:" + ("SOLVED" if ok_q else "INFEASIBLE")
            if ok_q and self._meets_rows(problem, zq):
                return zq, mq, status, iters
            if ok_q:
                status += "_CHECK_FAILED"
        return (z if ok else None), mult, status, iters

    def _is_stationary(self, problem: QpProblem, z: Array, mult: Array) -> bool:
        """KKT stationarity H z + g + C' y = 0 with y of the right signs (measured: proxsuite can
        report SOLVED at a point 6 % worse than the optimum when a p = 1e12 slack is present)."""
        if np.any(mult[problem.lower <= -BIG / 2] < -self.options.check_tolerance):
            return False
        if np.any(mult[problem.upper >= BIG / 2] > self.options.check_tolerance):
            return False
        r = problem.H @ z + problem.g + problem.C.T @ mult
        return bool(np.linalg.norm(r[:3]) <= self.options.check_tolerance * (1.0 + np.linalg.norm(problem.g)))

    def _meets_rows(self, problem: QpProblem, z: Array) -> bool:
        if not np.all(np.isfinite(z)):
            return False
        Cz = problem.C @ z
        tol = self.options.check_tolerance
        return bool(np.all(Cz >= problem.lower - tol) and np.all(Cz <= problem.upper + tol))


    def filter(self, x: Array, u_des: Array) -> FilterResult:
        """Filter one desired command.

        Args:
            x: state (19,), model units.
            u_des: desired wheel accelerations (3,), rad/s^2 (non-finite entries are treated as 0
                and the call is counted as a fallback).

        Returns:
            FilterResult with u_act and the per-constraint record.

        Raises:
            SolverError: the QP failed and the fallback policy is 'raise'.
        """
        t0 = time.perf_counter()
        b = self.filter_batch(np.asarray(x, dtype=float)[None], np.asarray(u_des, dtype=float)[None])
        return FilterResult(
            u=b.u[0], u_des=np.asarray(u_des, dtype=float), names=self.names, h=b.h[0], psi0=b.psi0[0],
            psi1=b.psi1[0], bc=b.bc[0], slack=b.slack[0], intervening=b.intervening[0],
            box_active=b.box_active[0], status=STATUS_NAMES[b.status[0]], solver_status=b.solver_status[0],
            iterations=int(b.iterations[0]), fallback=b.fallback[0], uncontrollable=b.uncontrollable[0],
            solve_time_s=time.perf_counter() - t0,
        )  # fmt: skip

    def filter_batch(self, x: Array, u_des: Array) -> BatchResult:
        """Filter a batch: x (N, 19), u_des (N, 3). Rows and the fast path are vectorised; states
        that need the QP are solved one by one. `filter` is this with N = 1, so a run inside a
        batch and a single run compute the same numbers."""
        x = np.array(x, dtype=float)
        u_des = np.asarray(u_des, dtype=float)
        n, m = x.shape[0], len(self.names)
        with np.errstate(all="ignore"):
            q_norm = np.linalg.norm(x[:, 0:4], axis=-1)
        valid = np.all(np.isfinite(x), axis=-1) & (q_norm > 0.5) & (q_norm < 1.5)
        x[valid, 0:4] /= q_norm[valid, None]
        x[~valid] = self._safe_placeholder
        with np.errstate(all="ignore"):  # absurd but finite states may overflow: caught just below
            table, lo, hi, _bad = self.evaluate(x)
        finite_rows = (np.all(np.isfinite(table.drift), axis=-1) & np.all(np.isfinite(table.gain), axis=(-2, -1))
                       & np.all(np.isfinite(lo), axis=-1) & np.all(np.isfinite(hi), axis=-1))
        valid &= finite_rows
        lo[~valid], hi[~valid] = -self.u_max, self.u_max
        table.drift[~valid], table.gain[~valid] = 0.0, 0.0
        gnorm = np.linalg.norm(table.gain, axis=-1)
        depends = gnorm > MIN_ROW_NORM
        uncontrollable = self.enabled & ~depends & (table.drift < 0)
        finite_des = np.all(np.isfinite(u_des), axis=-1)
        u_target = np.where(np.isfinite(u_des), u_des, 0.0)
        u0 = np.clip(u_target, lo, hi)
        bc0 = table.drift + np.einsum("nmk,nk->nm", table.gain, u0)
        tol = self.options.check_tolerance
        need = self.enabled & depends & (bc0 < -tol * np.maximum(1.0, gnorm))
        solve = (need.any(axis=-1) | ~finite_des) & valid
        u = u0.copy()
        slack = np.zeros((n, m))
        intervening = np.zeros((n, m), dtype=bool)
        status = np.zeros(n, dtype=np.int8)
        solver_status = np.full(n, "", dtype=object)
        fallback = np.full(n, "", dtype=object)
        iterations = np.zeros(n, dtype=np.int64)
        self.counters.calls += n
        self.counters.fast_path += int(n - solve.sum())
        for k in np.nonzero(solve)[0]:
            row = BarrierTable(table.h[k], table.psi0[k], table.psi1[k], table.drift[k], table.gain[k])
            u[k], slack[k], intervening[k], status[k], solver_status[k], iterations[k], fallback[k] = (
                self._solve_state(row, lo[k], hi[k], u_target[k], bool(finite_des[k])))
        if not valid.all():
            # a state that is not a state (NaN, inf, no attitude, barrier rows that overflow): no
            # barrier can be trusted; the wheels hold their speed (u = 0), keeping the body rates
            bad = ~valid
            self.counters.fallbacks += int(bad.sum())
            self.counters.invalid_states += int(bad.sum())
            lo[bad], hi[bad] = -self.u_max, self.u_max
            u[bad] = 0.0
            status[bad] = CODE_FALLBACK
            fallback[bad] = "invalid_state"
            table.h[bad] = table.psi0[bad] = table.psi1[bad] = table.drift[bad] = np.nan
        for code, name in enumerate(STATUS_NAMES):
            c = int(np.count_nonzero(status == code))
            if c:
                self.counters.by_status[name] = self.counters.by_status.get(name, 0) + c
        des = np.where(np.isfinite(u_des), u_des, 0.0)
        box_active = ((u <= lo) & (des < lo)) | ((u >= hi) & (des > hi))
        return BatchResult(
            u=u, h=table.h, psi0=table.psi0, psi1=table.psi1, bc=table.drift + np.einsum("nmk,nk->nm", table.gain, u),
            slack=slack, intervening=intervening, box_active=box_active, status=status,
            solver_status=solver_status.astype(str), iterations=iterations, fallback=fallback.astype(str),
            uncontrollable=uncontrollable,
        )  # fmt: skip

    def _solve_state(self, table: BarrierTable, lo: Array, hi: Array, u_target: Array, finite_des: bool
                     ) -> tuple[Array, Array, Array, int, str, int, str]:
        """QP of one state (objective ||u - u_target||^2, u_target = u_des with non-finite entries
        zeroed), with the fallback policy. Returns (u, slack, intervening, status code, solver
        status, iterations, fallback name)."""
        u0 = np.clip(u_target, lo, hi)
        m = len(self.names)
        slack = np.zeros(m)
        intervening = np.zeros(m, dtype=bool)
        problem = self.qp(table, lo, hi, u_target)
        z, mult, solver_status, iters = self.solve(problem)
        fallback = "" if finite_des else "non_finite_u_des"
        if z is None:
            self.counters.solver_failures += 1
            fallback = self.options.fallback
            log.debug("QP failed (%s); fallback %s", solver_status, fallback)
            if fallback == "raise":
                raise SolverError(f"ASIF QP failed with status {solver_status}")
            if fallback == "soften":
                soft = self.qp(table, lo, hi, u_target, soften=True)
                z, mult, status2, it2 = self.solve(soft)
                iters += it2
                solver_status = f"{solver_status}+soften:{status2}"
                if z is not None:
                    problem = soft
            if z is None:
                self.counters.fallbacks += 1
                u = np.clip(np.zeros(3), lo, hi) if fallback == "hold" else u0
                return u, slack, intervening, CODE_FALLBACK, solver_status, iters, fallback
        if fallback:
            self.counters.fallbacks += 1
        else:
            self.counters.solved += 1
        u = np.clip(z[:3], lo, hi)
        for r, nm in enumerate(problem.row_names[:-3]):
            i = self.names.index(nm)
            intervening[i] = abs(mult[r]) > ACTIVE_MULTIPLIER
            if i in problem.slack_index:
                slack[i] = problem.slack_scale[problem.slack_index[i]] * z[problem.slack_index[i]]
        return u, slack, intervening, (CODE_FALLBACK if fallback else CODE_SOLVED), solver_status, iters, fallback


__all__ = ["AsifFilter", "BatchResult", "FilterCounters", "FilterResult", "QpProblem", "STATUS_FALLBACK", "STATUS_PASS",
           "STATUS_SOLVED"]
