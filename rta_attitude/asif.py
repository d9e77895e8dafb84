"""Active Set Invariance Filter: the minimal change of u_des that keeps every barrier condition.

    min_{u, s}  ||u - u_des||^2 + ||s||^2
    s.t.        BC_i(x, u) + s_i / sqrt(p_i) >= 0     slacked constraints (delta_i = s_i / sqrt(p_i))
                BC_i(x, u)                   >= 0     hard constraints
                lo(x) <= u <= hi(x)                   admissible set U (and, in the `robust` preset,
                                                      the one-step-ahead ZOH bounds on omega and psi)

BC_i(x, u) = drift_i(x) + gain_i(x) . u is defined in `rta_attitude.constraints` (one module per
constraint) and evaluated per call by its compiled port `barrier_rows`. The slack is scaled (cost
s^2 instead of p delta^2, p = 1e12 would ruin the Hessian's conditioning), every row is normalised
to unit norm, and every solution is checked against the rows before it is used. Fast path:
u0 = clip(u_des, lo, hi) is the exact QP solution whenever it meets every row, so the solver is not
called then. Solvers (`filter.solver`): `active_set`, the exact dual active-set method, compiled
(`active_set`, default: the whole call runs in `filter_kernel.filter_active_set`), or `proxsuite`
(iterations capped; answers also checked for KKT stationarity; `quadprog` re-solves where proxsuite
fails). If the QP fails, the configured fallback acts: `pass_through` (the paper: u_des clipped to
U), `hold` (u = 0), `soften` (re-solve with every row slacked, the least-violation command), or
`raise` (SolverError).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, fields

import numpy as np
import proxsuite
from numpy.typing import NDArray

from . import active_set
from . import filter_kernel as kernel
from .barrier_rows import row_parameters
from .constraints import BarrierTable, ConstraintSet
from .errors import SolverError
from .params import Config
from .state import STATE_SIZE

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

BIG = kernel.BIG
"""proxsuite's stand-in for an infinite bound."""
MIN_ROW_NORM = kernel.MIN_ROW_NORM
"""Rows whose gradient in u is smaller than this do not depend on u and are not sent to the QP."""
ACTIVE_MULTIPLIER = kernel.ACTIVE_MULTIPLIER
"""A row whose multiplier exceeds this at the solution is active (it shapes u)."""

STATUS_PASS = "pass"
"""u_des (clipped to the box) already met every row: no solve."""
STATUS_SOLVED = "solved"
STATUS_FALLBACK = "fallback"
STATUS_NAMES: tuple[str, ...] = (STATUS_PASS, STATUS_SOLVED, STATUS_FALLBACK)
CODE_PASS, CODE_SOLVED, CODE_FALLBACK = kernel.CODE_PASS, kernel.CODE_SOLVED, kernel.CODE_FALLBACK


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
    qp_failed: NDArray[np.bool_]
    """The state's first QP failed (a fallback policy acted)."""


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

    The per-call work runs compiled (`filter_kernel`, `barrier_rows`); `evaluate` and `box` give
    the same rows and box from the numpy reference (`constraints`), for inspection and tests. Not thread-safe (keeps its
    proxsuite workspaces).
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
        self._params = row_parameters(cfg)
        self._enabled = np.ascontiguousarray(self.enabled, dtype=np.bool_)
        self._slack_weight = np.where(self.slacked, weights, 0.0)
        self._policy = kernel.POLICIES.index(cfg.filter.fallback)
        self._workspaces: dict[tuple[int, int], proxsuite.proxqp.dense.QP] = {}
        self._scratch = (np.empty(3), np.empty(3), np.zeros(kernel.N_INFO, dtype=np.int64))
        compile_kernels(cfg)

    # ---------------------------------------------------------------- bounds and rows (reference)
    def box(self, x: Array, ctx: object | None = None) -> tuple[Array, Array, Array]:
        """(lo, hi, zoh_infeasible) on u (..., 3): U, intersected with the ZOH bounds if robust.

        Where a ZOH interval misses U entirely, the box shrinks to the edge of U nearest to it
        (the best the actuator can do) and zoh_infeasible is True for that axis. (The numpy
        reference of the compiled box in `barrier_rows`.)
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
        """Barrier table and box (lo, hi, zoh_infeasible) of states x (..., 19), computed by the
        numpy reference (`constraints`)."""
        ctx = self.constraints.context(x)
        table = self.constraints.evaluate(x, ctx)
        lo, hi, bad = self.box(x, ctx)
        return table, lo, hi, bad

    def _problem(self, C: Array, lower: Array, upper: Array, z0: Array, row_of: NDArray[np.int64],
                 slack_var: NDArray[np.int64], scale: Array, norms: Array) -> QpProblem:
        n = C.shape[1]
        names = (*tuple(self.names[i] for i in row_of), "u_x", "u_y", "u_z")
        slack_index = {int(i): int(v) for i, v in enumerate(slack_var) if v >= 0}
        return QpProblem(np.eye(n), -z0, C, lower, upper, names, norms, slack_index, scale)

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

    def solve_proxsuite(self, problem: QpProblem) -> tuple[Array | None, Array, str, int]:
        """Solve with proxsuite, then (if it failed or its answer does not meet the rows or the KKT
        conditions) with the backup solver; verify. Returns (z or None if unusable, row
        multipliers, status, iterations). (The active-set solver runs inside `filter_kernel`.)

        Multipliers follow proxsuite's sign convention: > 0 at an active upper bound, < 0 at an
        active lower bound, 0 for inactive rows.
        """
        tol = self.options.check_tolerance
        n, n_in = problem.C.shape[1], problem.C.shape[0]
        qp = self._workspace(n, n_in)
        qp.init(problem.H, problem.g, None, None, problem.C, problem.lower, problem.upper)
        qp.solve()
        res = qp.results
        solved = res.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        status = res.info.status.name
        z = np.array(res.x, dtype=float)
        mult = np.array(res.z, dtype=float)
        iters = int(res.info.iter)
        ok = (solved and active_set.rows_hold(problem.C, problem.lower, problem.upper, z, tol)
              and kernel.is_stationary(problem.C, problem.lower, problem.upper, z, mult, problem.g, tol))
        if not ok and solved:
            status += "_CHECK_FAILED"
        if not ok and self.options.backup_solver == "quadprog":
            self.counters.backup_solves += 1
            zq, mq, ok_q = solve_with_quadprog(problem)
            status += ">quadprog:" + ("SOLVED" if ok_q else "INFEASIBLE")
            if ok_q and active_set.rows_hold(problem.C, problem.lower, problem.upper, zq, tol):
                return zq, mq, status, iters
            if ok_q:
                status += "_CHECK_FAILED"
        return (z if ok else None), mult, status, iters

    # ---------------------------------------------------------------- filtering
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
        x = np.asarray(x, dtype=float)
        u_des = np.asarray(u_des, dtype=float)
        if x.shape != (STATE_SIZE,) or u_des.shape != (3,):
            raise ValueError(f"filter takes x ({STATE_SIZE},) and u_des (3,), got {x.shape} and {u_des.shape}")
        m = len(self.names)
        # the record's arrays are new each call; lo, hi and info are scratch (not in the record)
        u, h, psi0, psi1, bc = np.empty(3), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
        slack, intervening = np.zeros(m), np.zeros(m, dtype=np.bool_)
        box_active, uncontrollable = np.zeros(3, dtype=np.bool_), np.zeros(m, dtype=np.bool_)
        lo, hi, info_array = self._scratch
        if self.options.solver == "active_set":
            kernel.filter_active_set(x, u_des, self._params, self._enabled, self._slack_weight,
                                     self.options.check_tolerance, self._policy, self.options.soften_weight,
                                     active_set.MAX_ACTIVE_SET_ITER, u, h, psi0, psi1, bc, slack, intervening,
                                     box_active, uncontrollable, lo, hi, info_array)
            info = info_array.tolist()
            solver_status = _kernel_status_text(info)
        else:
            out = _Outputs(u, h, psi0, psi1, bc, slack, intervening, box_active, uncontrollable, lo, hi, info_array)
            solver_status = self._filter_proxsuite(x, u_des, out)
            info = info_array.tolist()
        self._count_one(info)
        if info[kernel.INFO_RAISE]:
            raise SolverError(f"ASIF QP failed with status {solver_status}")
        return FilterResult(u, u_des, self.names, h, psi0, psi1, bc, slack, intervening, box_active,
                            STATUS_NAMES[info[kernel.INFO_STATUS]], solver_status, info[kernel.INFO_ITERATIONS],
                            self._fallback_text(info[kernel.INFO_FALLBACK]), uncontrollable,
                            time.perf_counter() - t0)  # positional: FilterResult's field order

    def filter_batch(self, x: Array, u_des: Array) -> BatchResult:
        """Filter a batch: x (N, 19), u_des (N, 3). Every state goes through the same per-state
        code as `filter` (compiled in one loop with the active-set solver), so a run inside a batch
        and a single run compute the same numbers."""
        x = np.ascontiguousarray(x, dtype=float)
        u_des = np.ascontiguousarray(u_des, dtype=float)
        if x.ndim != 2 or x.shape[1] != STATE_SIZE or u_des.shape != (x.shape[0], 3):
            raise ValueError(f"filter_batch takes x (N, {STATE_SIZE}) and u_des (N, 3), got {x.shape} and "
                             f"{u_des.shape}")
        n, m = x.shape[0], len(self.names)
        out = _Outputs.empty(m, n)
        if self.options.solver == "active_set":
            kernel.filter_active_set_many(x, u_des, self._params, self._enabled, self._slack_weight,
                                          self.options.check_tolerance, self._policy, self.options.soften_weight,
                                          active_set.MAX_ACTIVE_SET_ITER, out.u, out.h, out.psi0, out.psi1, out.bc,
                                          out.slack, out.intervening, out.box_active, out.uncontrollable, out.lo,
                                          out.hi, out.info)
            solver_status = np.array([_kernel_status_text(i) if i[kernel.INFO_SOLVER] >= 0 else "" for i in out.info],
                                     dtype=str) if n else np.zeros(0, dtype=str)
        else:
            texts = []
            for k in range(n):
                texts.append(self._filter_proxsuite(x[k], u_des[k], out.row(k)))
            solver_status = np.array(texts, dtype=str)
        self._count(out.info)
        if np.any(out.info[:, kernel.INFO_RAISE]):
            k = int(np.flatnonzero(out.info[:, kernel.INFO_RAISE])[0])
            raise SolverError(f"ASIF QP failed with status {solver_status[k]} (state {k} of the batch)")
        fallback = np.array([self._fallback_text(int(c)) for c in out.info[:, kernel.INFO_FALLBACK]], dtype=str)
        return BatchResult(
            u=out.u, h=out.h, psi0=out.psi0, psi1=out.psi1, bc=out.bc, slack=out.slack,
            intervening=out.intervening, box_active=out.box_active,
            status=out.info[:, kernel.INFO_STATUS].astype(np.int8), solver_status=solver_status,
            iterations=out.info[:, kernel.INFO_ITERATIONS].copy(), fallback=fallback,
            uncontrollable=out.uncontrollable, qp_failed=out.info[:, kernel.INFO_QP_FAILED].astype(bool),
        )  # fmt: skip

    def _filter_proxsuite(self, x: Array, u_des: Array, out: _Outputs) -> str:
        """One call with proxsuite (and the backup solver) as the QP solver, around the compiled
        rows and QP; the same steps as `filter_kernel.filter_active_set`. Returns the solver status."""
        m = len(self.names)
        drift, gain, gnorm, u_target = np.empty(m), np.empty((m, 3)), np.empty(m), np.empty(3)
        info = out.info
        info[:] = 0
        info[kernel.INFO_SOLVER] = info[kernel.INFO_SOFT_SOLVER] = -1
        out.slack[:] = 0.0
        out.intervening[:] = False
        code, finite_des = kernel.prepare(x, u_des, self._params, self._enabled, self.options.check_tolerance,
                                          out.h, out.psi0, out.psi1, drift, gain, out.lo, out.hi, gnorm, u_target,
                                          out.uncontrollable)
        solver_status = ""
        if code == kernel.PREP_INVALID:
            out.u[:] = 0.0
            info[kernel.INFO_STATUS] = kernel.CODE_FALLBACK
            info[kernel.INFO_FALLBACK] = kernel.FB_INVALID
            kernel.finish(drift, gain, out.u, out.lo, out.hi, u_target, out.bc, out.box_active)
            out.h[:] = out.psi0[:] = out.psi1[:] = out.bc[:] = np.nan
            return solver_status
        out.u[:] = np.clip(u_target, out.lo, out.hi)
        if code == kernel.PREP_QP:
            problem = self._problem(*kernel.assemble(drift, gain, out.lo, out.hi, u_target, self._enabled, gnorm,
                                                     self._slack_weight, False, self.options.soften_weight))
            z, mult, solver_status, iters = self.solve_proxsuite(problem)
            info[kernel.INFO_SOLVER] = 0 if z is not None else 1
            info[kernel.INFO_ITERATIONS] = iters
            fb = kernel.FB_NONE if finite_des else kernel.FB_NON_FINITE
            if z is None:
                info[kernel.INFO_QP_FAILED] = 1
                fb = kernel.FB_POLICY
                log.debug("QP failed (%s); fallback %s", solver_status, self.options.fallback)
                if self._policy == kernel.POLICY_RAISE:
                    info[kernel.INFO_RAISE] = 1
                elif self._policy == kernel.POLICY_SOFTEN:
                    problem = self._problem(*kernel.assemble(drift, gain, out.lo, out.hi, u_target, self._enabled,
                                                             gnorm, self._slack_weight, True,
                                                             self.options.soften_weight))
                    z, mult, status2, it2 = self.solve_proxsuite(problem)
                    info[kernel.INFO_SOFT_SOLVER] = 0 if z is not None else 1
                    info[kernel.INFO_ITERATIONS] += it2
                    solver_status = f"{solver_status}+soften:{status2}"
                if z is None and self._policy == kernel.POLICY_HOLD:
                    out.u[:] = np.clip(np.zeros(3), out.lo, out.hi)
            if z is not None:
                row_of = np.array([self.names.index(nm) for nm in problem.row_names[:-3]], dtype=np.int64)
                slack_var = np.full(m, -1, dtype=np.int64)
                for i, v in problem.slack_index.items():
                    slack_var[i] = v
                kernel.extract(z, mult, out.lo, out.hi, row_of, slack_var, problem.slack_scale, out.u, out.slack,
                               out.intervening)
            info[kernel.INFO_FALLBACK] = fb
            info[kernel.INFO_STATUS] = kernel.CODE_FALLBACK if fb != kernel.FB_NONE else kernel.CODE_SOLVED
        else:
            info[kernel.INFO_STATUS] = kernel.CODE_PASS
        kernel.finish(drift, gain, out.u, out.lo, out.hi, u_target, out.bc, out.box_active)
        return solver_status

    def _fallback_text(self, code: int) -> str:
        return ("", "non_finite_u_des", self.options.fallback, "invalid_state")[code]

    def _count_one(self, info: list[int]) -> None:
        """Add one call with info (N_INFO,) to the counters (`_count` for one call, on Python ints)."""
        c = self.counters
        status = info[kernel.INFO_STATUS]
        c.calls += 1
        if status == CODE_PASS:
            c.fast_path += 1
        elif status == CODE_SOLVED:
            c.solved += 1
        else:
            c.fallbacks += 1
        c.solver_failures += info[kernel.INFO_QP_FAILED]
        c.invalid_states += info[kernel.INFO_FALLBACK] == kernel.FB_INVALID
        name = STATUS_NAMES[status]
        c.by_status[name] = c.by_status.get(name, 0) + 1

    def _count(self, info: NDArray[np.int64]) -> None:
        """Add calls with info rows (N, N_INFO) to the counters."""
        c = self.counters
        status = info[:, kernel.INFO_STATUS]
        c.calls += len(info)
        c.fast_path += int(np.count_nonzero(status == CODE_PASS))
        c.solved += int(np.count_nonzero(status == CODE_SOLVED))
        c.fallbacks += int(np.count_nonzero(status == CODE_FALLBACK))
        c.solver_failures += int(np.count_nonzero(info[:, kernel.INFO_QP_FAILED]))
        c.invalid_states += int(np.count_nonzero(info[:, kernel.INFO_FALLBACK] == kernel.FB_INVALID))
        for code, name in enumerate(STATUS_NAMES):
            k = int(np.count_nonzero(status == code))
            if k:
                c.by_status[name] = c.by_status.get(name, 0) + k


@dataclass
class _Outputs:
    """Output arrays of one call (shapes (m,), (3,), ...) or of N calls (leading N axis)."""

    u: Array
    h: Array
    psi0: Array
    psi1: Array
    bc: Array
    slack: Array
    intervening: NDArray[np.bool_]
    box_active: NDArray[np.bool_]
    uncontrollable: NDArray[np.bool_]
    lo: Array
    hi: Array
    info: NDArray[np.int64]

    @classmethod
    def empty(cls, m: int, n: int | None = None) -> _Outputs:
        lead: tuple[int, ...] = () if n is None else (n,)
        return cls(np.empty((*lead, 3)), np.empty((*lead, m)), np.empty((*lead, m)), np.empty((*lead, m)),
                   np.empty((*lead, m)), np.zeros((*lead, m)), np.zeros((*lead, m), dtype=np.bool_),
                   np.zeros((*lead, 3), dtype=np.bool_), np.zeros((*lead, m), dtype=np.bool_), np.empty((*lead, 3)),
                   np.empty((*lead, 3)), np.zeros((*lead, kernel.N_INFO), dtype=np.int64))

    def row(self, k: int) -> _Outputs:
        """Views of call k of a batch."""
        return _Outputs(*(getattr(self, f.name)[k] for f in fields(self)))


_kernels_ready = False
"""compile_kernels has run in this process."""


def compile_kernels(cfg: Config) -> float:
    """Compile the filter's numba kernels, or load them from numba's on-disk cache (the first call
    in a fresh installation compiles for ~20-40 s; later processes load in ~0.5-1 s), once per
    process. `AsifFilter()` calls it, so no filter call (and no message of a node) waits for a
    compiler and the first call's time is like any other's.

    Returns the seconds it took (0 once done in this process).
    """
    global _kernels_ready
    if _kernels_ready:
        return 0.0
    _kernels_ready = True
    t0 = time.perf_counter()
    x = np.zeros(STATE_SIZE)
    x[3], x[10], x[11] = 1.0, 273.15, 5000.0
    u = np.zeros(3)
    f = AsifFilter(cfg.with_solver("active_set"))
    f.filter(x, u)
    f.filter_batch(x[None], u[None])
    m = len(f.names)
    out = _Outputs.empty(m)
    drift, gain, gnorm, u_target = np.ones(m), np.ones((m, 3)), np.ones(m), np.zeros(3)
    kernel.prepare(x, u, f._params, f._enabled, 1e-6, out.h, out.psi0, out.psi1, drift, gain, out.lo, out.hi, gnorm,
                   u_target, out.uncontrollable)
    C, lower, upper, z0, row_of, slack_var, scale, _n = kernel.assemble(
        drift, gain, out.lo, out.hi, u_target, f._enabled, gnorm, f._slack_weight, False, 1.0)
    z, mult = z0.copy(), np.zeros(len(lower))  # any point: this only compiles the proxsuite path's helpers
    active_set.rows_hold(C, lower, upper, z, 1e-6)
    kernel.is_stationary(C, lower, upper, z, mult, -z0, 1e-6)
    kernel.extract(z, mult, out.lo, out.hi, row_of, slack_var, scale, out.u, out.slack, out.intervening)
    kernel.finish(drift, gain, out.u, out.lo, out.hi, u_target, out.bc, out.box_active)
    return time.perf_counter() - t0


ACTIVE_SET_STATUS: tuple[str, ...] = ("ACTIVE_SET_SOLVED", "ACTIVE_SET_INFEASIBLE", "ACTIVE_SET_MAX_ITER")
"""Solver status names of the active-set solver, by its code."""


def _active_set_status(code: int, check_failed: bool) -> str:
    return ACTIVE_SET_STATUS[int(code)] + ("_CHECK_FAILED" if check_failed else "")


def _kernel_status_text(info: NDArray[np.int64] | list[int]) -> str:
    """Solver status of a compiled active-set call from its info vector."""
    if info[kernel.INFO_SOLVER] < 0:
        return ""
    text = _active_set_status(info[kernel.INFO_SOLVER], bool(info[kernel.INFO_CHECK_FAILED]))
    if info[kernel.INFO_SOFT_SOLVER] >= 0:
        soft = _active_set_status(info[kernel.INFO_SOFT_SOLVER], bool(info[kernel.INFO_SOFT_CHECK_FAILED]))
        text += "+soften:" + soft
    return text


__all__ = [
    "AsifFilter", "BatchResult", "FilterCounters", "FilterResult", "QpProblem", "STATUS_FALLBACK", "STATUS_PASS",
    "STATUS_SOLVED", "compile_kernels",
]  # fmt: skip
