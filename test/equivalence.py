"""Records of what the default and paper configurations compute, to check a refactor against bit for bit.

`python test/equivalence.py record OUT.json LABEL` writes sha256 digests of

- filter answers: `AsifFilter.filter` of FILTER_STATES sampled states with random desired commands, one call
  each after a reset, under the default configuration (gyrostat, gatekeeper), the default without the
  gatekeeper, the paper's model and preset, and the default with sensor errors;
- `simulate` trajectories: the default scenarios under the default configuration, and the paper example's PD
  slew with the default filter (the scenario's paper model and no-gatekeeper overrides dropped);
- Monte Carlo runs: per run, the outcome of the first MC_RUNS states of seed 7 (2,000 s), default and paper
  configurations.

Only the paper's constraints are read, by name (PAPER_NAMES), so the records stay comparable when the result
arrays change shape. `python test/equivalence.py runs OUT.csv OUTCOME.npz` turns a campaign's outcome.npz into
per-run digests (test/data/equivalence_runs_*.csv: the 1,000-run campaigns of seed 7; `check-runs RECORDED.csv
OUTCOME.npz` names the runs that differ).
test/test_equivalence.py checks the records against test/data/equivalence.json.
"""

from __future__ import annotations

import csv
import hashlib
import json
import sys
from dataclasses import replace
from typing import Any

import numpy as np

PAPER_NAMES = ("exclusion_zone", "communication", "temperature", "battery",
               "omega_x", "omega_y", "omega_z", "psi_x", "psi_y", "psi_z")  # fmt: skip
"""The paper's constraints, in the order the records hold them."""
FILTER_STATES = 60
MC_RUNS = 4
MC_SEED = 7
MC_DURATION_S = 2000.0
RESULT_FIELDS = ("u", "u_held", "h", "psi0", "psi1", "bc", "slack")


def sha(*arrays: Any) -> str:
    """sha256 of the float64 bytes of arrays, in order."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def _columns(names: tuple[str, ...], values: np.ndarray) -> np.ndarray:
    """The PAPER_NAMES columns of values (..., m) whose last axis follows names."""
    idx = [list(names).index(n) for n in PAPER_NAMES]
    return np.asarray(values)[..., idx]


def configurations() -> dict[str, Any]:
    from rta_attitude import config

    cfg = config.load()
    return {
        "default": cfg,
        "no_gate": cfg.with_backup("none"),
        "paper": cfg.with_models("paper", "paper").with_backup("none").with_preset("paper"),
        "noisy": cfg.with_noise(True),
    }


def filter_records(cfgs: dict[str, Any]) -> dict[str, str]:
    from rta_attitude.filter.asif import AsifFilter
    from rta_attitude.montecarlo.sampling import sample_initial_states

    out: dict[str, str] = {}
    x0, _ = sample_initial_states(FILTER_STATES, 3, cfgs["default"])
    rng = np.random.default_rng(11)
    u_des = rng.uniform(-60.0, 60.0, size=(FILTER_STATES, 3))
    for label, cfg in cfgs.items():
        filt = AsifFilter(cfg)
        rows = []
        for x, u in zip(x0, u_des):
            filt.reset()
            r = filt.filter(x, u)
            names = tuple(r.names)
            rows.append([*np.ravel(r.u), *np.ravel(r.u_held),
                         *[np.ravel(_columns(names, getattr(r, f))) for f in RESULT_FIELDS[2:]],
                         float(r.status_code), float(r.record["gate"])])
        out[f"filter/{label}"] = sha(*[np.hstack([np.ravel(v) for v in row]) for row in rows])
    return out


def simulate_records(cfgs: dict[str, Any]) -> dict[str, str]:
    from rta_attitude.simulation.closed_loop import simulate

    out: dict[str, str] = {}
    cfg = cfgs["default"]
    for label in ("default", "noisy"):
        tr = simulate(cfgs[label], "battery-vs-temperature")
        out[f"simulate/{label}/battery_vs_temperature"] = sha(tr.x, tr.u_des, tr.u,
                                                              _columns(tuple(tr.names), tr.h_substep_min))
    slew = replace(cfg.scenario("paper-example"), model=None, backup_law=None)
    tr = simulate(cfg, slew)
    out["simulate/default/paper_example_slew"] = sha(tr.x, tr.u_des, tr.u, _columns(tuple(tr.names), tr.h_substep_min))
    return out


def run_digests(names: tuple[str, ...], o: Any) -> list[dict[str, str]]:
    """One row per run: failed flags, violated constraints and a digest of the rest of its outcome."""
    rows = []
    for k in range(o.x_final.shape[0]):
        vs = _columns(names, o.violated_samples[k])
        vb = _columns(names, o.violated_substeps[k])
        rows.append({
            "run": str(k),
            "failed": str(int(vs.any())),
            "violated": " ".join(n for n, v in zip(PAPER_NAMES, vb) if v),
            "digest": sha(o.x_final[k], _columns(names, o.min_h_samples[k]), _columns(names, o.first_violation_s[k]),
                          o.gate_steps[k], [o.qp_steps[k], o.fallback_steps[k], o.qp_failures[k]],
                          [o.max_comm_slack[k]])[:16],
        })
    return rows


def montecarlo_records(cfgs: dict[str, Any]) -> dict[str, Any]:
    from rta_attitude.constraints import ConstraintSet
    from rta_attitude.montecarlo.runner import run_runs
    from rta_attitude.montecarlo.sampling import sample_initial_states

    out: dict[str, Any] = {}
    for label in ("default", "paper"):
        cfg = cfgs[label]
        x0, _ = sample_initial_states(5000, MC_SEED, cfg)
        o = run_runs(cfg, x0[:MC_RUNS], MC_DURATION_S)
        out[f"montecarlo/{label}"] = run_digests(tuple(ConstraintSet(cfg).names), o)
    return out


def record() -> dict[str, Any]:
    cfgs = configurations()
    return {**filter_records(cfgs), **simulate_records(cfgs), **montecarlo_records(cfgs)}


def runs_csv(path: str, outcome_npz: str, names: tuple[str, ...] = PAPER_NAMES) -> None:
    """Per-run digests of a campaign's outcome.npz (`rta-attitude montecarlo --out`) into a CSV."""
    from rta_attitude.montecarlo.runner import BatchOutcome

    z = np.load(outcome_npz)
    names = tuple(str(n) for n in z["constraint_names"]) if "constraint_names" in z else names
    o = BatchOutcome(z["violated_samples"], z["violated_substeps"], z["first_violation_s"], z["min_h_samples"],
                     z["qp_steps"], z["fallback_steps"], z["qp_failures"], z["max_comm_slack"], z["gate_steps"],
                     z["x_final"])
    rows = run_digests(names, o)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    if sys.argv[1] == "record":
        result = {"commit": sys.argv[3], "records": record()}
        with open(sys.argv[2], "w") as fh:
            json.dump(result, fh, indent=1, sort_keys=True)
            fh.write("\n")
    elif sys.argv[1] == "runs":
        runs_csv(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == "check-runs":  # check-runs RECORDED.csv OUTCOME.npz: the runs that differ
        import tempfile

        with tempfile.NamedTemporaryFile("r", suffix=".csv") as tmp:
            runs_csv(tmp.name, sys.argv[3])
            new = list(csv.DictReader(open(tmp.name)))
        old = list(csv.DictReader(open(sys.argv[2])))
        differ = [a["run"] for a, b in zip(old, new) if a != b]
        print(f"{len(new)} runs of {len(old)} compared: {len(differ)} differ {' '.join(differ[:20])}")
        raise SystemExit(1 if differ or len(old) != len(new) else 0)
    else:
        raise SystemExit(f"unknown command {sys.argv[1]!r}: record | runs | check-runs")
