"""Benchmark: the filter call with eight pointing constraints against the call with the paper's two, same states.

    python bench/bench_cones.py [--runs 20] [--cones 8]

States: Monte Carlo states of the default configuration (seed 1, `--runs` runs of 2,000 s, every 5th step,
u_des = 0), filtered without the gatekeeper (its cost: bench_backup.py), once by the paper's set and once by a
set with `--cones` pointing constraints: the paper's two and keep-out cones of 2 deg about every other kind of
target (the Earth, the orbit normal, the velocity, a Hill vector, an inertial vector, the sun), which these
states seldom come near (they change the answer in 28 of 2,000 states of 5 runs), so the difference is mostly
the cost of the rows; the report says whether the answers were identical. Reports
`AsifFilter.filter` per call (median, p99) and the compiled kernel alone (`filter_many`, mean per call), and the
ratios eight / two (the target: <= 2). Appends to bench/results/cones.json with the machine's load. Not collected
by pytest.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine

from rta_attitude import config
from rta_attitude.config.schema import PointingConstraint
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.pipeline import filter_many
from rta_attitude.filter.records import RESULT_DTYPE
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states

EXTRA = (("earth", None, (0.0, 0.0, 1.0)), ("orbit_normal", None, (1.0, 0.0, 0.0)),
         ("velocity", None, (0.0, -1.0, 0.0)), ("hill", (0.6, 0.0, 0.8), (0.0, 1.0, 0.0)),
         ("inertial", (0.0, 0.6, 0.8), (0.0, 0.0, -1.0)), ("sun", None, (-1.0, 0.0, 0.0)))  # fmt: skip
"""(target, target vector, boresight) of the added cones."""


def with_cones(cfg: config.Config, n: int) -> config.Config:
    """cfg with n pointing constraints: its own and keep-out cones of 2 deg (EXTRA, in turn)."""
    extra = []
    for k in range(n - len(cfg.pointing)):
        target, vector, axis = EXTRA[k % len(EXTRA)]
        extra.append(PointingConstraint(f"bench_{k}", "keep_out", axis, target, math.radians(2.0),
                                        cfg.pointing[0].gains, target_vector=vector))
    return dataclasses.replace(cfg, pointing=(*cfg.pointing, *extra))


def time_calls(cfg: config.Config, X: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """(per-call wall times of AsifFilter.filter in us, the compiled kernel's mean per call in us, answers)."""
    f = AsifFilter(cfg)
    U = np.zeros(3)
    us = np.empty(len(X))
    out = np.empty((len(X), 3))
    for k in range(len(X)):
        t0 = time.perf_counter()
        out[k] = f.filter(X[k], U).u
        us[k] = (time.perf_counter() - t0) * 1e6
    R = np.zeros(len(X), RESULT_DTYPE)
    Z, T = np.zeros((len(X), 3)), np.zeros(len(X))
    filter_many(X, Z, T, f.record, f._ws, R)
    t0 = time.process_time()
    filter_many(X, Z, T, f.record, f._ws, R)
    return us, (time.process_time() - t0) / len(X) * 1e6, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20, help="Monte Carlo runs whose states are filtered")
    ap.add_argument("--cones", type=int, default=8, help="pointing constraints of the larger set")
    ap.add_argument("--out", type=Path, default=machine.RESULTS)
    args = ap.parse_args()
    before = machine.describe()
    paper = config.load().with_backup("none")
    x0, _ = sample_initial_states(args.runs, 1, paper)
    mc = run_runs(paper, x0, 2000.0, record=True)
    assert mc.trajectory is not None
    X = np.ascontiguousarray(mc.trajectory[:, :-1].reshape(-1, 19)[::5])
    many = with_cones(paper, args.cones)
    rows = {}
    answers = {}
    for label, cfg in (("paper's 2", paper), (f"{args.cones} cones", many)):
        time_calls(cfg, X[:50])  # compile or load, warm up
        us, kernel, answers[label] = time_calls(cfg, X)
        rows[label] = {"calls": len(X), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
                       "kernel_mean_us": kernel}
    a, b = rows.values()
    same = bool(np.array_equal(*answers.values()))
    ratio = {"median": b["median_us"] / a["median_us"], "p99": b["p99_us"] / a["p99_us"],
             "kernel": b["kernel_mean_us"] / a["kernel_mean_us"]}
    print(f"{len(X)} Monte Carlo states (seed 1, {args.runs} runs); answers identical: {same}")
    print(f"{'set':<12}{'median':>10}{'p99':>10}{'kernel':>10}")
    for label, r in rows.items():
        print(f"{label:<12}{r['median_us']:>8.1f}us{r['p99_us']:>8.1f}us{r['kernel_mean_us']:>8.2f}us")
    print(f"ratio (target <= 2): median {ratio['median']:.2f}, p99 {ratio['p99']:.2f}, kernel {ratio['kernel']:.2f}")
    path = machine.append("cones", {"machine_before": before, "machine_after": machine.describe(), "rows": rows,
                                    "ratio": ratio, "answers_identical": same})
    print(f"load average before {before['load_average']}, after {machine.describe()['load_average']}; "
          f"appended to {path}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
