"""The Monte Carlo campaign: sample, run, classify (the library entry point of `rta-attitude montecarlo`)."""

from __future__ import annotations

import math
import time
from typing import Any

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.errors import ConfigError
from rta_attitude.montecarlo import BACKENDS, DEFAULT_CHUNK_RUNS
from rta_attitude.montecarlo.classify import classify
from rta_attitude.montecarlo.controllers import RunController
from rta_attitude.montecarlo.report import PAPER_RESULTS, MonteCarloResult, format_table, summary, write_outputs
from rta_attitude.montecarlo.runner import BatchOutcome, run_dask, run_local, run_runs
from rta_attitude.montecarlo.sampling import rejected, sample_initial_states


def _cpu_s() -> float:
    """User + system CPU seconds of this process and its reaped children."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def montecarlo(cfg: Config, runs: int, duration_s: float, seed: int, workers: int = 1, backend: str = "local",
               scheduler: str | Any | None = None, chunk_runs: int | None = None,
               progress: bool = False, max_runs: int | None = None, controller: str = "none",
               retarget_s: float | None = None) -> MonteCarloResult:
    """Sample, run and classify (the library entry point of the CLI).

    max_runs: run only the first max_runs of the `runs` sampled states (the same states, in the same
    order, as the whole campaign of that seed): a subset for a slower simulator (`plant.simulator`).
    controller: the runs' primary controller, 'none' (u_des = 0, the paper's protocol), 'pd' or a user's
    'module:function'; retarget_s: a new random target every retarget_s seconds (default one per run);
    `montecarlo.controllers`. The initial states do not depend on the controller.

    Raises:
        ConfigError: bad arguments.
    """
    if backend not in BACKENDS:
        raise ConfigError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise ConfigError(f"duration must be > 0 s, got {duration_s!r}")
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if backend == "dask" and not scheduler:
        raise ConfigError("the dask backend needs --scheduler ADDRESS (e.g. tcp://127.0.0.1:8786)")
    if max_runs is not None and max_runs < 1:
        raise ConfigError(f"max_runs must be >= 1, got {max_runs}")
    ctrl = RunController(controller, seed, retarget_s)
    if ctrl.kind == "python":
        ctrl.function()  # a missing module or function fails here, before any run
    x0, redraws = sample_initial_states(runs, seed, cfg)
    if max_runs is not None:
        x0, redraws = x0[:max_runs], redraws[:max_runs]
    t0 = time.perf_counter()
    cpu0 = _cpu_s()
    if backend == "local":
        outcome = run_local(cfg, x0, duration_s, workers, chunk_runs, progress, controller=ctrl)
    else:
        outcome = run_dask(cfg, x0, duration_s, scheduler, chunk_runs or DEFAULT_CHUNK_RUNS, progress, controller=ctrl)
    wall = time.perf_counter() - t0
    cpu = _cpu_s() - cpu0
    slacked = ConstraintSet(cfg).slacked
    result = MonteCarloResult(cfg, seed, duration_s, x0, redraws, outcome, slacked, wall, backend, workers,
                              cpu_s=cpu if backend == "local" else math.nan, controller=ctrl)
    result.unrecoverable, result.rules = classify(x0, outcome.violated_samples & result.counted, cfg, duration_s)
    return result



__all__ = ["PAPER_RESULTS", "BatchOutcome", "MonteCarloResult", "RunController", "classify", "format_table",
           "montecarlo", "rejected", "run_dask", "run_local", "run_runs", "sample_initial_states", "summary",
           "write_outputs"]
