"""Benchmark: one ASIF filter call (median, p99, max), intervening vs not, and simulation speed.

Not a test: run `python bench/bench_filter.py [--solver active_set proxsuite]`. States come from
the paper example (robust preset, PD active), run with each solver; each timed answer is checked
against that run's recorded command. Targets (issue 3): median <= 100 us intervening, <= 30 us
non-intervening, max over the example run <= 5 ms.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rta_attitude import config
from rta_attitude.filter.asif import AsifFilter, compile_kernels
from rta_attitude.simulation.closed_loop import ClosedLoop


def stats(us: np.ndarray) -> str:
    p99 = np.percentile(us, 99)
    return f"{len(us):6d} calls  median {np.median(us):8.1f} us  p99 {p99:8.1f} us  max {us.max():8.1f} us"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="timed passes over the run's states")
    ap.add_argument("--solver", nargs="+", default=["active_set", "proxsuite"], choices=["active_set", "proxsuite"])
    args = ap.parse_args()
    print(f"filter kernels compiled or loaded in {compile_kernels(config.load()):.2f} s")
    for solver in args.solver:
        bench(solver, args.repeat)


def bench(solver: str, repeat: int) -> None:
    cfg = config.load().with_solver(solver)
    scen = cfg.scenario("paper-example")
    loop = ClosedLoop(cfg, scen, rta=True)
    t0 = time.perf_counter()
    traj = loop.run()
    wall = time.perf_counter() - t0
    print(f"[{solver}] in-process simulation, paper example, robust RTA: {traj.steps} steps in {wall:.2f} s "
          f"= {traj.steps / wall:.0f} steps/s; filter call inside that run: median "
          f"{np.median(traj.solve_time_s) * 1e6:.1f} us, max {traj.solve_time_s.max() * 1e6:.1f} us")
    f = AsifFilter(loop.cfg)
    times: dict[str, list[float]] = {"pass": [], "solved": [], "fallback": []}
    for _ in range(repeat):
        for k in range(traj.steps):
            t = time.perf_counter()
            res = f.filter(traj.x[k], traj.u_des[k])
            dt = time.perf_counter() - t
            times[res.status].append(dt * 1e6)
            if not np.allclose(res.u, traj.u[k], rtol=0, atol=1e-9 * (1 + np.abs(traj.u[k]).max())):
                raise SystemExit(f"step {k}: filter answer differs from the run's command")
    print(f"[{solver}] filter call on the paper example's states (each checked against the run):")
    for key, label in (("pass", "non-intervening (fast path)"), ("solved", "intervening (QP)"),
                       ("fallback", "fallback")):
        if times[key]:
            print(f"  {label:30s} {stats(np.array(times[key]))}")
    allt = np.concatenate([np.array(v) for v in times.values() if v])
    print(f"  {'all':30s} {stats(allt)}")


if __name__ == "__main__":
    main()
