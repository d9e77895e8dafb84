"""`rta-attitude simulate`: a scenario in process (no DDS): summary, time series, figure, sky map, and the
verdict as the exit status (0 SAFE, 2 UNSAFE unless --allow-unsafe, 1 bad input: `cli.main`)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from rta_attitude.cli.main import add_verdict_arguments, verdict_status
from rta_attitude.cli.options import add_config_arguments
from rta_attitude.config.schema import BACKUP_LAWS, PRESETS, SIMULATORS, SOLVERS
from rta_attitude.errors import RtaError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude simulate`."""
    parser.add_argument("--scenario", default="paper-example", help="scenario in the config (default paper-example)")
    parser.add_argument("--no-rta", action="store_true", help="pass u_des straight to the plant (no filter)")
    parser.add_argument("--preset", choices=PRESETS, default=None, help="filter preset (default: the config's)")
    parser.add_argument("--duration", type=float, default=None, help="override the scenario duration, s")
    parser.add_argument("--solver", choices=SOLVERS, default=None,
                        help="QP solver (default: the config's; active_set = the Monte Carlo's)")
    parser.add_argument("--simulator", choices=SIMULATORS, default=None,
                        help="what integrates the spacecraft (default: the config's plant.simulator); basilisk "
                             "needs pip install rta_attitude[basilisk]")
    parser.add_argument("--noise", action="store_true",
                        help="sensor and actuator errors on (the config's sensors: section; docs/noise.md)")
    parser.add_argument("--backup-law", choices=BACKUP_LAWS, default=None,
                        help="the gatekeeper's backup law (default: the scenario's, else the config's "
                             "filter.backup_law; docs/backup.md)")
    parser.add_argument("--out", type=Path, default=Path("out/simulate"), help="output directory")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG figures (figure.png, skymap.png)")
    add_config_arguments(parser)
    add_verdict_arguments(parser, safe="no non-slacked constraint violated at a sample or an RK4 substep",
                          unsafe="a non-slacked constraint violated, also with --no-rta")


def write_trajectory(traj: Any, out: Path) -> Path:
    """Save a Trajectory's time series as a compressed NPZ with named columns. Returns the path."""
    import numpy as np

    from rta_attitude.dynamics.state import STATE_NAMES
    from rta_attitude.files import atomic

    path = out / "timeseries.npz"
    with atomic(path) as tmp:
        np.savez_compressed(
            tmp, t_s=traj.t_s, x=traj.x, state_names=np.array(STATE_NAMES), q_c=traj.q_c, u_des=traj.u_des,
            u=traj.u, omega_dot=traj.omega_dot, constraint_names=np.array(traj.names), h=traj.h,
            h_substep_min=traj.h_substep_min, bc=traj.bc, slack=traj.slack, intervening=traj.intervening,
            box_active=traj.box_active, status=traj.status, fallback=traj.fallback, solve_time_s=traj.solve_time_s,
        )  # fmt: skip
    return path


def run(args: argparse.Namespace) -> int:
    """`rta-attitude simulate`."""
    from rta_attitude.cli.options import load
    from rta_attitude.files import output_folder, write_text
    from rta_attitude.simulation.closed_loop import closed_loop
    from rta_attitude.simulation.metrics import format_summary, summarize_trajectory

    cfg = load(args, preset=args.preset)
    if args.solver is not None:
        cfg = cfg.with_solver(args.solver)
    if args.simulator is not None:
        cfg = cfg.with_simulator(args.simulator)
    if args.noise:
        cfg = cfg.with_noise()
    from dataclasses import replace

    scenario = cfg.scenario(args.scenario)
    if args.backup_law is not None:  # the command line over the scenario's
        scenario = replace(scenario, backup_law=args.backup_law)
    if args.duration is not None:
        if not args.duration > 0:
            raise RtaError(f"--duration must be > 0 s, got {args.duration}")
        scenario = replace(scenario, duration_s=float(args.duration))
    with output_folder(args.out) as out:  # a failed run leaves no empty folder
        loop = closed_loop(cfg, scenario, rta=not args.no_rta)
        t0 = time.perf_counter()
        traj = loop.run()
        wall = time.perf_counter() - t0
        summary = summarize_trajectory(traj, loop.cfg)
        summary["wall_time_s"] = wall
        summary["simulator"] = loop.cfg.plant.simulator
        summary["filter_model"] = loop.cfg.filter.model  # the scenario's (the paper's scenarios run the paper's model)
        write_trajectory(traj, out)
        write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
        print(format_summary(summary))
        if not args.no_plot:
            from rta_attitude.recording.plots import plot_runs
            from rta_attitude.recording.skymap import plot_skymap

            rta = f"RTA on ({cfg.filter.preset})" if not args.no_rta else "RTA off"
            png = plot_runs([(rta, traj)], loop.cfg, out / "figure.png", f"{scenario.name}: {rta}")
            sky = plot_skymap([(rta, traj)], loop.cfg, out / "skymap.png", f"{scenario.name}: {rta}")
            print(f"figure: {png}\nsky map: {sky}")
    print(f"wrote {out / 'summary.json'}, {out / 'timeseries.npz'} ({traj.steps} steps in {wall:.2f} s)")
    return verdict_status(summary["safe"], args.allow_unsafe,
                          f"scenario {scenario.name} violated {', '.join(summary['violated'])}")


__all__ = ["add_arguments", "run", "write_trajectory"]
