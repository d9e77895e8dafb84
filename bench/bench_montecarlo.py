"""Benchmark: the Monte Carlo at the paper's scale, against the plant alone (bench/floors.py).

    python bench/bench_montecarlo.py [--runs 5000] [--duration 2000] [--workers 2] [--check 3]

1. The whole campaign (`montecarlo.campaign.montecarlo`, sampling excluded from its wall time, as the
   CLI reports it): wall and CPU seconds and the paper-style table.
2. The floor on the same initial states, the same worker count and the same process pool: the plant
   alone in a compiled loop (RK4 with the zero-order hold, the safety values at every substep, no
   filter, u = 0). Monte Carlo / floor (wall and CPU) is what the filter and the bookkeeping add to
   the physics; the target is <= 2.
3. A check as it times: `--check` runs of the campaign equal `simulate` of their initial states bit
   for bit (the same compiled one-state functions).

Appends to bench/results/montecarlo.json with the machine's load. Not collected by pytest.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine
from floors import plant_floor

from rta_attitude import config
from rta_attitude.config.schema import Scenario
from rta_attitude.montecarlo import campaign
from rta_attitude.montecarlo.runner import run_runs, split
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.closed_loop import ClosedLoop


def _cpu_s() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _floor_chunk(args: tuple[str, np.ndarray, float]) -> np.ndarray:
    preset, x0, duration_s = args
    return plant_floor(config.load(preset=preset), x0, duration_s)


def floor(preset: str, x0: np.ndarray, duration_s: float, workers: int) -> tuple[float, float]:
    """(wall, CPU) seconds of the plant alone over x0 in `workers` processes (one chunk each, as the
    campaign splits them)."""
    plant_floor(config.load(preset=preset), x0[:1], 1.0)  # compile or load before timing
    chunks = [(preset, x0[a:b], duration_s) for a, b in split(len(x0), workers)]
    ctx = mp.get_context("spawn")
    with ctx.Pool(workers) as pool:
        pool.map(_floor_chunk, [(preset, x0[:1], 1.0)] * workers)  # workers load the kernels untimed
        cpu0, t0 = _cpu_s(), time.perf_counter()
        out = pool.map(_floor_chunk, chunks)
        wall = time.perf_counter() - t0
        pool.close()
        pool.join()
    cpu = _cpu_s() - cpu0
    assert np.all(np.isfinite(np.concatenate(out)))
    return wall, cpu


def check_bit_for_bit(cfg: config.Config, x0: np.ndarray, duration_s: float) -> float:
    """Largest |x_campaign - x_simulate| over the runs x0 (0.0 means bit for bit)."""
    out = run_runs(cfg, x0, duration_s, record=True)
    assert out.trajectory is not None
    worst = 0.0
    for k in range(len(x0)):
        scen = Scenario("bench", "", duration_s, x0[k], controller="none")
        traj = ClosedLoop(cfg, scen).run()
        worst = max(worst, float(np.max(np.abs(traj.x - out.trajectory[k]))))
    return worst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5000)
    ap.add_argument("--duration", type=float, default=2000.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--presets", nargs="+", default=["robust"])
    ap.add_argument("--check", type=int, default=3, help="runs compared with simulate")
    ap.add_argument("--check-duration", type=float, default=300.0)
    ap.add_argument("--out", type=Path, default=machine.RESULTS)
    args = ap.parse_args()
    for preset in args.presets:
        cfg = config.load(preset=preset)
        before = machine.describe()
        result = campaign.montecarlo(cfg, args.runs, args.duration, args.seed, args.workers)
        s = campaign.summary(result)
        print(campaign.format_table(s))
        x0, _ = sample_initial_states(args.runs, args.seed, cfg)
        f_wall, f_cpu = floor(preset, x0, args.duration, args.workers)
        worst = check_bit_for_bit(cfg, x0[: args.check], args.check_duration) if args.check else 0.0
        steps = args.runs * round(args.duration / cfg.filter.sample_time_s)
        rec = {
            "preset": preset, "runs": args.runs, "duration_s": args.duration, "seed": args.seed,
            "workers": args.workers, "montecarlo_wall_s": round(result.wall_s, 2),
            "montecarlo_cpu_s": round(result.cpu_s, 1), "floor_wall_s": round(f_wall, 2),
            "floor_cpu_s": round(f_cpu, 1), "ratio_wall": round(result.wall_s / f_wall, 2),
            "ratio_cpu": round(result.cpu_s / f_cpu, 2),
            "cpu_us_per_state_step": round(result.cpu_s / steps * 1e6, 2),
            "floor_cpu_us_per_state_step": round(f_cpu / steps * 1e6, 2),
            "success_rate": s["at_samples"]["success_rate"], "failed": s["at_samples"]["failed"],
            "max_abs_diff_vs_simulate": worst, "checked_runs": args.check,
            "machine_before": before, "machine_after": machine.describe(),
        }  # fmt: skip
        print(f"\n{'':<28}{'wall':>9}{'CPU':>9}{'CPU/state-step':>16}")
        print(f"{'Monte Carlo':<28}{result.wall_s:>8.1f}s{result.cpu_s:>8.1f}s{rec['cpu_us_per_state_step']:>14.2f}us")
        print(f"{'floor (plant alone)':<28}{f_wall:>8.1f}s{f_cpu:>8.1f}s{rec['floor_cpu_us_per_state_step']:>14.2f}us")
        print(f"{'ratio (target <= 2)':<28}{rec['ratio_wall']:>9.2f}{rec['ratio_cpu']:>9.2f}")
        print(f"campaign vs simulate: max |dx| = {worst:.3g} over {args.check} runs x {args.check_duration:.0f} s; "
              f"load average before {before['load_average']}, after {rec['machine_after']['load_average']}")
        path = machine.append("montecarlo", rec, args.out)
        print(f"appended to {path}")
        if worst != 0.0:
            print("ERROR: a campaign run does not equal simulate bit for bit", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
