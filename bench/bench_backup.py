"""Benchmark: the cost of the gatekeeper (filter.backup_law) per filter call.

    python bench/bench_backup.py [--runs 5] [--duration 600] [--horizon S] [--nominal S]

States: Monte Carlo runs (seed 1, u_des = 0, the campaign's loop) with the gatekeeper on, recorded;
each run's states are then fed in order to `AsifFilter.filter` (what a node pays, Python in and out),
the filter reset at each run's start, once with the backup law and once without. The gate has memory
(its committed plan), so the states go in their run's order. Prints median, p99 and max per call and
the gate's outcomes; appends to bench/results/backup.json with the machine's load. Not collected by
pytest.
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

from rta_attitude import config
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.outcome import GATE_NAMES
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states


def time_calls(cfg: config.Config, runs: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """Per-call wall times (s) of `AsifFilter.filter` over runs (R, steps, 19), u_des = 0; gate counts
    ('reused': verified calls answered from a committed nominal plan, without a rollout)."""
    f = AsifFilter(cfg)
    times = []
    gates = dict.fromkeys((*GATE_NAMES, "reused"), 0)
    u = np.zeros(3)
    for run in runs:
        f.reset()
        for x in run:
            t0 = time.perf_counter()
            r = f.filter(x, u)
            times.append(time.perf_counter() - t0)
            gates[GATE_NAMES[int(r.record["gate"])]] += 1
        gates["reused"] += int(f._ws[0]["gate"]["reused"])
    return np.asarray(times), gates


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--horizon", type=float, default=None, help="backup_horizon_s (default: the config's)")
    ap.add_argument("--nominal", type=float, default=None, help="backup_nominal_s (default: the config's)")
    args = ap.parse_args()
    before = machine.describe()
    base = config.load()
    o = base.filter
    horizon = o.backup_horizon_s if args.horizon is None else args.horizon
    nominal = o.backup_nominal_s if args.nominal is None else args.nominal
    on = dataclasses.replace(base, filter=dataclasses.replace(o, backup_law="sun_safe", backup_horizon_s=horizon,
                                                              backup_nominal_s=nominal))
    x0, _ = sample_initial_states(args.runs, 1, on)
    mc = run_runs(on, x0, args.duration, record=True)
    assert mc.trajectory is not None
    runs = mc.trajectory[:, :-1]
    records = []
    for name, cfg in (("none", base.with_backup("none")), ("sun_safe", on)):
        AsifFilter(cfg).filter(runs[0, 0], np.zeros(3))  # compile or load first
        t, gates = time_calls(cfg, runs)
        us = t * 1e6
        rec = {"backup_law": name, "horizon_s": horizon, "nominal_s": nominal, "calls": len(us),
               "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max()),
               "gates": gates}
        records.append(rec)
        print(f"{name:9s} calls {len(us):6d}  median {rec['median_us']:8.1f} us  p99 {rec['p99_us']:8.1f} us  "
              f"max {rec['max_us']:8.1f} us  gates {gates}")
    after = machine.describe()
    machine.append("backup", {"machine_before": before, "machine_after": after, "results": records})
    print(f"load average before {before['load_average']}, after {after['load_average']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
