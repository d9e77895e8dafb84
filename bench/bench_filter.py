"""Benchmark: one ASIF filter call, against the filter written plainly (bench/floors.py).

    python bench/bench_filter.py [--solver active_set proxsuite] [--runs 40] [--reference 300]

States: the paper example's run (robust preset, PD, u_des from the run) and Monte Carlo states (seed 1,
`--runs` runs of 2,000 s, u_des = 0 as in the campaign). For each solver and state set:

- `AsifFilter.filter` per call (what a node pays, Python in and out): median, p99, max, by outcome
  (pass = the fast path, solved = a QP); each answer checked against the run's recorded command;
- the compiled kernel alone (`filter_many` over the states of one outcome): mean per call;
- `StraightforwardFilter.filter` (numpy barrier rows of the first implementation, numpy QP assembly,
  proxsuite) on `--reference` states of each outcome: median, and its answers against ours;
- the ratio median(straightforward) / median(AsifFilter.filter): the speed-up (target >= 50x).

Appends to bench/results/filter.json with the machine's load. Not collected by pytest.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine
from floors import StraightforwardFilter

from rta_attitude import config
from rta_attitude.dynamics.sensors import Instruments
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.pipeline import filter_many
from rta_attitude.filter.records import RESULT_DTYPE
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.closed_loop import ClosedLoop

OUTCOMES = ("pass", "solved", "fallback")


def state_sets(cfg: config.Config, runs: int) -> dict[str, tuple[config.Config, np.ndarray, np.ndarray, np.ndarray]]:
    """name -> (config, states (N, 19) as the filter receives them, u_des (N, 3), the run's command u (N, 3))."""
    loop = ClosedLoop(cfg, cfg.scenario("paper-example"), rta=True)
    traj = loop.run()
    read = Instruments(loop.cfg)  # the state across the message interface, as the run's filter got it
    received = np.array([read.deliver(x) for x in traj.x[:-1]])
    out = {"paper example": (loop.cfg, received, traj.u_des, traj.u)}
    x0, _ = sample_initial_states(runs, 1, cfg)
    mc = run_runs(cfg, x0, 2000.0, record=True)
    assert mc.trajectory is not None
    X = mc.trajectory[:, :-1].reshape(-1, 19)[::5]  # every 5th step of every run
    U = np.zeros((len(X), 3))
    f = AsifFilter(cfg)
    out["Monte Carlo (u_des = 0)"] = (cfg, X, U, np.asarray(f.filter_batch(X, U).u))
    return out


def stats(us: np.ndarray) -> dict[str, float]:
    return {"n": len(us), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max())}


def bench_set(cfg: config.Config, X: np.ndarray, U: np.ndarray, u_ref: np.ndarray, n_ref: int
              ) -> dict[str, dict[str, float]]:
    f = AsifFilter(cfg)
    sf = StraightforwardFilter(cfg)
    times: dict[str, list[float]] = {k: [] for k in OUTCOMES}
    status = []
    for k in range(len(X)):
        t0 = time.perf_counter()
        res = f.filter(X[k], U[k])
        times[res.status].append((time.perf_counter() - t0) * 1e6)
        status.append(res.status)
        if not np.allclose(res.u, u_ref[k], rtol=0, atol=1e-9 * (1 + np.abs(u_ref[k]).max())):
            raise SystemExit(f"state {k}: the filter's answer differs from the run's command")
    status_a = np.array(status)
    rows: dict[str, dict[str, float]] = {}
    for outcome in OUTCOMES:
        idx = np.flatnonzero(status_a == outcome)
        if len(idx) == 0:
            continue
        row = {"calls": len(idx), **{f"asif_{k}": v for k, v in stats(np.array(times[outcome])).items()}}
        Xs, Us = np.ascontiguousarray(X[idx]), np.ascontiguousarray(U[idx])
        res = np.zeros(len(idx), RESULT_DTYPE)
        filter_many(Xs, Us, np.zeros(len(idx)), f.record, f._ws, res)
        t0 = time.process_time()
        filter_many(Xs, Us, np.zeros(len(idx)), f.record, f._ws, res)
        row["kernel_mean_us"] = (time.process_time() - t0) / len(idx) * 1e6
        if outcome == "fallback":  # an infeasible QP: the plain filter has no fallback policy to time against
            rows[outcome] = row
            continue
        sub = idx[np.linspace(0, len(idx) - 1, min(n_ref, len(idx))).astype(int)]
        ref_t, worst = [], 0.0
        for k in sub:
            t0 = time.perf_counter()
            u = sf.filter(X[k], U[k])
            ref_t.append((time.perf_counter() - t0) * 1e6)
            worst = max(worst, float(np.max(np.abs(u - u_ref[k]))))
        row["straightforward_median_us"] = float(np.median(ref_t))
        row["straightforward_max_abs_du"] = worst
        row["speedup"] = row["straightforward_median_us"] / row["asif_median_us"]
        rows[outcome] = row
    all_t = np.concatenate([np.array(v) for v in times.values() if v])
    rows["all"] = {"calls": len(all_t), **{f"asif_{k}": v for k, v in stats(all_t).items()}}
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--solver", nargs="+", default=["active_set"], choices=["active_set", "proxsuite"])
    ap.add_argument("--runs", type=int, default=40, help="Monte Carlo runs whose states are filtered")
    ap.add_argument("--reference", type=int, default=300, help="states per outcome given to the plain filter")
    ap.add_argument("--out", type=Path, default=machine.RESULTS)
    args = ap.parse_args()
    before = machine.describe()
    records = []
    for solver in args.solver:
        # the ASIF's own call, as the straightforward filter computes it (the gatekeeper's cost: bench_backup.py)
        cfg = config.load().with_solver(solver).with_backup("none")
        for name, (scfg, X, U, u_ref) in state_sets(cfg, args.runs).items():
            rows = bench_set(scfg, X, U, u_ref, args.reference)
            print(f"\n[{solver}] {name}: {len(X)} states")
            print(f"{'outcome':<10}{'calls':>7}{'median':>10}{'p99':>10}{'max':>10}{'kernel':>10}"
                  f"{'plain':>11}{'speed-up':>10}{'max |du|':>11}")
            for outcome, r in rows.items():
                line = (f"{outcome:<10}{r['calls']:>7}{r['asif_median_us']:>8.1f}us{r['asif_p99_us']:>8.1f}us"
                        f"{r['asif_max_us']:>8.0f}us")
                if "kernel_mean_us" in r:
                    line += f"{r['kernel_mean_us']:>8.2f}us"
                if "speedup" in r:
                    line += (f"{r['straightforward_median_us']:>9.0f}us"
                             f"{r['speedup']:>9.0f}x{r['straightforward_max_abs_du']:>11.1e}")
                print(line)
            records.append({"solver": solver, "states": name, "rows": rows})
    path = machine.append("filter", {"machine_before": before, "machine_after": machine.describe(),
                                     "results": records})
    print(f"\nload average before {before['load_average']}, after {machine.describe()['load_average']}; "
          f"appended to {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
