"""Many runs of the closed loop: a compiled loop over runs of the one-state step, on local processes or
a Dask cluster.

Each run is `simulation.closed_loop.advance` from its initial state with the campaign's primary
controller (`montecarlo.controllers`): u_des = 0 (none, the paper's protocol), or the PD law
(`pd_command`) toward the run's targets, computed in the compiled loop exactly as `run_scenario`
computes it; so a run here equals `simulate` of the same state and targets bit for bit (tested). Per
run the compiled loop keeps only what the report needs: which constraints were violated at a sample
or at an RK4 substep and when first, the smallest h at the samples, the filter's QP, fallback and
failure counts, the largest slack, the final state (and, on request, the states at every sample).

Runs are independent, so their results do not depend on the chunk or the worker they ran in: the
local backend (`fork`ed processes) and the Dask backend give identical results.

Another simulator than the compiled one (`plant.simulator: basilisk`), and a user's Python controller
(`--controller module:function`), run each state through `simulation.closed_loop.run_stepped`, a Python
loop over the plant's steps with the same filter call (`run_runs_stepped`); its outcome has the same
fields, computed from the run's samples and substeps as the compiled loop marks them (over the compiled
plant the two are equal bit for bit, tested). That loop adds ~0.1 ms of Python per step around the
compiled filter and plant (~0.2 s of CPU per 2,000 s run): 1.2-1.4x the compiled loop's run in the
default configuration, whose gatekeeper costs more than that, ~10x where the filter alone is cheap
(paper model, no gatekeeper: 0.02 s per run compiled); docs/montecarlo.md, "Your controller".
"""

from __future__ import annotations

import itertools
import logging
import math
import multiprocessing as mp
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.base import MAX_ROWS
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.rows import safety_values
from rta_attitude.dynamics.controller import ControllerError, PrimaryController, pd_command
from rta_attitude.dynamics.plant import Plant
from rta_attitude.dynamics.sensors import INSTRUMENT_DTYPE, read, reset_instruments
from rta_attitude.dynamics.spacecraft import RK4_WORK_ROWS, demand_round_trip
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.errors import RtaError
from rta_attitude.filter.gatekeeper.gate import reset
from rta_attitude.filter.outcome import FALLBACK, GATE_NAMES, PASS
from rta_attitude.filter.records import RESULT_DTYPE, WORKSPACE_DTYPE, WORKSPACES
from rta_attitude.jit import JIT, LEAF
from rta_attitude.kernel_cache import drop_stale_caches
from rta_attitude.montecarlo import DEFAULT_CHUNK_RUNS
from rta_attitude.montecarlo.controllers import RunController
from rta_attitude.simulation.closed_loop import advance, command_row, loop_record

Array = NDArray[np.float64]
log = logging.getLogger(__name__)
M = MAX_ROWS
PROGRESS_RUNS = 20
"""Runs per compiled call, between two progress updates."""


@dataclass
class BatchOutcome:
    """Per-run results (N runs, m constraints in the configuration's row order, `Config.constraint_names`).

    Attributes:
        violated_samples: (N, m) h < 0 at some sample t_k (the paper's criterion).
        violated_substeps: (N, m) h < 0 at some sample or RK4 substep.
        first_violation_s: (N, m) earliest sample or substep time with h < 0, NaN if none.
        min_h_samples: (N, m) smallest h over the samples.
        qp_steps, fallback_steps, qp_failures: (N,) steps that needed the QP, that ended in the
            fallback, and whose first QP failed.
        max_comm_slack: (N,) largest |delta| of the slacked constraints (in their h's units).
        gate_steps: (N, len(GATE_NAMES)) steps by what the gatekeeper did (all 'off' without a
            backup law; `filter.outcome.GATE_NAMES`).
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
    gate_steps: NDArray[np.int64]
    x_final: Array
    trajectory: Array | None = None


@numba.njit(**LEAF)
def _mark(h: Array, t: float, sample: bool, k: int, viol_s: NDArray[np.bool_], viol_sub: NDArray[np.bool_],
          first: Array) -> None:
    for i in range(viol_s.shape[1]):
        if h[i] < 0:
            if sample:
                viol_s[k, i] = True
            viol_sub[k, i] = True
            if first[k, i] != first[k, i]:
                first[k, i] = t


@numba.njit(**JIT)
def run_batch(X0: Array, steps: int, loop: NDArray[np.void], sched_t: Array, sched_q: Array,
              viol_s: NDArray[np.bool_], viol_sub: NDArray[np.bool_], first: Array, min_h: Array,
              qp_steps: NDArray[np.int64], fb_steps: NDArray[np.int64], qp_fail: NDArray[np.int64], max_slack: Array,
              gate_steps: NDArray[np.int64], x_final: Array, traj: Array, record: bool, first_run: int) -> None:
    """Run every initial state X0 (N, 19) for `steps` samples; outputs with a leading N (see BatchOutcome;
    traj (N, steps + 1, 19) is filled only if record). Without a primary controller (the loop record's
    controller.pd = 0) u_des = 0; with the PD law, run k tracks its targets sched_q[k] (K, 4) commanded
    at sched_t (K,), as `run_scenario` does (the law on the measured state, then the torque interface).
    Run k of X0 has the sensors' noise sequence first_run + k (its index in the campaign); the caller's
    loop record is left as it was (its sensors' stream restored at the end)."""
    lp = loop[0]
    stream0 = lp.sensors.stream
    p, c = lp.plant, lp.filter.constraints
    S = lp.substeps
    dt = lp.dt_s
    ws = np.zeros(WORKSPACES, WORKSPACE_DTYPE)
    ctx = np.zeros(1, CONTEXT_DTYPE)
    r = np.zeros(1, RESULT_DTYPE)
    u_des, u, u_pd = np.zeros(3), np.empty(3), np.empty(3)
    y, yd = np.empty(STATE_SIZE), np.empty(STATE_SIZE)
    ins = np.zeros(1, INSTRUMENT_DTYPE)
    subs = np.empty((S, STATE_SIZE))
    work = np.zeros((RK4_WORK_ROWS, STATE_SIZE))
    hs = np.empty((S, M))
    h = np.empty(M)
    n = c.n_rows
    slacked = np.zeros(M, dtype=np.bool_)
    for i in range(n):
        slacked[i] = c.gains[i].enabled != 0 and c.gains[i].slack_weight > 0
    sub_t = np.empty(S)
    for j in range(S):
        sub_t[j] = dt * (j + 1) / S
    for k in range(X0.shape[0]):
        x = X0[k].copy()
        lp.sensors.stream = first_run + k
        reset_instruments(ins[0])
        reset(ws[0].gate)  # each run starts without a committed plan
        if record:
            traj[k, 0] = x
        for i in range(n):
            first[k, i] = np.nan
            min_h[k, i] = np.inf
        for step in range(steps):
            t = step * dt
            safety_values(x, t, p, c, ctx[0], h)
            for i in range(n):
                if h[i] < min_h[k, i]:
                    min_h[k, i] = h[i]
            _mark(h, t, True, k, viol_s, viol_sub, first)
            read(x, step, lp.sensors, ins[0], y, yd)
            if lp.controller.pd:  # the branch run_scenario takes; without it u_des stays 0
                pd_command(yd, sched_q[k, command_row(sched_t, t)], lp.controller, u_pd)
                demand_round_trip(u_pd, p, u_des)
            advance(x, yd, u_des, step, lp, ins[0], ws, r[0], u, subs, hs, ctx[0], work)
            status = r[0].status
            if status != PASS:
                qp_steps[k] += 1
            if status == FALLBACK:
                fb_steps[k] += 1
            qp_fail[k] += r[0].qp_failed
            gate_steps[k, r[0].gate] += 1
            for i in range(n):
                if slacked[i] and abs(r[0].slack[i]) > max_slack[k]:
                    max_slack[k] = abs(r[0].slack[i])
            for j in range(S - 1):  # the last substep is the next sample, checked there
                _mark(hs[j], t + sub_t[j], False, k, viol_s, viol_sub, first)
            x[:] = subs[S - 1]
            if record:
                traj[k, step + 1] = x
        safety_values(x, steps * dt, p, c, ctx[0], h)
        for i in range(n):
            if h[i] < min_h[k, i]:
                min_h[k, i] = h[i]
        _mark(h, steps * dt, True, k, viol_s, viol_sub, first)
        x_final[k] = x
    lp.sensors.stream = stream0


def _new_outcome(N: int, m: int, steps: int, record: bool) -> BatchOutcome:
    return BatchOutcome(np.zeros((N, m), dtype=bool), np.zeros((N, m), dtype=bool), np.full((N, m), np.nan),
                        np.full((N, m), np.inf), np.zeros(N, dtype=np.int64), np.zeros(N, dtype=np.int64),
                        np.zeros(N, dtype=np.int64), np.zeros(N), np.zeros((N, len(GATE_NAMES)), dtype=np.int64),
                        np.empty((N, STATE_SIZE)),
                        np.empty((N, steps + 1, STATE_SIZE)) if record else None)


def _check_states(x0: Array) -> Array:
    x0 = np.ascontiguousarray(x0, dtype=float)
    if x0.ndim != 2 or x0.shape[1] != STATE_SIZE:
        raise ValueError(f"x0 must be (N, {STATE_SIZE}), got {x0.shape}")
    return x0


def run_runs(cfg: Config, x0: Array, duration_s: float, record: bool = False,
             progress: Callable[[int], None] | None = None, first_run: int = 0,
             controller: RunController | None = None) -> BatchOutcome:
    """Run initial states x0 (N, 19) for duration_s in this process; progress(runs done) after each
    group of PROGRESS_RUNS runs (each run with another simulator than the compiled one or a Python
    controller). x0[k] is run first_run + k of its campaign (its sensor noise sequence and its targets).
    controller: the primary controller (default none: u_des = 0); a user's function runs through
    `run_runs_stepped`."""
    drop_stale_caches()  # a library entry point: its kernels inline other modules' (kernel_cache)
    ctrl = RunController() if controller is None else controller
    if cfg.plant.simulator != "compiled" or ctrl.kind == "python":
        return run_runs_stepped(cfg, x0, duration_s, record=record, progress=progress, first_run=first_run,
                                controller=ctrl)
    x0 = _check_states(x0)
    steps = round(duration_s / cfg.filter.sample_time_s)
    N = x0.shape[0]
    out = _new_outcome(N, len(cfg.constraint_names), steps, record)
    loop = loop_record(cfg, rta=True, pd=ctrl.kind == "pd")
    sched_t = ctrl.target_times(steps * cfg.filter.sample_time_s)
    sched_q = ctrl.targets(first_run, N, steps * cfg.filter.sample_time_s)
    traj = out.trajectory if out.trajectory is not None else np.empty((1, 1, STATE_SIZE))
    for a in range(0, N, PROGRESS_RUNS):
        b = min(a + PROGRESS_RUNS, N)
        run_batch(x0[a:b], steps, loop, sched_t, sched_q[a:b], out.violated_samples[a:b], out.violated_substeps[a:b],
                  out.first_violation_s[a:b], out.min_h_samples[a:b], out.qp_steps[a:b], out.fallback_steps[a:b],
                  out.qp_failures[a:b], out.max_comm_slack[a:b], out.gate_steps[a:b], out.x_final[a:b],
                  traj[a:b] if record else traj, record, first_run + a)
        if progress is not None:
            progress(b)
    return out


def run_runs_stepped(cfg: Config, x0: Array, duration_s: float, plant: Callable[[Config, Array], Plant] | None = None,
                     record: bool = False, progress: Callable[[int], None] | None = None, first_run: int = 0,
                     controller: RunController | None = None) -> BatchOutcome:
    """Run initial states x0 (N, 19) for duration_s with the primary controller (default none: u_des = 0),
    one `run_stepped` each, on the plant `plant(cfg, x0)` builds (default `dynamics.plant.make_plant`: the
    configured simulator); the outcome of `run_runs`, marked as `run_batch` marks it (samples and
    substeps in time order). progress(runs done) after each run.

    Raises:
        ControllerError: a user's controller answered other than 3 finite numbers, or raised (one line
            naming the controller and the run; `rta-attitude -v` logs the traceback).
    """
    from rta_attitude.dynamics.plant import make_plant
    from rta_attitude.filter.asif import AsifFilter
    from rta_attitude.simulation.closed_loop import run_stepped

    x0 = _check_states(x0)
    dt = cfg.filter.sample_time_s
    steps = round(duration_s / dt)
    S = cfg.substeps
    N = x0.shape[0]
    m = len(cfg.constraint_names)
    out = _new_outcome(N, m, steps, record)
    build = make_plant if plant is None else plant
    ctrl = RunController() if controller is None else controller
    function = ctrl.function() if ctrl.kind == "python" else None
    command = None if function is None else _guarded(function)
    reset_command = getattr(function, "reset", None)
    filt = AsifFilter(cfg)
    slacked = filt.slacked
    # the samples and the substeps before the next sample, in time order, with run_batch's times
    t = np.empty(steps * S + 1)
    for step in range(steps):
        t[step * S] = step * dt
        for j in range(S - 1):
            t[step * S + 1 + j] = step * dt + dt * (j + 1) / S
    t[-1] = steps * dt
    is_sample = np.zeros(steps * S + 1, dtype=bool)
    is_sample[::S] = True
    for k in range(N):
        scenario = ctrl.scenario(x0[k], first_run + k, steps * dt)
        filt.reset()
        if callable(reset_command):
            reset_command()
        try:
            with build(cfg, x0[k]) as p:
                run = run_stepped(cfg, scenario, steps, p, filt, stream=first_run + k, command=command)
        except ControllerError as exc:
            raise ControllerError(f"--controller {ctrl.name}, run {first_run + k}: {exc}") from None
        h = np.empty((steps * S + 1, m))
        h[::S] = run.h
        for j in range(S - 1):
            h[1 + j::S] = run.h_sub[:, j]
        neg = h < 0
        out.violated_samples[k] = neg[is_sample].any(axis=0)
        out.violated_substeps[k] = neg.any(axis=0)
        for i in np.flatnonzero(out.violated_substeps[k]):
            out.first_violation_s[k, i] = t[np.argmax(neg[:, i])]
        out.min_h_samples[k] = np.fmin.reduce(run.h, axis=0, initial=np.inf)  # NaN skipped, as run_batch
        status = run.results["status"]
        out.qp_steps[k] = np.count_nonzero(status != PASS)
        out.fallback_steps[k] = np.count_nonzero(status == FALLBACK)
        out.qp_failures[k] = int(run.results["qp_failed"].sum())
        out.gate_steps[k] = np.bincount(run.results["gate"], minlength=len(GATE_NAMES))
        if slacked.any():
            out.max_comm_slack[k] = float(np.fmax.reduce(np.abs(run.results["slack"][:, :m][:, slacked]), axis=None,
                                                         initial=0.0))
        out.x_final[k] = run.x[-1]
        if out.trajectory is not None:
            out.trajectory[k] = run.x
        if progress is not None:
            progress(k + 1)
    return out


def _guarded(function: PrimaryController) -> PrimaryController:
    """A user's controller whose exceptions become one-line ControllerErrors (the traceback goes to the debug
    log: `rta-attitude -v`)."""

    def call(y: Array, q_c: Array, t_s: float) -> Any:
        try:
            return function(y, q_c, t_s)
        except Exception as exc:
            log.debug("the primary controller raised at t = %g s", t_s, exc_info=True)
            raise ControllerError(f"it raised {type(exc).__name__}: {' '.join(str(exc).split())} at t = {t_s:g} s"
                                  ) from None

    return call


# ----------------------------------------------------------------------------- chunks and backends
@dataclass(frozen=True)
class ChunkTask:
    """One chunk of runs for a worker (picklable)."""

    cfg: Config
    x0: Array
    duration_s: float
    start: int
    controller: RunController = field(default_factory=RunController)


def run_chunk(task: ChunkTask, progress: Callable[[int], None] | None = None) -> tuple[int, BatchOutcome]:
    """Simulate one chunk; returns (start index, outcome)."""
    return task.start, run_runs(task.cfg, task.x0, task.duration_s, progress=progress, first_run=task.start,
                                controller=task.controller)


_COUNTER: Any = None


def _init_worker(counter: Any) -> None:
    global _COUNTER
    _COUNTER = counter
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _run_chunk_counted(task: ChunkTask) -> tuple[int, BatchOutcome]:
    last = [0]

    def tick(done: int) -> None:
        with _COUNTER.get_lock():
            _COUNTER.value += done - last[0]
        last[0] = done

    return run_chunk(task, tick)


def merge(parts: list[tuple[int, BatchOutcome]]) -> BatchOutcome:
    """One outcome from chunks (start, outcome), in run order."""
    outs = [o for _, o in sorted(parts, key=lambda p: p[0])]
    names = [f.name for f in fields(BatchOutcome) if f.name != "trajectory"]
    return BatchOutcome(**{n: np.concatenate([getattr(o, n) for o in outs]) for n in names})  # type: ignore[arg-type]


def split(runs: int, chunks: int) -> list[tuple[int, int]]:
    """(start, end) of `chunks` near-equal chunks of `runs` runs."""
    edges = np.linspace(0, runs, chunks + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges) if b > a]


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def progress_bar(total: int, show: bool) -> Any:
    """A tqdm bar over runs (or one that shows nothing)."""
    if not show:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, unit="run", desc="montecarlo", smoothing=0.1)


def run_local(cfg: Config, x0: Array, duration_s: float, workers: int, chunk_runs: int | None = None,
              progress: bool = False, controller: RunController | None = None) -> BatchOutcome:
    """Run every state on this machine: chunks over `workers` processes (1: in this process), with the
    primary controller (default none)."""
    runs = x0.shape[0]
    ctrl = RunController() if controller is None else controller
    n_chunks = max(1, math.ceil(runs / chunk_runs)) if chunk_runs else max(1, min(workers, runs))
    tasks = [ChunkTask(cfg, x0[a:b], duration_s, a, ctrl) for a, b in split(runs, n_chunks)]
    bar = progress_bar(runs, progress)
    if workers <= 1:
        parts = []
        for t in tasks:
            done = [0]

            def tick(n: int, done: list[int] = done) -> None:
                bar.update(n - done[0])
                done[0] = n

            parts.append(run_chunk(t, tick))
        bar.close()
        return merge(parts)
    # compile (or load) the kernels once here: forked workers inherit them
    run_runs(cfg, x0[:1], cfg.filter.sample_time_s, controller=ctrl if ctrl.kind != "python" else None)
    ctx = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    counter = ctx.Value("q", 0)
    with ctx.Pool(processes=min(workers, len(tasks)), initializer=_init_worker, initargs=(counter,)) as pool:
        pending = pool.map_async(_run_chunk_counted, tasks, chunksize=1)
        seen = 0
        while not pending.ready():
            pending.wait(0.5)
            v = counter.value
            bar.update(v - seen)
            seen = v
        parts = pending.get()
        bar.update(runs - seen)
    bar.close()
    return merge(parts)


def run_dask(cfg: Config, x0: Array, duration_s: float, scheduler: str | Any, chunk_runs: int = DEFAULT_CHUNK_RUNS,
             progress: bool = False, controller: RunController | None = None) -> BatchOutcome:
    """Run every state on a Dask cluster: one task per chunk of `chunk_runs` runs.

    Args:
        scheduler: the scheduler's address ('tcp://host:8786') or a distributed.Client.
        controller: the primary controller (default none); a user's function must be importable on the workers.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover - dask is in requirements.txt
        raise RtaError("the dask backend needs the 'distributed' package (pip install 'dask[distributed]')") from None
    runs = x0.shape[0]
    ctrl = RunController() if controller is None else controller
    tasks = [ChunkTask(cfg, x0[a:b], duration_s, a, ctrl) for a, b in split(runs, max(1, math.ceil(runs / chunk_runs)))]
    own = not isinstance(scheduler, Client)
    client: Client = Client(scheduler) if own else scheduler  # type: ignore[assignment]
    try:
        futures = client.map(run_chunk, tasks, pure=False)
        bar = progress_bar(runs, progress)
        parts = []
        for fut in as_completed(futures):
            start, out = fut.result()
            parts.append((start, out))
            bar.update(out.x_final.shape[0])
        bar.close()
    finally:
        if own:
            client.close()
    return merge(parts)


__all__ = ["BatchOutcome", "ChunkTask", "merge", "progress_bar", "run_batch", "run_chunk",
           "run_dask", "run_local", "run_runs", "run_runs_stepped", "split"]
