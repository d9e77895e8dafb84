"""Monte Carlo of a wheel array beside the same vehicle on three wheels, the paper's protocol (u_des = 0).

    python bench/array_montecarlo.py --config config/examples/pyramid_12u.yaml [--runs 1000] [--seed 7]
        [--workers 2] [--fail rw1]

The filter over the array (`filter.wheel_array`) runs each state through `simulation.array_loop.ArrayLoop`
(a Python loop over the compiled plant and filter); the three-wheel reference is the same configuration with
three wheels on the body axes through the package's Monte Carlo (`montecarlo.runner.run_runs`), both without
the gatekeeper (the array's filter does not take it yet). The initial states are the package's sampler's for
the three-wheel vehicle (`montecarlo.sampling`); the array starts holding the same momentum (its minimum-norm
split, `array_loop.array_state`); a state whose split puts a wheel past the speed its rows keep is counted and
left out of both. A run is safe if no hard constraint's h is negative at a sample or an RK4 substep.

Prints one table and appends it to bench/results/array_montecarlo.json with the machine's load. Not collected
by pytest.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine

from rta_attitude.config.loader import load
from rta_attitude.config.schema import BODY_AXES, WHEEL_JOINTS
from rta_attitude.dynamics.state import wheel_columns
from rta_attitude.montecarlo.controllers import RunController
from rta_attitude.montecarlo.runner import run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.array_loop import ArrayLoop, array_state

DURATION_S = 2000.0


def three_wheels(cfg):
    """cfg's vehicle with three wheels on its body axes (the array's reference)."""
    return replace(cfg, spacecraft=replace(cfg.spacecraft, wheel_axes_body=BODY_AXES, wheel_names=WHEEL_JOINTS,
                                           failed_wheels=()))


def _array_chunk(args):
    path, failed, states, first = args
    cfg = load(path)
    cfg = replace(cfg, spacecraft=replace(cfg.spacecraft, failed_wheels=tuple(failed)))
    ctrl = RunController()
    hard = [i for i, n in enumerate(cfg.constraint_names) if n not in cfg.slacked_constraints]
    filt, safety, out = None, None, []
    for k, x0 in enumerate(states):
        scen = ctrl.scenario(x0, first + k, DURATION_S)
        loop = ArrayLoop(cfg, scen, filt=filt, safety=safety)
        filt, safety = loop.filter, loop.safety
        run = loop.run()
        worst = run.h_substep_min[:, hard].min(axis=0)
        out.append({cfg.constraint_names[hard[i]]: float(worst[i]) for i in np.flatnonzero(worst < 0)})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--fail", default="", help="wheels failed from the start, comma-separated joint names")
    args = ap.parse_args()
    failed = [w.strip() for w in args.fail.split(",") if w.strip()]
    cfg = load(args.config)
    cfg = replace(cfg, spacecraft=replace(cfg.spacecraft, failed_wheels=tuple(failed)))
    ref = three_wheels(cfg)
    X, _ = sample_initial_states(args.runs, args.seed, ref)
    cols = list(wheel_columns(cfg.spacecraft.n_wheels))
    fits = np.array([np.abs(array_state(cfg, x)[cols]).max() <= cfg.psi_keep_rad_s for x in X])
    X = X[fits]
    before = machine.describe()
    t0 = time.perf_counter()
    chunks = np.array_split(np.arange(len(X)), args.workers * 4)
    with mp.get_context("fork").Pool(args.workers) as pool:
        parts = pool.map(_array_chunk, [(args.config, failed, X[c], int(c[0]) if len(c) else 0) for c in chunks])
    wall_array = time.perf_counter() - t0
    lost = [v for part in parts for v in part]
    index = np.flatnonzero(fits)  # each kept state's run number in the sampled campaign
    t0 = time.perf_counter()
    outcome = run_runs(ref, X, DURATION_S)
    wall_ref = time.perf_counter() - t0
    hard = [i for i, n in enumerate(ref.constraint_names) if n not in ref.slacked_constraints]
    ref_bad = outcome.violated_substeps[:, hard].any(axis=1)
    n = len(X)
    row = {"config": args.config, "seed": args.seed, "runs": args.runs, "kept_states": int(n),
           "left_out": int(args.runs - n), "failed_wheels": failed,
           "array_safe": int(sum(not v for v in lost)), "array_violated": {},
           "three_wheels_safe": int(n - ref_bad.sum()), "array_wall_s": round(wall_array, 1),
           "three_wheels_wall_s": round(wall_ref, 1), "workers": args.workers, "machine": before}
    for v in lost:
        for name in v:
            row["array_violated"][name] = row["array_violated"].get(name, 0) + 1
    row["array_failed_runs"] = {int(index[k]): v for k, v in enumerate(lost) if v}
    row["three_wheels_failed_runs"] = [int(index[k]) for k in np.flatnonzero(ref_bad)]
    print(f"{args.config} (failed: {', '.join(failed) or 'none'}), seed {args.seed}, {n} of {args.runs} states "
          f"({args.runs - n} left out: a wheel of the split past its limit)")
    print(f"  array:        {row['array_safe']} safe = {100 * row['array_safe'] / n:.2f} % "
          f"({row['array_wall_s']} s, {args.workers} workers); violated: {row['array_violated']}; failed runs (h): "
          f"{row['array_failed_runs']}")
    print(f"  three wheels: {row['three_wheels_safe']} safe = {100 * row['three_wheels_safe'] / n:.2f} % "
          f"({row['three_wheels_wall_s']} s, 1 process)")
    machine.append("array_montecarlo", row)


if __name__ == "__main__":
    main()
