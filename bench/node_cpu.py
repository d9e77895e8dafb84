"""Benchmark: CPU per step of each node of the lockstep DDS loop, against the forward-only chains.

    python bench/node_cpu.py [--repeat 2] [--short 200] [--long 2000]

Runs the paper example's four node processes (plant, controller, filter, recorder; no scene) as the
launcher starts them, and the two floors of bench_dds.py (bench/forward_chain.py: rclpy message objects,
and `--raw`: bytes), each at two lengths. Every process is reaped with os.wait4, whose rusage gives its
CPU (user + system, all threads: Fast DDS's included); the difference between the long and the short run,
divided by the difference in steps, is the CPU a step with start-up and shutdown cancelled. Reports each
role's median over `--repeat` alternated passes, and the totals. Appends to bench/results/node_cpu.json
with the machine's load. Not collected by pytest; runs on its own ROS_DOMAIN_ID, localhost only.

Where the DDS loop's time goes: on 2 cores shared by four processes and DDS's threads the loop is CPU-bound,
so a node's CPU a step is its share of the loop.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import machine  # noqa: E402

machine.isolate_ros()
import forward_chain  # noqa: E402

from rta_attitude import topics  # noqa: E402
from rta_attitude.cli import launch as launch_cli  # noqa: E402
from rta_attitude.cli import launcher  # noqa: E402

ROLES = (topics.PLANT, topics.CONTROLLER, topics.FILTER, topics.RECORDER)
TIMEOUT_S = 300.0


def _reap(procs: dict[str, subprocess.Popen[bytes]], stop_after: tuple[str, ...]) -> dict[str, float]:
    """Wait for the processes (SIGINT to the others once every role in `stop_after` has exited); each one's
    CPU [s] from os.wait4. Raises SystemExit if one fails or the run outlasts TIMEOUT_S."""
    cpu: dict[str, float] = {}
    deadline = time.monotonic() + TIMEOUT_S
    stopped = False
    while len(cpu) < len(procs):
        for role, p in procs.items():
            if role in cpu:
                continue
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid == 0:
                continue
            p.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
            if p.returncode != 0:
                for q in procs.values():
                    if q.returncode is None:
                        q.kill()
                raise SystemExit(f"node_cpu: {role} exited with code {p.returncode}")
            cpu[role] = usage.ru_utime + usage.ru_stime
        if not stopped and all(r in cpu for r in stop_after):
            for role, p in procs.items():
                if role not in cpu:
                    p.send_signal(signal.SIGINT)
            stopped = True
        if time.monotonic() > deadline:
            for p in procs.values():
                if p.returncode is None:
                    p.kill()
            raise SystemExit("node_cpu: a run outlasted its timeout")
        time.sleep(0.02)
    return cpu


def real_cpu(steps: int, work: Path) -> dict[str, float]:
    """The launcher's four node processes for `steps` steps (no scene): each one's CPU [s]."""
    parser = argparse.ArgumentParser()
    launch_cli.add_arguments(parser)
    bag = work / f"node_cpu_{time.monotonic_ns()}.mcap"
    args = parser.parse_args(["--bag", str(bag), "--duration", str(float(steps)), "--no-scene"])
    plan = launcher.plan(args)
    env = {**os.environ, **plan.env, "PYTHONUNBUFFERED": "1"}
    procs = {}
    with open(work / "nodes.log", "ab") as log:
        for role, cmd in plan.commands.items():
            procs[role] = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=log, stderr=log)
        cpu = _reap(procs, stop_after=(topics.PLANT, topics.RECORDER))
    bag.unlink(missing_ok=True)
    return cpu


def floor_cpu(steps: int, work: Path, raw: bool) -> dict[str, float]:
    """bench/forward_chain.py's four processes (`raw`: of bytes) for `steps` steps: each one's CPU [s]."""
    result = work / f"chain_{time.monotonic_ns()}.json"
    procs = {role: subprocess.Popen(forward_chain.command(role, steps, result, raw), stdin=subprocess.DEVNULL)
             for role in ROLES}
    return _reap(procs, stop_after=tuple(ROLES))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--short", type=int, default=200, help="steps of the short runs")
    p.add_argument("--long", type=int, default=2000, help="steps of the long runs")
    p.add_argument("--out", type=Path, default=machine.RESULTS)
    args = p.parse_args()
    if not 0 < args.short < args.long:
        raise SystemExit("node_cpu: need 0 < --short < --long")
    kinds = {"real loop": lambda n, w: real_cpu(n, w), "floor (objects)": lambda n, w: floor_cpu(n, w, False),
             "raw floor (bytes)": lambda n, w: floor_cpu(n, w, True)}
    before = machine.describe()
    per_step: dict[str, list[dict[str, float]]] = {k: [] for k in kinds}
    with tempfile.TemporaryDirectory(prefix="node_cpu_") as tmp:
        for i in range(args.repeat):
            for kind, run in kinds.items():
                short, long = run(args.short, Path(tmp)), run(args.long, Path(tmp))
                per_step[kind].append({r: (long[r] - short[r]) / (args.long - args.short) * 1e3 for r in ROLES})
                print(f"pass {i + 1}, {kind}: " + ", ".join(f"{r} {v:.2f}" for r, v in per_step[kind][-1].items())
                      + " ms a step", flush=True)
    med = {k: {r: float(np.median([s[r] for s in v])) for r in ROLES} for k, v in per_step.items()}
    print(f"\nCPU a step (ms; medians of {args.repeat}; {args.long} - {args.short} steps; load average before "
          f"{before['load_average']})")
    print(f"{'':<20}" + "".join(f"{r:>12}" for r in (*ROLES, "total")))
    for kind, m in med.items():
        print(f"{kind:<20}" + "".join(f"{m[r]:>12.2f}" for r in ROLES) + f"{sum(m.values()):>12.2f}")
    total = {k: sum(m.values()) for k, m in med.items()}
    print(f"real / floor {total['real loop'] / total['floor (objects)']:.2f}, "
          f"real / raw floor {total['real loop'] / total['raw floor (bytes)']:.2f}")
    rec = {"short": args.short, "long": args.long, "repeat": args.repeat, "per_step_ms": per_step, "median_ms": med,
           "machine_before": before, "machine_after": machine.describe()}
    print(f"appended to {machine.append('node_cpu', rec, args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
