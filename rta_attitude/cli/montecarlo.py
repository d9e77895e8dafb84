"""`rta-attitude montecarlo`: the paper's Monte Carlo (`rta_attitude.montecarlo`), locally or on Dask."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from rta_attitude.config.schema import PLANT_MODELS, PRESETS, SIMULATORS, SOLVERS
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
    parser.add_argument("--out", type=Path, default=Path("out/montecarlo"), help="output directory")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG figure")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--config", type=Path, default=None, help="parameter YAML (default: the package's)")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude montecarlo`: returns the exit status (errors raise RtaError for the CLI to print)."""
    if args.runs < 1:
        raise ConfigError(f"--runs must be >= 1, got {args.runs}")
    if args.chunk_runs is not None and args.chunk_runs < 1:
        raise ConfigError(f"--chunk-runs must be >= 1, got {args.chunk_runs}")
    if args.max_runs is not None and args.max_runs < 1:
        raise ConfigError(f"--max-runs must be >= 1, got {args.max_runs}")
    from rta_attitude import config as config_module
    from rta_attitude.files import output_dir
    from rta_attitude.montecarlo.campaign import format_table, montecarlo, summary, write_outputs

    cfg = config_module.load(args.config, preset=args.preset)
    if args.solver is not None:
        cfg = cfg.with_solver(args.solver)
    if args.simulator is not None:
        cfg = cfg.with_simulator(args.simulator)
    cfg = cfg.with_models(args.plant_model, args.filter_model)
    output_dir(args.out)  # before hours of work, not after
    result = montecarlo(cfg, args.runs, args.duration, args.seed, args.workers, args.backend, args.scheduler,
                        args.chunk_runs, progress=not args.no_progress and sys.stderr.isatty(),
                        max_runs=args.max_runs)
    paths = write_outputs(result, args.out, plot=not args.no_plot)
    print(format_table(summary(result)))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


__all__ = ["add_arguments", "run"]
