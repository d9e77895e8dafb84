"""Benchmark: the filter call over four wheels in a pyramid with eight pointing constraints, against today's call
(the paper's three wheels and two cones), same states.

    python bench/bench_array_filter.py [--runs 20] [--cones 8]

States: Monte Carlo states of the default configuration without the gatekeeper (seed 1, `--runs` runs of 2,000 s,
every 5th step, u_des = 0), filtered once by `AsifFilter` (the paper's vehicle) and once by `ArrayFilter` (the
same body with four wheels in a pyramid, each 35.26 deg above the x-y plane, and `--cones` pointing constraints:
bench_cones.py's set), each state holding the same momentum (`array_loop.array_state`). Reports the Python call
(median, p99) and the ratio array / paper (the target: <= 2). Appends to bench/results/array_filter.json with the
machine's load. Not collected by pytest.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine
from bench_cones import with_cones

from rta_attitude import config
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.wheel_array import ArrayFilter
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.array_loop import array_state

S = 0.57735027
PYRAMID = ((S, S, S), (-S, S, S), (-S, -S, S), (S, -S, S))


def time_calls(filt, X: np.ndarray, n_u: int) -> np.ndarray:
    """Per-call wall times (us) of filt.filter over the states X with u_des = 0."""
    U = np.zeros(n_u)
    us = np.empty(len(X))
    for k in range(len(X)):
        t0 = time.perf_counter()
        filt.filter(X[k], U)
        us[k] = (time.perf_counter() - t0) * 1e6
    return us


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20, help="Monte Carlo runs whose states are filtered")
    ap.add_argument("--cones", type=int, default=8, help="pointing constraints of the array's set")
    ap.add_argument("--out", type=Path, default=machine.RESULTS)
    args = ap.parse_args()
    before = machine.describe()
    paper = config.load().with_backup("none")
    x0, _ = sample_initial_states(args.runs, 1, paper)
    mc = run_runs(paper, x0, 2000.0, record=True)
    assert mc.trajectory is not None
    X = np.ascontiguousarray(mc.trajectory[:, :-1].reshape(-1, 19)[::5])
    sc = dataclasses.replace(paper.spacecraft, wheel_axes_body=PYRAMID, wheel_names=("rw1", "rw2", "rw3", "rw4"))
    array = with_cones(dataclasses.replace(paper, spacecraft=sc), args.cones)
    XA = np.array([array_state(array, x) for x in X])
    rows = {}
    for label, filt, states, n_u in (("paper: 3 wheels, 2 cones", AsifFilter(paper), X, 3),
                                     (f"pyramid: 4 wheels, {args.cones} cones", ArrayFilter(array), XA, 4)):
        time_calls(filt, states[:50], n_u)  # compile or load, warm up
        us = time_calls(filt, states, n_u)
        rows[label] = {"calls": len(states), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
                       "by_status": dict(filt.counters.by_status)}
    a, b = rows.values()
    ratio = {"median": b["median_us"] / a["median_us"], "p99": b["p99_us"] / a["p99_us"]}
    print(f"{len(X)} Monte Carlo states (seed 1, {args.runs} runs)")
    for label, r in rows.items():
        print(f"  {label:<28} median {r['median_us']:7.1f} us  p99 {r['p99_us']:7.1f} us  {r['by_status']}")
    print(f"ratio (target <= 2): median {ratio['median']:.2f}, p99 {ratio['p99']:.2f}")
    path = machine.append("array_filter", {"machine_before": before, "machine_after": machine.describe(),
                                           "rows": rows, "ratio": ratio})
    print(f"load average before {before['load_average']}, after {machine.describe()['load_average']}; "
          f"appended to {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
