"""`rta-attitude`: the command line. Every subcommand checks its inputs first, prints one
`ERROR: ...` line and returns 1 on bad input (no traceback).

    rta-attitude simulate --scenario paper-example [--no-rta] [--preset robust|paper] --out DIR
    rta-attitude check-config [--config FILE]
    rta-attitude launch ...        (ROS 2 nodes over DDS, see rta_attitude.launcher)
    rta-attitude montecarlo ...    (batched Monte Carlo, see rta_attitude.montecarlo)
    rta-attitude analyze BAG ...   (bag replay analysis, see rta_attitude.analysis)
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from . import config as config_module
from .errors import RtaError
from .files import atomic, output_dir, write_text
from .params import PRESETS, SOLVERS, Config
from .state import STATE_NAMES

log = logging.getLogger("rta_attitude")

EXTERNAL_COMMANDS: dict[str, tuple[str, str]] = {
    "launch": ("rta_attitude.launcher", "run the closed loop as ROS 2 nodes over DDS, record an MCAP bag"),
    "montecarlo": ("rta_attitude.montecarlo", "batched Monte Carlo of the filter from Latin-hypercube states"),
    "analyze": ("rta_attitude.analysis", "summary and figure of a recorded MCAP bag"),
    "replay": ("rta_attitude.replay", "republish a bag's messages over DDS with /clock"),
    "topics": ("rta_attitude.topic_tools", "list live ROS topics with types, publishers and rates"),
    "echo": ("rta_attitude.topic_tools", "print the messages of one live topic as YAML"),
}
"""Subcommands that live in their own modules: module, help. Each module has add_arguments(parser,
command) and run(args) -> int; a missing module simply leaves its subcommand out."""


def _add_config(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=None,
                   help="parameter YAML (default: $RTA_ATTITUDE_CONFIG or the package's config/rta_attitude.yaml)")


def write_trajectory(traj: Any, cfg: Config, out: Path) -> Path:
    """Save a Trajectory's time series as a compressed NPZ with named columns. Returns the path."""
    path = out / "timeseries.npz"
    with atomic(path) as tmp:
        np.savez_compressed(
            tmp, t_s=traj.t_s, x=traj.x, state_names=np.array(STATE_NAMES), q_c=traj.q_c, u_des=traj.u_des,
            u=traj.u, omega_dot=traj.omega_dot, constraint_names=np.array(traj.names), h=traj.h,
            h_substep_min=traj.h_substep_min, bc=traj.bc, slack=traj.slack, intervening=traj.intervening,
            box_active=traj.box_active, status=traj.status, fallback=traj.fallback, solve_time_s=traj.solve_time_s,
        )  # fmt: skip
    return path


def slacked_names(cfg: Config) -> tuple[str, ...]:
    """Constraints that carry a slack in this configuration (Config.slacked_constraints)."""
    return cfg.slacked_constraints


def cmd_simulate(args: argparse.Namespace) -> int:
    from .metrics import format_summary, summarize_trajectory
    from .simulation import ClosedLoop

    cfg = config_module.load(args.config, preset=args.preset)
    if args.solver is not None:
        cfg = cfg.with_solver(args.solver)
    scenario = cfg.scenario(args.scenario)
    if args.duration is not None:
        if not args.duration > 0:
            raise RtaError(f"--duration must be > 0 s, got {args.duration}")
        from dataclasses import replace

        scenario = replace(scenario, duration_s=float(args.duration))
    out = output_dir(args.out)
    loop = ClosedLoop(cfg, scenario, rta=not args.no_rta)
    t0 = time.perf_counter()
    traj = loop.run(progress=sys.stderr.isatty())
    wall = time.perf_counter() - t0
    summary = summarize_trajectory(traj, cfg.limits.omega_dot_max_rad_s2, slacked_names(loop.cfg))
    summary["wall_time_s"] = wall
    write_trajectory(traj, loop.cfg, out)
    write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(format_summary(summary))
    if not args.no_plot:
        from .plots import plot_runs

        rta = f"RTA on ({cfg.filter.preset})" if not args.no_rta else "RTA off"
        png = plot_runs([(rta, traj)], loop.cfg, out / "figure.png", f"{scenario.name}: {rta}")
        print(f"figure: {png}")
    print(f"wrote {out / 'summary.json'}, {out / 'timeseries.npz'} ({traj.steps} steps in {wall:.1f} s)")
    return 0


def cmd_check_config(args: argparse.Namespace) -> int:
    cfg = config_module.load(args.config)
    print(f"{cfg.source}: ok")
    print(f"  preset {cfg.filter.preset}, fallback {cfg.filter.fallback}, dt {cfg.filter.sample_time_s} s, "
          f"{cfg.substeps} RK4 substeps")
    print(f"  admissible |u| <= {np.array2string(cfg.u_max_rad_s2, precision=2)} rad/s^2 (x, y, z)")
    print(f"  slacked: {', '.join(slacked_names(cfg)) or 'none'}")
    print(f"  scenarios: {', '.join(s.replace('_', '-') for s in cfg.scenarios)}")
    return 0


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, Any]]:
    """The argument parser and the handler of each subcommand."""
    parser = argparse.ArgumentParser(prog="rta-attitude", description=__doc__.split("\n")[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    handlers: dict[str, Any] = {"simulate": cmd_simulate, "check-config": cmd_check_config}

    p = sub.add_parser("simulate", help="run a scenario in process (no DDS); summary, time series, figure")
    p.add_argument("--scenario", default="paper-example", help="scenario name in the config (default paper-example)")
    p.add_argument("--no-rta", action="store_true", help="pass u_des straight to the plant (no filter)")
    p.add_argument("--preset", choices=PRESETS, default=None, help="filter preset (default: the config's)")
    p.add_argument("--duration", type=float, default=None, help="override the scenario duration, s")
    p.add_argument("--solver", choices=SOLVERS, default=None,
                   help="QP solver (default: the config's; active_set = the Monte Carlo's)")
    p.add_argument("--out", type=Path, default=Path("out/simulate"), help="output directory")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG figure")
    _add_config(p)

    p = sub.add_parser("check-config", help="validate a parameter file and print what it sets")
    _add_config(p)

    for name, (module_name, help_text) in EXTERNAL_COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue
            raise
        p = sub.add_parser(name, help=help_text)
        module.add_arguments(p, name)
        handlers[name] = module.run
    return parser, handlers


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status."""
    parser, handlers = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(handlers[args.command](args) or 0)
    except RtaError as exc:
        print(f"ERROR: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a file error no command anticipated: still one line, not a traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"ERROR: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("ERROR: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
