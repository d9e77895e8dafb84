"""Benchmark: the cost of the gatekeeper (filter.backup_law) per filter call.

    python bench/bench_backup.py [--runs 40] [--duration 2000] [--first 0] [--horizon S] [--nominal S]

States: Monte Carlo runs (seed 1, u_des = 0, the campaign's loop and length) with the gatekeeper on,
recorded; each run's states are then fed in order to `AsifFilter.filter` (what a node pays, Python in
and out), the filter reset at each run's start, once with the backup law and once without. The gate has
memory (its committed plan), so the states go in their run's order. The default, the first 40 runs of
the campaign's 5,000 over its 2,000 s, is a sample of the calls the Monte Carlo makes (`--runs 5
--duration 600` is the smaller set of the rows before 2026-11-27, one in five of whose runs has no
verified way out for most of its calls).

Prints median, p99, p99.9 and max per call; the calls by what the gate did (`path`: answered from a
committed plan, a new nominal plan verified, a one-sample check while nominal plans wait after a failed
one, the committed plan's backup law, nothing verified, the backup law through the filter); the run
with the worst p99; and a floor timed in the same run: the straightforward numpy + proxsuite filter
(`floors.StraightforwardFilter`, what `bench_filter.py` compares the filter with) on 300 of the same
states. Appends to bench/results/backup.json with the machine's load. Not collected by pytest.
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
from floors import StraightforwardFilter

from rta_attitude import config
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.outcome import GATE_NAMES
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states

PATHS = ("from_plan", "nominal_plan", "after_failed_plan", "backup", "nothing_verified", "filtered_backup", "other")
"""What the gate did at a call (`path_of`)."""


def path_of(code: str, reused: bool, new_plan: bool, waiting: bool) -> str:
    """The gate's path at one call from its outcome code and its workspace before and after (bench only)."""
    if reused:
        return "from_plan"
    if code == "verified":
        return "nominal_plan" if new_plan else ("after_failed_plan" if waiting else "other")
    if code in ("unverified", "toward_backup"):
        return "nothing_verified"
    if code in ("backup", "filtered_backup"):
        return code
    return "other"


def time_calls(cfg: config.Config, runs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, int]]:
    """Per-call wall times (s) of `AsifFilter.filter` over runs (R, steps, 19), u_des = 0; each call's path
    (PATHS) and run; gate counts ('reused': verified calls answered from a committed nominal plan)."""
    f = AsifFilter(cfg)
    nominal = int(f.record[0]["backup"]["nominal_steps"])
    times, paths, run_of = [], [], []
    gates = dict.fromkeys((*GATE_NAMES, "reused"), 0)
    u = np.zeros(3)
    for k, run in enumerate(runs):
        f.reset()
        g = f._ws[0]["gate"]
        for x in run:
            reused0 = int(g["reused"])
            t0 = time.perf_counter()
            r = f.filter(x, u)
            times.append(time.perf_counter() - t0)
            code = GATE_NAMES[int(r.record["gate"])]
            gates[code] += 1
            new_plan = int(g["plan_at"]) == 1 and int(g["plan_n"]) == nominal > 1
            paths.append(path_of(code, int(g["reused"]) > reused0, new_plan, int(g["nominal_wait"]) > 0))
            run_of.append(k)
        gates["reused"] += int(g["reused"])
    return np.asarray(times), np.asarray(paths), np.asarray(run_of), gates


def stats(us: np.ndarray) -> dict[str, float]:
    return {"calls": len(us), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "p999_us": float(np.percentile(us, 99.9)), "max_us": float(us.max()),
            "over_1ms": int((us > 1000).sum()), "over_3ms": int((us > 3000).sum())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--first", type=int, default=0, help="the first run of the campaign's states to take")
    ap.add_argument("--duration", type=float, default=2000.0)
    ap.add_argument("--horizon", type=float, default=None, help="backup_horizon_s (default: the config's)")
    ap.add_argument("--nominal", type=float, default=None, help="backup_nominal_s (default: the config's)")
    ap.add_argument("--floor-states", type=int, default=300, help="states the straightforward filter is timed on")
    args = ap.parse_args()
    before = machine.describe()
    base = config.load()
    o = base.filter
    horizon = o.backup_horizon_s if args.horizon is None else args.horizon
    nominal = o.backup_nominal_s if args.nominal is None else args.nominal
    on = dataclasses.replace(base, filter=dataclasses.replace(o, backup_law="sun_safe", backup_horizon_s=horizon,
                                                              backup_nominal_s=nominal))
    x0, _ = sample_initial_states(args.first + args.runs, 1, on)
    mc = run_runs(on, x0[args.first:], args.duration, record=True)
    assert mc.trajectory is not None
    runs = mc.trajectory[:, :-1]
    records = []
    for name, cfg in (("none", base.with_backup("none")), ("sun_safe", on)):
        AsifFilter(cfg).filter(runs[0, 0], np.zeros(3))  # compile or load first
        t, paths, run_of, gates = time_calls(cfg, runs)
        us = t * 1e6
        rec = {"backup_law": name, "horizon_s": horizon, "nominal_s": nominal, "runs": args.runs, "first": args.first,
               "duration_s": args.duration, **stats(us), "gates": gates}
        if name == "sun_safe":
            rec["paths"] = {p: stats(us[paths == p]) for p in PATHS if (paths == p).any()}
            p99_run = [float(np.percentile(us[run_of == k], 99)) for k in range(len(runs))]
            worst = int(np.argmax(p99_run))
            nothing = int(((run_of == worst) & (paths == "nothing_verified")).sum())
            rec["worst_run"] = {"run": args.first + worst, **stats(us[run_of == worst]),
                                "nothing_verified_calls": nothing}
        records.append(rec)
        print(f"{name:9s} calls {len(us):6d}  median {rec['median_us']:8.1f} us  p99 {rec['p99_us']:8.1f} us  "
              f"p99.9 {rec['p999_us']:8.1f} us  max {rec['max_us']:8.1f} us  over 1 ms {rec['over_1ms']}")
    for p, s in records[1]["paths"].items():
        print(f"  {p:18s} {s['calls']:7d} calls  median {s['median_us']:8.1f} us  p99 {s['p99_us']:8.1f} us  "
              f"max {s['max_us']:8.1f} us  over 1 ms {s['over_1ms']}")
    w = records[1]["worst_run"]
    print(f"  worst run {w['run']}: p99 {w['p99_us']:.0f} us, max {w['max_us']:.0f} us, "
          f"{w['nothing_verified_calls']} of its {w['calls']} calls with nothing verified")
    sf = StraightforwardFilter(base)
    X = runs.reshape(-1, runs.shape[-1])
    pick = np.linspace(0, len(X) - 1, args.floor_states).astype(int)
    ref = []
    for k in pick:
        t0 = time.perf_counter()
        sf.filter(X[k], np.zeros(3))
        ref.append((time.perf_counter() - t0) * 1e6)
    floor = {"states": len(pick), "median_us": float(np.median(ref))}
    p99 = records[1]["p99_us"]
    print(f"floor: the straightforward filter, median {floor['median_us']:.0f} us on {len(pick)} of the states; "
          f"the gate's p99 / that = {p99 / floor['median_us']:.2f}")
    after = machine.describe()
    machine.append("backup", {"machine_before": before, "machine_after": after, "results": records,
                              "straightforward_floor": floor})
    print(f"load average before {before['load_average']}, after {after['load_average']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
