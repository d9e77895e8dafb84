"""`rta-attitude launch`: a scenario as four ROS 2 nodes over DDS, recorded and summarized (`--controller none`:
three, and a controller node of yours); the process management lives in `cli.launcher`."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from rta_attitude import topics
from rta_attitude.cli.launcher import (
    CONTROLLER_PD,
    CONTROLLERS,
    DEFAULT_DOMAIN_ID,
    DISCOVERY_RANGES,
    Plan,
    controller_mode,
    launch,
    plan,
)
from rta_attitude.config.schema import PRESETS
from rta_attitude.errors import RtaError
from rta_attitude.files import output_dir, write_text


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude launch`."""
    parser.add_argument("--scenario", default="paper-example", help="scenario in the parameter file")
    parser.add_argument("--no-rta", action="store_true", help="filter node passes torque_des through (no RTA)")
    parser.add_argument("--controller", choices=CONTROLLERS, default=CONTROLLER_PD,
                        help="pd: the paper's PD controller node (default); none: no controller node, the run waits "
                             "for a node of yours that publishes torque_des on --namespace and reads the state "
                             "(examples/my_controller_node.py)")
    parser.add_argument("--scene", choices=(topics.SCENE_RECORDER, topics.SCENE_NODE), default=topics.SCENE_RECORDER,
                        help="the scene node (3D view topics scene/transform, scene/markers): hosted in the recorder's "
                             "process (default) or a process of its own")
    parser.add_argument("--no-scene", action="store_true", help="leave out the scene node")
    parser.add_argument("--preset", choices=PRESETS, default=None, help="filter preset (default: the config's)")
    parser.add_argument("--realtime", type=float, default=None, metavar="RTF",
                        help="real-time stepping at this real-time factor (default: lockstep)")
    parser.add_argument("--bag", type=Path, default=None,
                        help="MCAP file to record (default: a temporary file, removed after the summary)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --bag file")
    parser.add_argument("--out", type=Path, default=None, help="directory for summary.json and the node logs")
    parser.add_argument("--duration", type=float, default=None, help="override the scenario duration, s")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE",
                        help="override a parameter of the YAML or a node knob (YAML value), e.g. "
                             "filter.fallback=hold; repeatable")
    parser.add_argument("--config", type=Path, default=None, help="parameter YAML (default: the package's)")
    parser.add_argument("--namespace", default=topics.DEFAULT_NAMESPACE, help="namespace of the nodes' topics")
    parser.add_argument("--timeout", type=float, default=None,
                        help="give up after this many seconds (default: from the scenario length)")
    parser.add_argument("--domain-id", type=int, default=None,
                        help=f"ROS_DOMAIN_ID of the nodes (default: $ROS_DOMAIN_ID, else {DEFAULT_DOMAIN_ID})")
    parser.add_argument("--discovery", choices=tuple(DISCOVERY_RANGES), default="localhost",
                        help="ROS_AUTOMATIC_DISCOVERY_RANGE of the nodes (default localhost: nothing leaves the "
                             "machine)")
    parser.add_argument("--verbose", action="store_true", help="show the nodes' log output")



def run(args: argparse.Namespace) -> int:
    """`rta-attitude launch`: see the module docstring."""
    from rta_attitude.simulation.closed_loop import compile_kernels

    p = plan(args)
    out: Path | None = None
    log_dir = None
    ok = False
    try:
        out = output_dir(args.out) if args.out is not None else None
        if out is not None:
            log_dir = output_dir(out / "logs")
        elif not args.verbose:
            log_dir = Path(tempfile.mkdtemp(prefix="rta_launch_logs_"))
        mode = f"realtime x{args.realtime:g}" if args.realtime is not None else "lockstep"
        # the nodes compile (or load) numba's kernels at start-up; do it once here, so that a fresh
        # installation's compile happens before any node waits on another
        ready_s = compile_kernels(p.cfg)
        print(f"compiled kernels ready in {ready_s:.1f} s", flush=True)
        if controller_mode(args) != CONTROLLER_PD:
            print(f"controller: none; waiting for your node to publish {args.namespace.rstrip('/')}/"
                  f"{topics.TORQUE_DES} (e.g. python examples/my_controller_node.py --ros-args "
                  f"-r __ns:={args.namespace})", flush=True)
        print(f"launch {p.scenario_key}: {p.steps} steps, {mode}, rta={'off' if args.no_rta else 'on'}, "
              f"namespace {args.namespace}, domain {p.env['ROS_DOMAIN_ID']} "
              f"({p.env['ROS_AUTOMATIC_DISCOVERY_RANGE'].lower()}), bag {p.bag}", flush=True)
        problems, facts = launch(p, log_dir)
        code = _report(args, p, out, log_dir, mode, problems, facts)
        ok = code == 0
        return code
    finally:
        _clean_up(p, log_dir if out is None else None, ok)


def _clean_up(p: Plan, temporary_logs: Path | None, ok: bool) -> None:
    """Remove what the launcher made for itself: the temporary bag and its directory (kept, and named,
    after a failed run), and the temporary log directory (kept after a failed run: its path was printed)."""
    if p.temporary_bag:
        if ok or not p.bag.exists():
            p.bag.unlink(missing_ok=True)
            shutil.rmtree(p.bag.parent, ignore_errors=True)
        else:
            print(f"bag kept: {p.bag}", flush=True)
    if temporary_logs is not None and ok:
        shutil.rmtree(temporary_logs, ignore_errors=True)


def _report(args: argparse.Namespace, p: Plan, out: Path | None, log_dir: Path | None, mode: str,
            problems: list[str], facts: dict[str, Any]) -> int:
    """Print the run's summary from its bag (and write summary.json); the exit code."""
    from rta_attitude.recording.analysis import load_run
    from rta_attitude.recording.bag import read_bag
    from rta_attitude.recording.summary import summarize_run
    from rta_attitude.ros.convert import run_status_from_msg
    from rta_attitude.simulation.metrics import format_summary

    if problems:  # one ERROR line (the first problem); the rest, and where the logs are, on stdout
        print(f"ERROR: {problems[0]}", file=sys.stderr)
        for line in problems[1:]:
            print(f"also: {line}", flush=True)
    node_failed = any(facts["exit_codes"].get(topics.EXECUTABLES[r]) != 0 for r in (topics.PLANT, topics.RECORDER))
    if problems and (not p.bag.exists() or node_failed):
        if log_dir is not None:
            print(f"node logs: {log_dir}", flush=True)
        return 1
    status = read_bag(p.bag, topics=[f"{args.namespace.rstrip('/')}/{topics.RUN_STATUS}"])
    run_values: dict[str, Any] = {}
    if status.messages:
        state, run_values = run_status_from_msg(status.messages[-1].message)
        run_values = {"run_state": state, **{k: v for k, v in run_values.items()
                                             if not k.startswith(topics.EXPECTED_PREFIX)}}
    bag_run = load_run(p.bag, p.cfg, args.namespace, p.scenario_key)
    summary = summarize_run(bag_run, p.cfg)
    summary["launch"] = {**facts, "mode": mode, "bag": str(p.bag), "problems": problems, **run_values}
    print(format_summary(summary))
    lat = run_values.get("latency_median_s")
    extra = f", state -> torque_cmd median {lat * 1e3:.2f} ms, p99 {run_values['latency_p99_s'] * 1e3:.2f} ms" \
        if isinstance(lat, float) else ""
    loop = run_values.get("wall_time_s")
    loop_text = f"loop {loop:.1f} s" if isinstance(loop, float) else "loop ?"
    print(f"DDS run, {len(p.commands)} processes: {loop_text} for {p.steps} steps ({facts['run_s']:.1f} s with "
          "start-up and "
          f"shutdown){extra}; deadline misses {run_values.get('deadline_misses', 0)}; re-integration residual "
          f"{bag_run.reintegration_residual:.2g}")
    counters = {k: run_values[k] for k in topics.PLANT_COUNTERS if k != "commands" and run_values.get(k)}
    if counters:
        print("plant counters: " + ", ".join(f"{k} {v}" for k, v in counters.items()))
    if out is not None:
        write_text(out / "summary.json", json.dumps(summary, indent=2, default=str) + "\n")
        print(f"wrote {out / 'summary.json'}, bag {p.bag}, logs {log_dir}")
    elif problems and log_dir is not None:
        print(f"node logs: {log_dir}", flush=True)
    return 1 if problems else 0


def main(argv: list[str] | None = None) -> int:
    """`python -m rta_attitude.cli.launch ...` (the same as `rta-attitude launch ...`)."""
    parser = argparse.ArgumentParser(prog="rta-attitude launch", description=__doc__.split("\n")[0])
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except RtaError as exc:
        print(f"ERROR: {exc}", file=sys.stderr)
        return 1


__all__ = ["add_arguments", "main", "run"]

if __name__ == "__main__":
    sys.exit(main())
