"""Active Set Invariance Filter: the minimal change of u_des that keeps every barrier condition.

    min_{u, s}  ||u - u_des||^2 + ||s||^2
    s.t.        BC_i(x, u) + s_i / sqrt(p_i) >= 0     slacked constraints (delta_i = s_i / sqrt(p_i))
                BC_i(x, u)                   >= 0     hard constraints
                lo(x) <= u <= hi(x)                   admissible set U (and, in the `robust` preset,
                                                      the one-step-ahead ZOH bounds on omega and psi)

BC_i(x, u) = drift_i(x) + gain_i(x) . u is defined in `rta_attitude.constraints` (one module per
constraint). The slack is scaled (cost s^2 instead of p delta^2: p = 1e12 would ruin the Hessian's
conditioning), every row is normalised to unit norm, and every solution is checked against the rows
before it is used. Fast path: u0 = clip(u_des, lo, hi) is the exact QP solution whenever it meets
every row, so the solver is not called then. The call runs compiled (`filter.pipeline`, one
pipeline whatever the solver); this module is its Python face: `AsifFilter` holds the records, and
`FilterResult` reads the result record (one state, or a batch with a leading axis).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.errors import SolverError
from rta_attitude.filter import outcome
from rta_attitude.filter.gatekeeper.gate import reset
from rta_attitude.filter.pipeline import filter_many
from rta_attitude.filter.records import RESULT_DTYPE, filter_record, new_workspace
from rta_attitude.jit import LEAF
from rta_attitude.kernel_cache import drop_stale_caches

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

STATUS_PASS, STATUS_SOLVED, STATUS_FALLBACK = outcome.STATUS_NAMES
"""The names of a call's status."""
PER_CONSTRAINT = frozenset({"h", "psi0", "psi1", "bc", "slack", "intervening", "uncontrollable"})
"""RESULT_DTYPE's fields with one entry per row (MAX_ROWS, of which a configuration uses its n_rows)."""


class FilterResult:
    """What filter call(s) did: a view of RESULT_DTYPE record(s), shape () for one state or (N,).

    Array fields follow `names` (the configuration's constraints, `Config.constraint_names`) on their last axis
    (m) or are per axis of u (3): u (the command sent),
    u_held (the filter's answer: what the wheels hold over the sample; u but where the drive's lag is
    compensated, `filter.drive.drive_command`), u_des, h, psi0,
    psi1, bc (barrier conditions at u, slack not included), slack, intervening (rows active at the
    solution), uncontrollable, box_active, lo, hi. Text fields: status ('pass', 'solved', 'fallback'),
    fallback (the policy applied, 'non_finite_u_des', 'invalid_state' or ''), solver_status, gate
    (what the gatekeeper did: 'off', 'verified', 'backup', 'unverified', 'toward_backup', 'filtered_backup').
    """

    def __init__(self, record: NDArray[np.void], policy: str, levels: tuple[tuple[str, ...], ...],
                 names: tuple[str, ...]) -> None:
        self.record = record
        self.policy = policy
        self.levels = levels
        """`Config.priority_levels` (the names `gave_way` reports)."""
        self.names = names

    def _field(self, name: str) -> NDArray[np.generic]:
        a = self.record[name]
        return a[..., : len(self.names)] if name in PER_CONSTRAINT else a

    u = property(lambda self: self._field("u"))
    u_held = property(lambda self: self._field("u_held"))
    u_des = property(lambda self: self._field("u_des"))
    h = property(lambda self: self._field("h"))
    psi0 = property(lambda self: self._field("psi0"))
    psi1 = property(lambda self: self._field("psi1"))
    bc = property(lambda self: self._field("bc"))
    slack = property(lambda self: self._field("slack"))
    lo = property(lambda self: self._field("lo"))
    hi = property(lambda self: self._field("hi"))
    intervening = property(lambda self: self._field("intervening").astype(bool))
    uncontrollable = property(lambda self: self._field("uncontrollable").astype(bool))
    box_active = property(lambda self: self._field("box_active").astype(bool))
    status_code = property(lambda self: self._field("status"))
    qp_failed = property(lambda self: self._field("qp_failed").astype(bool))

    @property
    def iterations(self) -> int | NDArray[np.int64]:
        it = self.record["iterations"]
        return int(it) if np.ndim(it) == 0 else it

    @property
    def solve_time_s(self) -> float | Array:
        t = self.record["solve_time_s"]
        return float(t) if np.ndim(t) == 0 else t

    def _text(self, fn: object) -> str | NDArray[np.str_]:
        if self.record.ndim == 0:
            return fn(self.record)  # type: ignore[operator]
        return np.array([fn(r) for r in self.record], dtype=str)  # type: ignore[operator]

    @property
    def status(self) -> str | NDArray[np.str_]:
        return self._text(lambda r: outcome.STATUS_NAMES[int(r["status"])])

    @property
    def fallback(self) -> str | NDArray[np.str_]:
        def text(r: np.void) -> str:
            reason = int(r["fallback"])
            return self.policy if reason == outcome.POLICY_ACTED else outcome.FALLBACK_REASONS[reason]

        return self._text(text)

    @property
    def gate(self) -> str | NDArray[np.str_]:
        """What the gatekeeper did (outcome.GATE_NAMES: 'off' without a backup law)."""
        return self._text(lambda r: outcome.GATE_NAMES[int(r["gate"])])

    @property
    def gave_way(self) -> str | NDArray[np.str_]:
        """The `prioritize` fallback: the most important level of `filter.priorities` that gave way, as its
        groups joined by '+' ('' where none did)."""
        return self._text(lambda r: "+".join(self.levels[int(r["gave_way"])]) if int(r["gave_way"]) >= 0 else "")

    @property
    def solver_status(self) -> str | NDArray[np.str_]:
        def text(r: np.void) -> str:
            first = outcome.solve_text(int(r["solver"]), int(r["solve_result"]), int(r["backup_result"]))
            if int(r["soft_result"]) != outcome.NOT_SOLVED:
                first += f"+{self.policy}:" + outcome.solve_text(int(r["solver"]), int(r["soft_result"]))
            return first

        return self._text(text)

    @property
    def intervened(self) -> bool | NDArray[np.bool_]:
        """u differs from u_des because of any row or the box."""
        out = self.intervening.any(axis=-1) | self.box_active.any(axis=-1)
        return bool(out) if np.ndim(out) == 0 else out

    def __getitem__(self, k: int) -> FilterResult:
        """Call k of a batch."""
        return FilterResult(self.record[k], self.policy, self.levels, self.names)

    def __len__(self) -> int:
        return len(self.record)


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

    def add_one(self, record: NDArray[np.void]) -> None:
        """Count one call (a record of shape ()): `add` without the array work (the nodes call this
        at every step)."""
        status, fallback = int(record["status"]), int(record["fallback"])
        qp_failed, backup = int(record["qp_failed"]), int(record["backup_result"])
        self.calls += 1
        if status == outcome.PASS:
            self.fast_path += 1
        elif status == outcome.SOLVED:
            self.solved += 1
        else:
            self.fallbacks += 1
        self.solver_failures += qp_failed != 0
        self.backup_solves += backup != outcome.NOT_SOLVED
        self.invalid_states += fallback == outcome.INVALID_STATE
        name = outcome.STATUS_NAMES[status]
        self.by_status[name] = self.by_status.get(name, 0) + 1

    def add(self, record: NDArray[np.void]) -> None:
        """Count the calls of result record(s) (shape () or (N,))."""
        status = np.atleast_1d(record["status"])
        self.calls += len(status)
        counts = [int(np.count_nonzero(status == code)) for code in range(len(outcome.STATUS_NAMES))]
        self.fast_path += counts[outcome.PASS]
        self.solved += counts[outcome.SOLVED]
        self.fallbacks += counts[outcome.FALLBACK]
        self.solver_failures += int(np.count_nonzero(record["qp_failed"]))
        self.backup_solves += int(np.count_nonzero(np.atleast_1d(record["backup_result"]) != outcome.NOT_SOLVED))
        self.invalid_states += int(np.count_nonzero(np.atleast_1d(record["fallback"]) == outcome.INVALID_STATE))
        for code, n in enumerate(counts):
            if n:
                name = outcome.STATUS_NAMES[code]
                self.by_status[name] = self.by_status.get(name, 0) + n


@numba.njit(**LEAF)
def _reset_gate(ws: NDArray[np.void]) -> None:
    reset(ws[0].gate)  # the gatekeeper's one reset (gatekeeper.gate.reset)


class AsifFilter:
    """The ASIF safety filter of one configuration; call `filter(x, u_des)` or `filter_batch(X, U)`.

    Builds its records once (and loads or compiles the kernels, so no call waits for a compiler). Not
    thread-safe (one workspace).
    """

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.record = filter_record(cfg)
        self.constraints = ConstraintSet(cfg)
        self.names = self.constraints.names
        self.u_max = cfg.u_max_rad_s2
        self.options = cfg.filter
        self.enabled = self.constraints.enabled
        self.slack_weights = self.constraints.slack_weights
        self.slacked = self.enabled & (self.slack_weights > 0)
        self.counters = FilterCounters()
        self._ws = new_workspace()
        self._out = np.zeros(1, RESULT_DTYPE)
        self._x1 = np.zeros((1, STATE_SIZE))
        self._u1 = np.zeros((1, 3))
        self._t1 = np.zeros(1)
        self.levels = cfg.priority_levels
        compile_kernels(cfg)

    def fail_wheels(self, cfg: Config) -> None:
        """Take cfg's failed wheels (`spacecraft.failed_wheels`, the one thing it may change here) while running:
        the records are rebuilt in place (the box 0 on a failed wheel) and the counters kept. The gatekeeper's
        committed plan was verified with the wheel, so it is forgotten, with the drive's state and the answer in
        flight (`reset`: the filter starts over from the next state)."""
        self.cfg = cfg
        self.record[:] = filter_record(cfg)
        self.constraints = ConstraintSet(cfg)  # (its box too: `evaluate` answers as the filter does)
        self.u_max = cfg.u_max_rad_s2
        self.reset()

    def reset(self) -> None:
        """Forget the gatekeeper's committed plan, the drive's state and the answer in flight (a new run starts;
        nothing else carries over)."""
        _reset_gate(self._ws)

    def filter(self, x: Array, u_des: Array, t_s: float = 0.0) -> FilterResult:
        """Filter one desired command.

        Args:
            x: state (19,), model units.
            u_des: desired wheel accelerations (3,), rad/s^2 (non-finite entries are treated as 0 and
                the call is counted as a fallback).
            t_s: the time of x, s from the run's start (t = 0 of the scenario): where the configured pointing
                constraints' windows are (none configured: any time gives the same answer).

        Returns:
            FilterResult (one record) with u_act and the per-constraint record.

        Raises:
            SolverError: the QP failed and the fallback policy is 'raise'.
        """
        t0 = time.perf_counter()
        sx = x.shape if isinstance(x, np.ndarray) else np.shape(x)
        su = u_des.shape if isinstance(u_des, np.ndarray) else np.shape(u_des)
        if sx != (STATE_SIZE,) or su != (3,):
            raise ValueError(f"filter takes x ({STATE_SIZE},) and u_des (3,), got {sx} and {su}")
        self._x1[0] = x
        self._u1[0] = u_des
        self._t1[0] = t_s
        # arrays, not record scalars, cross into compiled code: numba types a record scalar at every
        # call (~28 us), an array of records once per dtype (~1.5 us)
        filter_many(self._x1, self._u1, self._t1, self.record, self._ws, self._out)
        # a byte copy: numpy copies a record with array fields field by field, 10 times slower
        rec = np.frombuffer(bytearray(self._out.tobytes()), RESULT_DTYPE).reshape(())
        rec["solve_time_s"] = time.perf_counter() - t0
        result = FilterResult(rec, self.options.fallback, self.levels, self.names)
        self.counters.add_one(rec)
        if rec["raise_error"]:
            raise SolverError(f"ASIF QP failed ({result.solver_status})")
        return result

    def filter_batch(self, x: Array, u_des: Array, t_s: float | Array = 0.0) -> FilterResult:
        """Filter a batch: x (N, 19), u_des (N, 3) at times t_s (s; one for all, or (N,)); every state through
        the same compiled call as `filter`, so a run inside a batch and a single run compute the same numbers.
        The filter's memory (the gatekeeper's plan; with a transport delay, the answer in flight) carries from
        each state to the next, as from one sample to the next: `reset()` between unrelated batches.

        Raises:
            SolverError: a QP failed and the fallback policy is 'raise' (the first such state named).
        """
        x = np.ascontiguousarray(x, dtype=float)
        u_des = np.ascontiguousarray(u_des, dtype=float)
        if x.ndim != 2 or x.shape[1] != STATE_SIZE or u_des.shape != (x.shape[0], 3):
            raise ValueError(f"filter_batch takes x (N, {STATE_SIZE}) and u_des (N, 3), got {x.shape} and "
                             f"{u_des.shape}")
        out = np.zeros(x.shape[0], RESULT_DTYPE)
        t = np.ascontiguousarray(np.broadcast_to(np.asarray(t_s, dtype=float), (x.shape[0],)))
        filter_many(x, u_des, t, self.record, self._ws, out)
        result = FilterResult(out, self.options.fallback, self.levels, self.names)
        self.counters.add(out)
        if np.any(out["raise_error"]):
            k = int(np.flatnonzero(out["raise_error"])[0])
            raise SolverError(f"ASIF QP failed ({result[k].solver_status}) (state {k} of the batch)")
        return result


_kernels_ready = False
"""compile_kernels has run in this process."""


def compile_kernels(cfg: Config) -> float:
    """Compile the filter's kernels, or load them from numba's on-disk cache (a fresh installation
    compiles for tens of seconds; later processes load in about a second), once per process, by one
    call of each on a dummy state. `AsifFilter()` calls it, so no filter call waits for a compiler.

    Returns the seconds it took (0 once done in this process).
    """
    global _kernels_ready
    if _kernels_ready:
        return 0.0
    _kernels_ready = True
    t0 = time.perf_counter()
    drop_stale_caches()
    x = np.zeros(STATE_SIZE)
    x[3], x[10], x[11] = 1.0, 273.15, 5000.0
    rec = filter_record(cfg)
    ws, out = new_workspace(), np.zeros(1, RESULT_DTYPE)
    filter_many(x[None], np.zeros((1, 3)), np.zeros(1), rec, ws, out)
    _reset_gate(ws)
    return time.perf_counter() - t0


__all__ = ["STATUS_FALLBACK", "STATUS_PASS", "STATUS_SOLVED", "AsifFilter", "FilterCounters", "FilterResult",
           "compile_kernels"]
