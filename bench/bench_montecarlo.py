"""Monte Carlo wall time at the paper's scale, checked against the single-run reference as it times.

    python bench/bench_montecarlo.py [--runs 5000] [--duration 2000] [--workers 2]
                                     [--presets robust paper] [--check 3] [--out bench/results]

For each preset: the whole Monte Carlo (sampling excluded from the wall time, as the CLI reports
it), the paper-style table, then a check that a few runs of the batch equal the single-run loop
(`ClosedLoop` with the same active-set solver) over --check-duration seconds. Results are appended
to OUT/montecarlo.json with the machine's core count and load. Never collected by pytest.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rta_attitude import config  # noqa: E402
from rta_attitude.config.schema import Scenario  # noqa: E402
from rta_attitude.montecarlo import batch  # noqa: E402
from rta_attitude.montecarlo import campaign as montecarlo  # noqa: E402
from rta_attitude.simulation import closed_loop as simulation  # noqa: E402


def check_against_single_runs(cfg: config.Config, x0: np.ndarray, duration_s: float) -> float:
    """Largest |x_batch - x_single| over the runs x0 (n, 19), duration_s each."""
    out = batch.BatchSimulator(cfg).run(x0, duration_s, record=True)
    worst = 0.0
    for k in range(len(x0)):
        scen = Scenario("bench", "", duration_s, x0[k], controller="none")
        traj = simulation.ClosedLoop(cfg.with_solver("active_set"), scen).run()
        worst = max(worst, float(np.max(np.abs(traj.x - out.trajectory[k]))))
    return worst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5000)
    ap.add_argument("--duration", type=float, default=2000.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--presets", nargs="+", default=["robust", "paper"])
    ap.add_argument("--check", type=int, default=3, help="runs compared with the single-run loop")
    ap.add_argument("--check-duration", type=float, default=300.0)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = ap.parse_args()
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             check=False).stdout.strip()
    except OSError:
        rev = ""
    records = []
    for preset in args.presets:
        cfg = config.load(preset=preset)
        load_before = os.getloadavg()
        t0 = time.perf_counter()
        result = montecarlo.montecarlo(cfg, args.runs, args.duration, args.seed, args.workers)
        total = time.perf_counter() - t0
        s = montecarlo.summary(result)
        print(montecarlo.format_table(s))
        worst = check_against_single_runs(cfg, result.x0[: args.check], args.check_duration) if args.check else 0.0
        steps = args.runs * round(args.duration / cfg.filter.sample_time_s)
        rec = {
            "preset": preset, "runs": args.runs, "duration_s": args.duration, "seed": args.seed,
            "workers": args.workers, "cores": os.cpu_count(), "wall_s": round(result.wall_s, 2),
            "wall_incl_sampling_s": round(total, 2), "cpu_s": round(result.cpu_s, 1),
            "idle_machine_wall_estimate_s": round(result.cpu_s / min(args.workers, os.cpu_count() or 1), 1),
            "state_steps_per_s": round(steps / result.wall_s),
            "us_per_state_step_per_core": round(result.wall_s * args.workers / steps * 1e6, 2),
            "load_average_before": [round(v, 2) for v in load_before],
            "load_average_after": [round(v, 2) for v in os.getloadavg()],
            "success_rate": s["at_samples"]["success_rate"], "failed": s["at_samples"]["failed"],
            "filter_shortfall": s["classification"]["filter_shortfall"],
            "max_abs_diff_vs_single_run": worst, "checked_runs": args.check, "git": rev,
            "python": platform.python_version(), "numpy": np.__version__,
            "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        }  # fmt: skip
        print(f"{preset}: {result.wall_s:.1f} s wall for {steps:.3g} state-steps "
              f"({rec['us_per_state_step_per_core']} us per state-step per core); batch vs single run: "
              f"max |dx| = {worst:.3g} over {args.check} runs x {args.check_duration:.0f} s")
        if worst > 1e-9:
            print("ERROR: the batch does not reproduce the single-run loop", file=sys.stderr)
            return 1
        records.append(rec)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "montecarlo.json"
    old = json.loads(path.read_text()) if path.is_file() else []
    path.write_text(json.dumps(old + records, indent=2) + "\n")
    print(f"appended to {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
