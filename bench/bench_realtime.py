"""Benchmark: the highest real-time rate the four-process loop sustains with zero deadline misses.

    python bench/bench_realtime.py [--steps 300] [--burners 0 2] [--lo 10] [--hi 4000] [--out DIR]

The plant steps on a wall-clock timer (`rta-attitude launch --realtime R`: R simulated seconds per
wall second, dt = 1 s, so R steps per wall second); at every tick the command for the previous
state must have arrived, or it is a deadline miss. A trial runs `--steps` steps of paper-example at
one rate and passes if the plant counted no deadline miss. The rate is doubled from `--lo` until a
trial fails, then bisected (4 more trials): the answer is the highest passing rate, within ~10 %.
Done on a quiet machine (`--burners 0`) and with busy processes keeping every core at 100 %
(`--burners 2` on this 2-core machine). Each trial is a real `rta-attitude launch` subprocess (nodes
over Fast DDS, the recorder on), so what is measured is what a user gets.

Prints a table and writes `bench/results/realtime.json` with the machine's load.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results"


def _burn(stop: mp.synchronize.Event) -> None:  # type: ignore[name-defined]
    x = 0
    while not stop.is_set():
        for _ in range(200_000):
            x = (x * 1103515245 + 12345) & 0xFFFFFFFF


def trial(rate: float, steps: int, work: Path, env: dict[str, str]) -> dict[str, object]:
    """One real-time launch at `rate` steps per wall second; its deadline misses and wall time."""
    out = work / f"rt_{rate:g}_{time.monotonic_ns()}"
    cmd = [sys.executable, "-m", "rta_attitude.cli", "launch", "--realtime", f"{rate:g}", "--duration", str(steps),
           "--bag", str(out / "run.mcap"), "--out", str(out), "-p", "deadline_fallback=zero"]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=600 + 2 * steps / rate)
    wall = time.monotonic() - t0
    summary_path = out / "summary.json"
    if proc.returncode != 0 or not summary_path.exists():
        return {"rate": rate, "ok": False, "misses": None, "error": (proc.stderr.strip().splitlines() or ["?"])[-1],
                "wall_s": wall}
    launch = json.loads(summary_path.read_text())["launch"]
    misses = int(launch.get("deadline_misses", 0))
    return {"rate": rate, "ok": misses == 0, "misses": misses, "loop_s": launch.get("wall_time_s"), "wall_s": wall}


def search(lo: float, hi: float, steps: int, work: Path, env: dict[str, str], log: list[dict[str, object]]) -> float:
    """Highest rate in [lo, hi] with zero misses (0 if even lo misses)."""

    def run(rate: float) -> bool:
        r = trial(rate, steps, work, env)
        log.append(r)
        print(f"  {rate:8.1f} steps/s: {'ok' if r['ok'] else 'MISS'} (misses {r['misses']}, "
              f"{r['wall_s']:.1f} s){'' if r.get('error') is None else ' ' + str(r['error'])}", flush=True)
        return bool(r["ok"])

    if not run(lo):
        return 0.0
    good, bad = lo, None
    while bad is None and good * 2 <= hi:
        if run(good * 2):
            good *= 2
        else:
            bad = good * 2
    if bad is None:
        return good
    for _ in range(4):
        mid = (good + bad) / 2
        if run(mid):
            good = mid
        else:
            bad = mid
    return good


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="steps per trial (default 300)")
    parser.add_argument("--burners", type=int, nargs="+", default=[0, os.cpu_count() or 2],
                        help="busy processes per condition (default: 0, then one per core)")
    parser.add_argument("--lo", type=float, default=10.0, help="first rate tried, steps/s (default 10)")
    parser.add_argument("--hi", type=float, default=4000.0, help="highest rate tried, steps/s (default 4000)")
    parser.add_argument("--out", type=Path, default=None, help="keep the trial bags and logs here")
    args = parser.parse_args(argv)
    env = {**os.environ, "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID", str(random.SystemRandom().randint(40, 100))),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "PYTHONPATH": str(REPO)}
    work = args.out or Path(tempfile.mkdtemp(prefix="bench_realtime_"))
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for burners in args.burners:
        stop = mp.Event()
        procs = [mp.Process(target=_burn, args=(stop,), daemon=True) for _ in range(burners)]
        for p in procs:
            p.start()
        print(f"{burners} burner(s): load {os.getloadavg()[0]:.1f}", flush=True)
        log: list[dict[str, object]] = []
        try:
            best = search(args.lo, args.hi, args.steps, work, env, log)
        finally:
            stop.set()
            for p in procs:
                p.join(timeout=5)
        rows.append({"burners": burners, "max_rate_steps_per_s": best, "trials": log,
                     "load_1min_after": os.getloadavg()[0]})
    print(f"\n{'condition':<28}{'highest rate with 0 misses':>28}")
    for r in rows:
        cond = "quiet" if r["burners"] == 0 else f"{r['burners']} cores busy"
        print(f"{cond:<28}{r['max_rate_steps_per_s']:>22.0f} steps/s")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "realtime.json").write_text(json.dumps({"steps_per_trial": args.steps, "cpus": os.cpu_count(),
                                                       "conditions": rows}, indent=2) + "\n")
    print(f"wrote {RESULTS / 'realtime.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
