"""Benchmark: the lockstep closed loop over DDS with four node processes, against the core alone.

    python bench/bench_dds.py [--duration 2000] [--no-rta] [--repeat 1] [--executor events|single]

Runs `paper-example` with `rta_attitude.cli.launcher` (four OS processes, Fast DDS shared memory,
recorder on), then reports:

- DDS loop wall time: from the plant's first state to its final run_status (the plant measures it),
  and the launcher's wall time including process start-up, discovery and the bag's close;
- state -> torque_cmd latency per step (plant: publish of state(t_k) to receipt of torque_cmd(t_k),
  i.e. controller + filter + three DDS hops), median and p99;
- the core's own cost per step, in process: ClosedLoop.run() wall time, integrate (plant) and
  AsifFilter.filter (filter node) per call: the floor the DDS loop cannot beat;
- a check against the reference as it times: the recorded states equal ClosedLoop.run() (max |dx|).

Not collected by pytest; prints a table. Set ROS_DOMAIN_ID to keep it off other DDS traffic.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(40, 100)))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)

from rta_attitude import config
from rta_attitude.cli import launcher
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.recording.bag import read_bag
from rta_attitude.ros import convert, topics
from rta_attitude.simulation.closed_loop import ClosedLoop, integrate


def core_costs(cfg: config.Config, duration_s: float, rta: bool) -> dict[str, float]:
    """In-process ClosedLoop.run() time and per-call cost of integrate and filter [s]."""
    scenario = replace(cfg.scenario("paper_example"), duration_s=duration_s)
    t0 = time.perf_counter()
    traj = ClosedLoop(cfg, scenario, rta=rta).run()
    run_s = time.perf_counter() - t0
    sample = traj.x[:: max(1, len(traj.u) // 200)][:200]
    t0 = time.perf_counter()
    for x in sample:
        integrate(x, np.zeros(3), cfg.filter.sample_time_s, cfg)
    integrate_s = (time.perf_counter() - t0) / len(sample)
    filt = AsifFilter(cfg.for_scenario(scenario))
    idx = np.arange(0, len(traj.u), max(1, len(traj.u) // 200))[:200]
    t0 = time.perf_counter()
    for k in idx:
        filt.filter(traj.x[k], traj.u_des[k])
    filter_s = (time.perf_counter() - t0) / len(idx)
    return {"run_s": run_s, "integrate_s": integrate_s, "filter_s": filter_s, "traj": traj}  # type: ignore[dict-item]


def dds_run(duration_s: float, rta: bool, executor: str, work: Path) -> dict[str, float]:
    """One launcher run; returns timings and the max state difference to the reference."""
    parser = argparse.ArgumentParser()
    launcher.add_arguments(parser)
    bag = work / f"bench_{time.monotonic_ns()}.mcap"
    argv = ["--bag", str(bag), "--duration", str(duration_s), "-p", f"executor={executor}"]
    args = parser.parse_args(argv + (["--no-rta"] if not rta else []))
    plan = launcher.plan(args)
    t0 = time.perf_counter()
    problems, _facts = launcher.launch(plan, log_dir=work)
    total_s = time.perf_counter() - t0
    if problems:
        raise SystemExit("bench: " + "; ".join(problems))
    contents = read_bag(bag, topics=[f"{topics.DEFAULT_NAMESPACE}/{topics.STATE}",
                                     f"{topics.DEFAULT_NAMESPACE}/{topics.RUN_STATUS}"])
    states, status = [], None
    for m in contents.messages:
        if m.topic.endswith(topics.STATE):
            states.append(convert.state_from_msg(m.message)[1])
        else:
            status = convert.run_status_from_msg(m.message)[1]
    bag.unlink()
    assert status is not None
    return {"loop_s": status["wall_time_s"], "total_s": total_s, "latency_median_s": status["latency_median_s"],
            "latency_p99_s": status["latency_p99_s"], "x": np.array(states)}  # type: ignore[dict-item]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--duration", type=float, default=2000.0, help="scenario length, s (steps at dt = 1 s)")
    p.add_argument("--no-rta", action="store_true")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--executor", choices=("events", "single"), default="events")
    args = p.parse_args()
    cfg = config.load()
    rta = not args.no_rta
    steps = round(args.duration / cfg.filter.sample_time_s)
    core = core_costs(cfg, args.duration, rta)
    ref = core.pop("traj")
    print(f"paper-example, {steps} steps, rta={'on' if rta else 'off'}, executor {args.executor}, "
          f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}, load average {os.getloadavg()[0]:.2f}")
    print(f"{'what':<46}{'value':>12}")
    print(f"{'core: ClosedLoop.run() in process':<46}{core['run_s']:>10.2f} s")
    print(f"{'core: integrate per step (plant)':<46}{core['integrate_s'] * 1e3:>9.2f} ms")
    print(f"{'core: AsifFilter.filter per call (filter)':<46}{core['filter_s'] * 1e3:>9.2f} ms")
    floor = steps * (core["integrate_s"] + (core["filter_s"] if rta else 0.0))
    print(f"{'core floor of the serial chain':<46}{floor:>10.2f} s")
    with tempfile.TemporaryDirectory(prefix="bench_dds_") as tmp:
        for i in range(args.repeat):
            r = dds_run(args.duration, rta, args.executor, Path(tmp))
            diff = float(np.max(np.abs(r.pop("x") - ref.x)))  # type: ignore[arg-type]
            tag = f"run {i + 1}: "
            print(f"{tag + 'DDS lockstep loop, 4 processes':<46}{r['loop_s']:>10.2f} s  "
                  f"({r['loop_s'] / steps * 1e3:.2f} ms/step)")
            print(f"{tag + 'launcher total (start, run, stop, bag)':<46}{r['total_s']:>10.2f} s")
            print(f"{tag + 'state -> torque_cmd latency median':<46}{r['latency_median_s'] * 1e3:>9.2f} ms")
            print(f"{tag + 'state -> torque_cmd latency p99':<46}{r['latency_p99_s'] * 1e3:>9.2f} ms")
            print(f"{tag + 'max |x_dds - x_ClosedLoop|':<46}{diff:>12.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
