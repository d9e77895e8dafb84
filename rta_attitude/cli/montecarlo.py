"""`rta-attitude montecarlo`: the paper's Monte Carlo (`rta_attitude.montecarlo`), locally or on Dask, with no
primary controller (the paper's protocol), the package's PD law or a user's Python controller
(`montecarlo.controllers`). The exit status is the campaign's verdict (0 SAFE, 2 UNSAFE unless
--allow-unsafe, 1 bad input: `cli.main`): UNSAFE when fewer than --min-safe-rate of the runs keep every
counted constraint at every sample and substep (default 1: any failed run)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from rta_attitude.cli.main import add_verdict_arguments, verdict_status
from rta_attitude.cli.options import add_config_arguments
from rta_attitude.config.schema import BACKUP_LAWS, FALLBACKS, PLANT_MODELS, PRESETS, SIMULATORS, SOLVERS
from rta_attitude.errors import ConfigError
from rta_attitude.montecarlo import BACKENDS, DEFAULT_CHUNK_RUNS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rta-attitude montecarlo`."""
    parser.add_argument("--runs", type=int, default=5000, help="number of runs (default 5000)")
    parser.add_argument("--duration", type=float, default=2000.0, help="run length, s (default 2000)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the initial states (default 1)")
    parser.add_argument("--preset", choices=PRESETS, default=None, help="filter preset (default: the config's)")
    parser.add_argument("--plant-model", choices=PLANT_MODELS, default=None,
                        help="model of the simulated plant (default: the config's spacecraft.model)")
    parser.add_argument("--filter-model", choices=PLANT_MODELS, default=None,
                        help="the filter's model of the plant (default: the config's filter.model)")
    parser.add_argument("--backup-law", choices=BACKUP_LAWS, default=None,
                        help="the gatekeeper's backup law (default: the config's filter.backup_law; docs/backup.md)")
    parser.add_argument("--fallback", choices=FALLBACKS, default=None,
                        help="what answers an infeasible QP (default: the config's filter.fallback)")
    parser.add_argument("--backup-horizon", type=float, default=None,
                        help="the gatekeeper's horizon, s (default: the config's filter.backup_horizon_s)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="local worker processes (default: the machine's cores)")
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="local processes or a Dask cluster")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address for --backend dask")
    parser.add_argument("--chunk-runs", type=int, default=None,
                        help=f"runs per chunk (default: one chunk per local worker; {DEFAULT_CHUNK_RUNS} on dask)")
    parser.add_argument("--solver", choices=SOLVERS, default=None,
                        help="QP solver (default: the config's): the exact active-set method or proxsuite (several "
                             "times slower); a run equals `simulate` with the same solver bit for bit")
    parser.add_argument("--simulator", choices=SIMULATORS, default=None,
                        help="what integrates the spacecraft (default: the config's plant.simulator); basilisk runs "
                             "a Python loop per run (about 1-3 ms a step): use --max-runs")
    parser.add_argument("--max-runs", type=int, default=None,
                        help="run only the first N of the --runs sampled states (the same states as the whole "
                             "campaign of that seed)")
    parser.add_argument("--noise", action="store_true",
                        help="sensor and actuator errors on (the config's sensors: section; docs/noise.md)")
    parser.add_argument("--controller", default="none", metavar="none|pd|MODULE:FUNCTION",
                        help="the runs' primary controller: none (u_des = 0, the paper's protocol; default), pd (the "
                             "package's PD law with the config's gains, compiled) or a Python function "
                             "u_des = FUNCTION(y, q_c, t_s) returning the desired wheel accelerations (3,) in "
                             "rad/s^2 from the measured state y (19,), the commanded attitude q_c (4, scalar last) "
                             "and the time, s (imported from MODULE, the working directory first; if it has a "
                             "reset() it is called before each run; a Python-stepped loop: ~0.2 s more CPU per "
                             "2,000 s run, 1.2-1.4x the compiled run of the default configuration). "
                             "Each run is commanded to random target attitudes drawn from --seed and the run's "
                             "index (docs/montecarlo.md, \"Your controller\")")
    parser.add_argument("--retarget", type=float, default=None, metavar="SECONDS",
                        help="with a controller: a new random target every SECONDS (default: one target per run)")
    parser.add_argument("--min-safe-rate", type=float, default=1.0, metavar="RATE",
                        help="the campaign is UNSAFE (exit 2) when the share of runs that keep every counted "
                             "constraint at every sample and substep is below RATE, a fraction (default 1: any "
                             "failed run; e.g. 0.995)")
    parser.add_argument("--out", type=Path, default=Path("out/montecarlo"), help="output directory")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG figure")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_config_arguments(parser)
    parser.add_argument("--viability", action="store_true",
                        help="then run the viability oracle on every failed run over the run length (slow: up to "
                             "--viability-time-limit per run); writes viability.json/.csv and reports the failures "
                             "with and without a witness")
    parser.add_argument("--viability-time-limit", type=float, default=900.0,
                        help="the oracle's wall-clock budget per failed run, s (default 900)")
    parser.add_argument("--viability-no-compile", action="store_true",
                        help="the oracle in casadi's virtual machine (no C compiler; ~10x slower)")
    add_verdict_arguments(parser, safe="at least --min-safe-rate of the runs (default all) keep every counted "
                                       "constraint at every sample and substep",
                          unsafe="fewer runs than --min-safe-rate kept every counted constraint; summary.json's "
                                 "verdict says how many")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude montecarlo`: returns the exit status (errors raise RtaError for the CLI to print)."""
    if args.runs < 1:
        raise ConfigError(f"--runs must be >= 1, got {args.runs}")
    if args.chunk_runs is not None and args.chunk_runs < 1:
        raise ConfigError(f"--chunk-runs must be >= 1, got {args.chunk_runs}")
    if args.max_runs is not None and args.max_runs < 1:
        raise ConfigError(f"--max-runs must be >= 1, got {args.max_runs}")
    if not args.viability_time_limit > 0:
        raise ConfigError(f"--viability-time-limit must be > 0 s, got {args.viability_time_limit}")
    if not 0.0 <= args.min_safe_rate <= 1.0:
        raise ConfigError(f"--min-safe-rate must be a fraction in [0, 1] (0.995 for 99.5 %), got {args.min_safe_rate}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    from rta_attitude.cli.options import load
    from rta_attitude.files import output_folder
    from rta_attitude.montecarlo.campaign import format_table, montecarlo, summary, write_outputs
    from rta_attitude.montecarlo.controllers import RunController

    controller = RunController(args.controller, args.seed, args.retarget)  # checks the names and --retarget
    if controller.kind == "python":
        controller.function()  # import it now: a missing module fails before any work

    cfg = load(args, preset=args.preset)
    if args.solver is not None:
        cfg = cfg.with_solver(args.solver)
    if args.simulator is not None:
        cfg = cfg.with_simulator(args.simulator)
    cfg = cfg.with_models(args.plant_model, args.filter_model)
    if args.noise:
        cfg = cfg.with_noise()
    cfg = cfg.with_backup(args.backup_law, args.backup_horizon)
    if args.fallback is not None:
        cfg = cfg.with_fallback(args.fallback)
    with output_folder(args.out) as out:  # checked before hours of work; a failed campaign leaves no empty folder
        result = montecarlo(cfg, args.runs, args.duration, args.seed, args.workers, args.backend, args.scheduler,
                            args.chunk_runs, progress=not args.no_progress and sys.stderr.isatty(),
                            max_runs=args.max_runs, controller=args.controller, retarget_s=args.retarget)
        paths = write_outputs(result, out, plot=not args.no_plot, min_safe_rate=args.min_safe_rate)
    s = summary(result, args.min_safe_rate)
    print(format_table(s))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    if args.viability:
        check_failures(result, args.out, args.viability_time_limit,
                       progress=not args.no_progress and sys.stderr.isatty(), compile=not args.viability_no_compile)
    v = s["verdict"]
    return verdict_status(v["safe"], args.allow_unsafe,
                          f"{v['runs'] - v['safe_runs']} of {v['runs']} runs failed, safe rate {v['safe_rate']:.2%} < "
                          f"--min-safe-rate {v['min_safe_rate']:.2%}")


def check_failures(result: Any, out: Path, time_limit_s: float, progress: bool, compile: bool = True) -> dict[str, Any]:
    """The viability oracle on every failed run (at samples) of a MonteCarloResult, over the run length;
    writes viability.json / viability.csv to out, prints the table and the counts. Returns the counts."""
    import numpy as np

    from rta_attitude.viability.batch import check_states, counts, write_report
    from rta_attitude.viability.params import default_enforce
    from rta_attitude.viability.result import format_table

    cfg = result.cfg
    items = [(f"run {k}", result.x0[k]) for k in np.flatnonzero(result.failed())]
    found = check_states(items, result.duration_s, cfg, progress=progress, time_limit_s=time_limit_s,
                         compile=compile)
    setup = {"config": cfg.source, "model": cfg.spacecraft.model, "horizon_s": result.duration_s,
             "enforce": list(default_enforce(cfg)), "time_limit_s": time_limit_s, "compiled": compile,
             "source": f"montecarlo seed {result.seed}, {len(result.x0)} runs, preset {cfg.filter.preset}",
             "select": "failed"}
    paths = write_report(out, found, setup)
    c = counts(found)
    if found:
        print(format_table(found))
    print(f"viability of the {c['states']} failed runs over {result.duration_s:.0f} s: {c['recoverable']} with a "
          f"witness (a filter shortfall), {c['no witness found']} without (no witness found), "
          f"{c['unrecoverable']} proven unrecoverable")
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return c


__all__ = ["add_arguments", "check_failures", "run"]
