"""Benchmark: the viability oracle's wall and CPU time on two hard states, by horizon and method.

    python bench/bench_viability.py [--model paper|gyrostat] [--horizons 100,300,1000,2000]
                                    [--modes default,direct,segmented] [--no-compile]

States (sun-safe attitude = panel on the sun, antenna on the Earth side, sensor perpendicular):
- hard: sensor 45 deg from the sun and turning towards it at 0.9 deg/s, wheels at (500, -500, 500)
  rad/s, T = 280 K, E = 3000 J;
- dark3000: panel pointing straight away from the sun, at rest, E = 3000 J (survives only a fast flip
  over long horizons).
Modes: default (`find_witness` as shipped), direct (warm-start laws only as the guess, one NLP over
the horizon), segmented (receding segments from the start). Every witness is re-simulated by the
project's plant and checked at every substep with the project's safety values. Appends to
bench/results/viability.json with the machine's load. The first use of a model compiles its blocks.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import machine  # noqa: E402

from rta_attitude import config  # noqa: E402
from rta_attitude.config.schema import Config  # noqa: E402
from rta_attitude.constraints import ConstraintSet, registry  # noqa: E402
from rta_attitude.dynamics.spacecraft import integrate, plant_record  # noqa: E402
from rta_attitude.dynamics.state import STATE_SIZE  # noqa: E402


def states(cfg: Config) -> dict[str, np.ndarray]:
    from rta_attitude.viability.laws import quat_from_matrix, sun_safe_matrix
    from rta_attitude.viability.params import from_config

    i, j, k = sun_safe_matrix(1.0, from_config(cfg))
    b = math.radians(45.0)
    hard = np.vstack([math.cos(b) * i + math.sin(b) * k, j, -math.sin(b) * i + math.cos(b) * k])
    return {
        "hard": np.concatenate([quat_from_matrix(hard), [0.0, -math.radians(0.9), 0.0], [500.0, -500.0, 500.0],
                                [280.0, 3000.0, 1.0]]),
        "dark3000": np.concatenate([quat_from_matrix(np.vstack([-i, j, -k])), np.zeros(6), [270.0, 3000.0, 1.0]]),
    }


def plant_check(cfg: Config, x0: np.ndarray, u: np.ndarray, enforce: tuple[str, ...]) -> float:
    """The smallest enforced safety value (project units) of u on the project's plant, at every substep."""
    p = plant_record(cfg)
    x = np.zeros(STATE_SIZE)
    x[:13] = x0
    rows = [x.copy()]
    for uk in u:
        x, s = integrate(x, uk, cfg.filter.sample_time_s, p, cfg.substeps)
        rows.extend(s)
    h = ConstraintSet(cfg).safety_values(np.array(rows))
    cols = [c.row for c in registry(cfg) if c.group in enforce]
    return float(h[:, cols].min())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", choices=("paper", "gyrostat"), default=None, help="default: the config's")
    ap.add_argument("--horizons", default="100,300,1000,2000")
    ap.add_argument("--modes", default="default,direct,segmented")
    ap.add_argument("--states", default="hard,dark3000")
    ap.add_argument("--time-limit", type=float, default=1200.0)
    ap.add_argument("--no-compile", action="store_true")
    args = ap.parse_args()
    from rta_attitude.viability import find_witness

    cfg = config.load()
    if args.model:
        cfg = replace(cfg, spacecraft=replace(cfg.spacecraft, model=args.model))
    table = states(cfg)
    rows = []
    print(f"{'state':<10}{'mode':<11}{'H s':>6}  {'verdict':<18}{'method':<12}{'wall s':>8}{'CPU s':>8}{'iters':>7}"
          f"{'plant min h':>13}")
    for name in args.states.split(","):
        for mode in args.modes.split(","):
            for horizon in (float(h) for h in args.horizons.split(",")):
                kw = {"time_limit_s": args.time_limit, "compile": not args.no_compile}
                if mode == "direct":
                    kw.update(use_warm_start=False, direct_max_s=horizon)
                elif mode == "segmented":
                    kw.update(direct_max_s=0.0)
                t0 = time.perf_counter()
                r = find_witness(table[name], horizon, cfg, **kw)
                wall = time.perf_counter() - t0
                hmin = plant_check(cfg, table[name], r.u, r.enforce) if r.u is not None else math.nan
                rows.append({"state": name, "mode": mode, "horizon_s": horizon, "verdict": r.verdict,
                             "method": r.method, "wall_s": round(wall, 2), "cpu_s": round(r.cpu_time_s, 2),
                             "iterations": r.iterations, "plant_min_h": hmin})
                print(f"{name:<10}{mode:<11}{horizon:>6.0f}  {r.verdict:<18}{r.method:<12}{wall:>8.1f}"
                      f"{r.cpu_time_s:>8.1f}{r.iterations:>7d}{hmin:>13.3g}", flush=True)
    path = machine.append("viability", {"machine": machine.describe(), "model": cfg.spacecraft.model,
                                        "compiled": not args.no_compile, "rows": rows})
    print(f"appended to {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
