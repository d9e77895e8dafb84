"""Fingerprint of the paper configuration (the paper's model in plant and filter): sha256 of the
trajectory and command arrays of `simulate` of the paper's scenarios and of Monte Carlo runs.

`python test/paper_fingerprint.py OUT.json LABEL` writes them; test/data/paper_fingerprint.json was written
at b39a96d + the message interface (test_paper_fingerprint's docstring says why again), and
test_paper_fingerprint checks that the paper configuration still gives those bytes.
"""

from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

from rta_attitude.config.schema import Config

MC_RUNS = 6
"""Monte Carlo runs fingerprinted per seed (the first of the nominal 5,000-run draw)."""
MC_SEEDS = (1, 7)
MC_DURATION_S = 2000.0


def sha(*arrays: np.ndarray) -> str:
    """sha256 of the float64 bytes of arrays, in order."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def fingerprint(cfg: Config) -> dict[str, str]:
    """{case: sha256} of the paper scenarios (both presets, RTA on and off) and of Monte Carlo runs."""
    from rta_attitude.montecarlo.runner import run_runs
    from rta_attitude.montecarlo.sampling import sample_initial_states
    from rta_attitude.simulation.closed_loop import simulate

    out: dict[str, str] = {}
    for scenario in ("paper-example", "passed-example"):
        for preset in ("robust", "paper"):
            for rta in (True, False):
                if not rta and preset == "paper":
                    continue
                tr = simulate(cfg, scenario, rta=rta, preset=preset)
                out[f"{scenario}/{preset}/{'rta' if rta else 'no-rta'}"] = sha(tr.x, tr.u_des, tr.u, tr.h_substep_min)
    for seed in MC_SEEDS:
        for preset in ("robust", "paper"):
            # the nominal draw (5,000 states), its first runs
            x0, _ = sample_initial_states(5000, seed, cfg)
            res = run_runs(cfg.with_preset(preset), x0[:MC_RUNS], MC_DURATION_S, record=True)
            out[f"montecarlo/seed{seed}/{preset}"] = sha(res.trajectory, res.min_h_samples, res.x_final)
    return out


def paper_configuration() -> Config:
    """The paper's model in plant and filter and the paper's method (no backup): what is fingerprinted."""
    from rta_attitude import config

    return config.load().with_models("paper", "paper").with_backup("none")


if __name__ == "__main__":
    result = {"commit": sys.argv[2] if len(sys.argv) > 2 else "?", "fingerprint": fingerprint(paper_configuration())}
    with open(sys.argv[1], "w") as fh:
        json.dump(result, fh, indent=1, sort_keys=True)
        fh.write("\n")
