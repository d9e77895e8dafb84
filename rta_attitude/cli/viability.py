"""`rta-attitude viability`: the viability oracle (rta_attitude.viability) on given states or on the
failed runs of a Monte Carlo.

    rta-attitude viability --state q1,q2,q3,q4,wx,wy,wz,psix,psiy,psiz,T,E,theta_S [--state ...] [--start-time S]
    rta-attitude viability --runs out/montecarlo/runs.csv [--select failed|failed_incl_substeps|all]
                           [--limit N] [--horizon S] [--time-limit S] [--enforce G,...] [--no-compile] --out DIR

States are in model units (rad/s, K, J, rad), as runs.csv writes them (a run's initial state, at t = 0);
--start-time is the time of the --state states (pointing constraints with time windows apply by it). The
constraint groups are the configuration's (`Config.groups`). Prints the verdict table and writes
viability.json (every result with its witness) and viability.csv to --out.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from rta_attitude.errors import ConfigError

DEFAULT_HORIZON_S = 2000.0
"""Horizon when neither --horizon nor a summary.json beside --runs gives one (the paper's run length)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rta-attitude viability`."""
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--state", action="append", default=None, metavar="Q1,...,THETA_S",
                     help="an initial state: 13 (or 19) comma-separated numbers, model units; repeatable")
    src.add_argument("--runs", type=Path, default=None, help="a Monte Carlo's runs.csv: check its failed runs")
    parser.add_argument("--select", choices=("failed", "failed_incl_substeps", "all"), default="failed",
                        help="which runs of --runs (default: failed at the samples)")
    parser.add_argument("--limit", type=int, default=None, help="check only the first N selected runs or states")
    parser.add_argument("--horizon", type=float, default=None,
                        help=f"horizon, s (default: the Monte Carlo's run length, else {DEFAULT_HORIZON_S:.0f})")
    parser.add_argument("--time-limit", type=float, default=900.0, help="wall-clock budget per state, s (default 900)")
    parser.add_argument("--enforce", default=None,
                        help="comma-separated constraint groups a witness must keep: pointing constraints by name, "
                             "temperature, battery, omega, psi (default: enabled, not slacked)")
    parser.add_argument("--start-time", dest="start_time_s", type=float, default=0.0, metavar="S",
                        help="time of the --state states, s from the run's start (default 0; --runs: 0, the runs' "
                             "initial states)")
    parser.add_argument("--no-compile", action="store_true",
                        help="casadi's virtual machine instead of compiled C blocks (no compiler needed, ~10x slower)")
    parser.add_argument("--no-trajectory", action="store_true", help="leave the witnesses out of viability.json")
    parser.add_argument("--out", type=Path, default=Path("out/viability"), help="output directory")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--config", type=Path, default=None, help="parameter YAML (default: the package's)")


def parse_state(text: str) -> list[float]:
    """The numbers of one --state; ConfigError unless 13 or 19 finite numbers."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(f"--state must be comma-separated numbers, got {text!r}") from None
    if len(values) not in (13, 19) or not all(math.isfinite(v) for v in values):
        raise ConfigError(f"--state must be 13 (q1..q4, omega, psi, T, E, theta_S) or 19 finite numbers, "
                          f"got {len(values)} in {text!r}")
    if not any(values[:4]):
        raise ConfigError(f"--state has a zero quaternion: {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    """`rta-attitude viability`: returns the exit status (errors raise RtaError for the CLI to print)."""
    import numpy as np

    from rta_attitude import config as config_module
    from rta_attitude.files import output_dir

    if args.horizon is not None and not (math.isfinite(args.horizon) and args.horizon >= 1.0):
        raise ConfigError(f"--horizon must be >= 1 s, got {args.horizon}")
    if args.limit is not None and args.limit < 1:
        raise ConfigError(f"--limit must be >= 1, got {args.limit}")
    if not args.time_limit > 0:
        raise ConfigError(f"--time-limit must be > 0 s, got {args.time_limit}")
    if not math.isfinite(args.start_time_s):
        raise ConfigError(f"--start-time must be a finite time in s, got {args.start_time_s}")
    if args.runs is not None and args.start_time_s != 0.0:
        raise ConfigError(f"--start-time applies to --state only (a runs.csv holds states at t = 0), got "
                          f"{args.start_time_s}")
    states = [parse_state(s) for s in args.state] if args.state else None
    if args.runs is not None and not args.runs.is_file():
        raise ConfigError(f"--runs {args.runs}: no such file")
    cfg = config_module.load(args.config)
    from rta_attitude.viability.batch import check_states, counts, horizon_of_runs, read_runs, write_report
    from rta_attitude.viability.params import check_enforce, default_enforce
    from rta_attitude.viability.result import format_table

    enforce = check_enforce([g.strip() for g in args.enforce.split(",")], cfg) if args.enforce else default_enforce(cfg)
    if states is not None:
        items = [(f"state {k}", np.array(s)) for k, s in enumerate(states)]
        horizon = args.horizon or DEFAULT_HORIZON_S
    else:
        items = read_runs(args.runs, args.select)
        horizon = args.horizon or horizon_of_runs(args.runs) or DEFAULT_HORIZON_S
    items = items[:args.limit] if args.limit else items
    output_dir(args.out)
    results = check_states(items, horizon, cfg, progress=not args.no_progress and sys.stderr.isatty(),
                           enforce=enforce, time_limit_s=args.time_limit, compile=not args.no_compile,
                           start_s=args.start_time_s)
    setup = {"config": cfg.source, "model": cfg.spacecraft.model, "horizon_s": horizon, "enforce": list(enforce),
             "start_s": args.start_time_s,
             "time_limit_s": args.time_limit, "compiled": not args.no_compile,
             "source": str(args.runs) if args.runs else "--state", "select": args.select if args.runs else None,
             "limit": args.limit}
    paths = write_report(args.out, results, setup, with_trajectory=not args.no_trajectory)
    c = counts(results)
    print(format_table(results))
    print(f"{c['states']} states over {horizon:.0f} s ({cfg.spacecraft.model} model): {c['recoverable']} recoverable "
          f"(witness), {c['no witness found']} no witness found, {c['unrecoverable']} unrecoverable"
          + (f" ({', '.join(f'{k} {v}' for k, v in c['by_rule'].items())})" if c["by_rule"] else ""))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


__all__ = ["DEFAULT_HORIZON_S", "add_arguments", "parse_state", "run"]
