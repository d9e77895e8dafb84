"""The Monte Carlo's results: the paper's table beside ours, the classification, the output files."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.state import STATE_NAMES
from rta_attitude.files import atomic, output_dir, write_text
from rta_attitude.filter.outcome import (
    GATE_BACKUP,
    GATE_FILTERED_BACKUP,
    GATE_NAMES,
    GATE_TOWARD_BACKUP,
    GATE_UNVERIFIED,
)
from rta_attitude.montecarlo.classify import UNRECOVERABLE_RULES
from rta_attitude.montecarlo.controllers import RunController, attitude_error_deg
from rta_attitude.montecarlo.runner import BatchOutcome

Array = NDArray[np.float64]

PAPER_RESULTS: dict[str, Any] = {
    "success_rate": 0.9832,
    "violations_per_failed_run": {"1": 0.4167, "2": 0.3452, "3": 0.2143, "4+": 0.0238},
    "by_constraint": {"sensor keep-out": 0.5119, "psi_y": 0.4762, "psi_z": 0.4048, "battery": 0.3810,
                      "psi_x": 0.0476, "temperature": 0.0238, "omega_x": 0.0, "omega_y": 0.0, "omega_z": 0.0},
}
"""McQuinn et al. 2024, sec. Monte-Carlo Analysis: shares of the failed runs. The paper's exclusion zone is
`PAPER_SENSOR_CONE` of a configuration, whatever its name there (`paper_names`)."""
PAPER_SENSOR_CONE = ("keep_out", (1.0, 0.0, 0.0), "sun", 40.0)
"""The paper's exclusion zone: (kind, boresight, target, half-angle in deg)."""
PAPER_ANTENNA_CONE = ("keep_in", (0.0, 1.0, 0.0), "earth", 90.0)
"""The paper's communication cone."""
PAPER_VEHICLE = {"inertia_kgm2": (0.022, 0.044, 0.056), "wheel_inertia_kgm2": 4.1e-5}
PAPER_DURATION_S = 2000.0


def paper_protocol(cfg: Config, duration_s: float, controller: str = "none") -> bool:
    """The campaign is the paper's: its vehicle, limits and orbit environment (SPEC sec. 3; the sun in the orbit
    plane), its sensor's keep-out cone, no primary controller over 2,000 s; only then is the paper's table
    printed beside ours."""
    from rta_attitude.config import load, package_config_path

    if controller != "none":
        return False
    ref = load(package_config_path())  # the package's limits and environment are the paper's
    sc = cfg.spacecraft
    return (tuple(sc.inertia_kgm2) == PAPER_VEHICLE["inertia_kgm2"]
            and sc.wheel_inertia_kgm2 == PAPER_VEHICLE["wheel_inertia_kgm2"] and cfg.limits == ref.limits
            and cfg.environment == ref.environment
            and duration_s == PAPER_DURATION_S and bool(paper_names(cfg)))


def paper_names(cfg: Config) -> dict[str, str]:
    """{the paper's row label: this configuration's constraint name} where the configuration has it."""
    out = {n: n for n in PAPER_RESULTS["by_constraint"] if n in cfg.constraint_names}
    for c in cfg.pointing:
        spec = (c.kind, c.boresight_body, c.target, round(math.degrees(c.half_angle_rad), 9))
        if spec == PAPER_SENSOR_CONE:
            out["sensor keep-out"] = c.name
        elif spec != PAPER_ANTENNA_CONE:
            return {}  # another cone: not the paper's constraints
    return out if "sensor keep-out" in out else {}

@dataclass
class MonteCarloResult:
    """Everything a Monte Carlo produced (arrays over runs)."""

    cfg: Config
    seed: int
    duration_s: float
    x0: Array
    redraws: NDArray[np.int64]
    outcome: BatchOutcome
    slacked: tuple[str, ...]
    wall_s: float
    backend: str
    workers: int
    cpu_s: float = math.nan
    """CPU time of this process and its finished worker processes during the runs (local backend), s."""
    unrecoverable: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    rules: list[str] = field(default_factory=list)
    controller: RunController = field(default_factory=RunController)
    """The runs' primary controller and their targets (`montecarlo.controllers`)."""

    @property
    def names(self) -> tuple[str, ...]:
        """The constraints, in the outcome's column order."""
        return self.cfg.constraint_names

    @property
    def counted(self) -> NDArray[np.bool_]:
        """(m,) constraints that decide success (enabled, not slacked)."""
        cs = ConstraintSet.from_config(self.cfg)
        return cs.enabled & (cs.slack_weights == 0)

    def failed(self, substeps: bool = False) -> NDArray[np.bool_]:
        """(N,) runs where a counted constraint has h < 0 at a sample (the paper's criterion), or with
        substeps also between samples."""
        v = self.outcome.violated_substeps if substeps else self.outcome.violated_samples
        return np.any(v & self.counted, axis=1)

    @property
    def run_length_s(self) -> float:
        """What each run simulated: duration_s in whole samples, s (the runner's length)."""
        dt = self.cfg.filter.sample_time_s
        return round(self.duration_s / dt) * dt

    def targets(self) -> tuple[Array, Array]:
        """(times (K,), targets (N, K, 4)) the runs were commanded to (zeros without a controller)."""
        ctrl = self.controller
        return ctrl.target_times(self.run_length_s), ctrl.targets(0, len(self.x0), self.run_length_s)

    def final_attitude_error_deg(self) -> Array:
        """(N,) angle from each run's final attitude to its target in force at the end, deg (NaN without a
        controller): whether the controller got where it was sent while the filter kept it safe."""
        if self.controller.kind == "none":
            return np.full(len(self.x0), np.nan)
        times, q = self.targets()
        last = int(np.searchsorted(times, self.run_length_s, side="right")) - 1
        return attitude_error_deg(self.outcome.x_final[:, :4], q[:, max(last, 0)])


def verdict(result: MonteCarloResult, min_safe_rate: float = 1.0) -> dict[str, Any]:
    """The campaign's verdict for the command's exit status: SAFE when the share of runs that keep every
    counted constraint at every sample and every RK4 substep (the stricter of the table's two columns, and
    `simulate`'s criterion for one run) is at least min_safe_rate (default 1: any failed run is UNSAFE)."""
    failed = result.failed(substeps=True)
    n = len(failed)
    safe_runs = n - int(failed.sum())
    rate = safe_runs / n if n else math.nan
    return {"safe": bool(n and rate >= min_safe_rate), "runs": n, "safe_runs": safe_runs, "safe_rate": rate,
            "min_safe_rate": min_safe_rate,
            "criterion": "every counted constraint kept at every sample and RK4 substep"}


def format_verdict(v: dict[str, Any]) -> str:
    """The verdict's line: SAFE or UNSAFE, the counts, the rate against the threshold."""
    rate, need = v["safe_rate"], v["min_safe_rate"]
    failed = v["runs"] - v["safe_runs"]
    if v["safe"]:
        if failed == 0:
            return f"SAFE: all {v['runs']} runs kept every counted constraint at every sample and substep"
        return (f"SAFE: {failed} of {v['runs']} runs violated a counted constraint (incl. substeps): safe rate "
                f"{rate:.2%} >= --min-safe-rate {need:.2%}")
    return (f"UNSAFE: {failed} of {v['runs']} runs violated a counted constraint (incl. substeps): safe rate "
            f"{rate:.2%} < --min-safe-rate {need:.2%}")


def _shares(result: MonteCarloResult, substeps: bool) -> dict[str, Any]:
    v = (result.outcome.violated_substeps if substeps else result.outcome.violated_samples) & result.counted
    failed = np.asarray(v.any(axis=1), dtype=bool)
    nf = int(failed.sum())
    n = len(failed)
    per_run = v[failed].sum(axis=1)
    counts = {"1": int(np.sum(per_run == 1)), "2": int(np.sum(per_run == 2)), "3": int(np.sum(per_run == 3)),
              "4+": int(np.sum(per_run >= 4))}
    by = {name: int(v[failed, i].sum()) for i, name in enumerate(result.names) if result.counted[i]}
    return {
        "runs": n, "failed": nf, "success_rate": (n - nf) / n if n else math.nan,
        "violations_per_failed_run": {k: (c / nf if nf else 0.0) for k, c in counts.items()},
        "violations_per_failed_run_counts": counts,
        "by_constraint": {k: (c / nf if nf else 0.0) for k, c in by.items()},
        "by_constraint_counts": by,
    }


def summary(result: MonteCarloResult, min_safe_rate: float = 1.0) -> dict[str, Any]:
    """The JSON-ready summary: paper-style tables at samples and incl. substeps, counts, timing, the
    primary controller (and how close the runs ended to their targets), the verdict (`verdict`)."""
    o = result.outcome
    failed = result.failed()
    cs = ConstraintSet.from_config(result.cfg)
    slacked = {}
    for i, name in enumerate(result.names):
        if name in result.slacked:
            slacked[name] = {"violated_runs_samples": int(o.violated_samples[:, i].sum()),
                             "violated_runs_incl_substeps": int(o.violated_substeps[:, i].sum()),
                             "max_slack_rad": float(o.max_comm_slack.max()) if len(o.max_comm_slack) else 0.0}
    unrec = result.unrecoverable & failed
    short = failed & ~result.unrecoverable
    steps = round(result.duration_s / result.cfg.filter.sample_time_s)
    paper = None
    if paper_protocol(result.cfg, result.duration_s, result.controller.name):
        names = paper_names(result.cfg)
        paper = {**PAPER_RESULTS, "by_constraint": {names[k]: v for k, v in PAPER_RESULTS["by_constraint"].items()}}
    ctrl = result.controller
    tracking = None
    if ctrl.kind != "none":
        err = result.final_attitude_error_deg()
        tracking = {**ctrl.as_dict(), "targets_per_run": len(ctrl.target_times(result.run_length_s)),
                    "final_attitude_error_deg": {
                        "median": float(np.median(err)), "p95": float(np.percentile(err, 95)),
                        "max": float(err.max())} if len(err) else None}
    return {
        "paper": paper,
        "verdict": verdict(result, min_safe_rate),
        "controller": tracking,
        "at_samples": _shares(result, False),
        "incl_substeps": _shares(result, True),
        "slacked_constraints": slacked,
        "classification": {
            "failed": int(failed.sum()),
            "physically_unrecoverable": int(unrec.sum()),
            "filter_shortfall": int(short.sum()),
            "shortfall_with_qp_failure": int((short & (o.fallback_steps > 0)).sum()),
            "shortfall_without_qp_failure": int((short & (o.fallback_steps == 0)).sum()),
            "worst_violation_without_qp_failure": {
                name: float(o.min_h_samples[short & (o.fallback_steps == 0), i].min())
                for i, name in enumerate(result.names)
                if result.counted[i] and np.any(o.violated_samples[short & (o.fallback_steps == 0), i])},
            "worst_violation_units": cs.registry.units,
            "by_rule": {r: int(sum(1 for k in np.flatnonzero(failed) if r in result.rules[k].split(";")))
                        for r in UNRECOVERABLE_RULES},
        },
        "filter": {
            "qp_state_steps": int(o.qp_steps.sum()),
            "qp_share": float(o.qp_steps.sum() / (len(failed) * steps)) if len(failed) else 0.0,
            "fallback_state_steps": int(o.fallback_steps.sum()),
            "runs_with_fallback": int((o.fallback_steps > 0).sum()),
            "qp_failures": int(o.qp_failures.sum()),
            "runs_with_qp_failure": int((o.qp_failures > 0).sum()),
            "fallback_policy": result.cfg.filter.fallback,
            "solver": result.cfg.filter.solver,
            "backup_law": result.cfg.filter.backup_law,
            "backup_horizon_s": result.cfg.filter.backup_horizon_s,
            "gate_state_steps": {name: int(o.gate_steps[:, i].sum()) for i, name in enumerate(GATE_NAMES)},
            "runs_with_backup": int((o.gate_steps[:, GATE_BACKUP] > 0).sum()),
            "runs_with_filtered_backup": int((o.gate_steps[:, GATE_FILTERED_BACKUP] > 0).sum()),
            # runs with a step no plan verified (the answer, or the answer to a backup command, applied)
            "runs_with_unverified": int((o.gate_steps[:, [GATE_UNVERIFIED, GATE_TOWARD_BACKUP]] > 0).any(axis=1).sum()),
        },
        "setup": {
            "runs": len(failed), "duration_s": result.duration_s, "seed": result.seed,
            "preset": result.cfg.filter.preset, "plant_model": result.cfg.spacecraft.model,
            "filter_model": result.cfg.filter.model, "dt_s": result.cfg.filter.sample_time_s,
            "substeps": result.cfg.substeps, "config": result.cfg.source, "backend": result.backend,
            "simulator": result.cfg.plant.simulator, "controller": ctrl.as_dict(),
            "sensors": f"on (seed {result.cfg.sensors.seed})" if result.cfg.sensors.enabled else "off",
            "workers": result.workers, "wall_s": result.wall_s,
            "cpu_s": None if math.isnan(result.cpu_s) else result.cpu_s,
            "redraws_total": int(result.redraws.sum()),
            "constraints_counted": [n for i, n in enumerate(cs.names) if result.counted[i]],
            "slacked": list(result.slacked),
        },
    }


def format_table(s: dict[str, Any]) -> str:
    """The paper's table beside ours (shares of failed runs), for a terminal."""
    a, b, p = s["at_samples"], s["incl_substeps"], s["paper"]
    setup = s["setup"]
    cpu = f", {setup['cpu_s']:.0f} s CPU" if setup.get("cpu_s") is not None else ""
    models = f"plant {setup['plant_model']}, filter model {setup['filter_model']}, " if "plant_model" in setup else ""
    lines = [f"Monte Carlo: {setup['runs']} runs x {setup['duration_s']:.0f} s, preset {setup['preset']}, "
             f"{models}seed {setup['seed']}, {setup['wall_s']:.1f} s wall{cpu} "
             f"({setup['backend']}, {setup['workers']} workers; simulator {setup.get('simulator', 'compiled')}; "
             f"sensor errors {setup.get('sensors', 'off')})"]
    tracking = s.get("controller")
    if tracking:
        where = (f"a new random target every {tracking['retarget_s']:g} s" if tracking["retarget_s"] is not None
                 else "one random target per run")
        err = tracking["final_attitude_error_deg"]
        ends = (f"; final attitude error to the target: median {err['median']:.3g} deg, 95 % {err['p95']:.3g} deg, "
                f"max {err['max']:.3g} deg" if err else "")
        lines.append(f"primary controller {tracking['name']}, {where}{ends}")
    lines.append(f"{'':<28}{'paper' if p else '':>10}{'at samples':>14}{'incl. substeps':>16}")

    def ref(value: float | None, spec: str) -> str:  # the paper's column: only for the paper's protocol
        return f"{value:>10{spec}}" if (p and value is not None) else f"{'-' if p else '':>10}"

    lines += [f"{'success rate':<28}{ref(p and p['success_rate'], '.2%')}{a['success_rate']:>14.2%}"
              f"{b['success_rate']:>16.2%}",
              f"{'failed runs':<28}{ref(84 if p else None, 'd')}{a['failed']:>14d}{b['failed']:>16d}",
              "of the failed runs, violating"]
    for k in ("1", "2", "3", "4+"):
        lines.append(f"  {k + ' constraint(s)':<26}{ref(p and p['violations_per_failed_run'][k], '.2%')}"
                     f"{a['violations_per_failed_run'][k]:>14.2%}{b['violations_per_failed_run'][k]:>16.2%}")
    lines.append("of the failed runs, violating")
    for name in a["by_constraint"]:
        lines.append(f"  {name:<26}{ref(p and p['by_constraint'].get(name), '.2%')}{a['by_constraint'][name]:>14.2%}"
                     f"{b['by_constraint'][name]:>16.2%}")
    for name, c in s["slacked_constraints"].items():
        lines.append(f"{name + ' (slacked)':<28}{'-':>10}{c['violated_runs_samples']:>14d}"
                     f"{c['violated_runs_incl_substeps']:>16d}  runs, max slack {c['max_slack_rad']:.3g} rad")
    c, f = s["classification"], s["filter"]
    lines.append(f"failed runs (at samples): {c['failed']} = {c['physically_unrecoverable']} physically unrecoverable "
                 f"+ {c['filter_shortfall']} filter shortfall  (rules: "
                 + ", ".join(f"{k} {v}" for k, v in c["by_rule"].items()) + ")")
    worst = ", ".join(f"{k} {v:.3g} {c['worst_violation_units'][k]}"
                      for k, v in c["worst_violation_without_qp_failure"].items())
    lines.append(f"  shortfalls: {c['shortfall_with_qp_failure']} with an infeasible QP (fallback), "
                 f"{c['shortfall_without_qp_failure']} with every QP feasible (sampled data; worst h: {worst or '-'})")
    lines.append(f"filter: QP in {f['qp_share']:.1%} of state-steps, {f['qp_failures']} QP failures in "
                 f"{f['runs_with_qp_failure']} runs, {f['fallback_state_steps']} fallback steps "
                 f"({f['fallback_policy']}) in {f['runs_with_fallback']} runs; solver {f['solver']}")
    if f["backup_law"] != "none":
        g = f["gate_state_steps"]
        lines.append(f"gatekeeper ({f['backup_law']}, {f['backup_horizon_s']:g} s): {g['verified']} verified, "
                     f"{g['backup']} backup steps in {f['runs_with_backup']} runs, {g['filtered_backup']} through the "
                     f"filter in {f['runs_with_filtered_backup']} runs, {g['unverified']} unverified and "
                     f"{g['toward_backup']} toward the backup law in {f['runs_with_unverified']} runs")
    if "verdict" in s:
        lines.append(format_verdict(s["verdict"]))
    return "\n".join(lines)


def write_outputs(result: MonteCarloResult, out: Path, plot: bool = True, min_safe_rate: float = 1.0
                  ) -> dict[str, Path]:
    """summary.json, runs.csv, outcome.npz and (optionally) initial_conditions.png in out. outcome.npz names
    the primary controller (`controller`) and, with one, holds the targets (target_times_s, targets_q);
    runs.csv then has each run's final attitude error. Returns the paths."""
    output_dir(out)
    s = summary(result, min_safe_rate)
    paths = {"json": out / "summary.json", "csv": out / "runs.csv", "npz": out / "outcome.npz"}
    write_text(paths["json"], json.dumps(s, indent=2) + "\n")
    o = result.outcome
    controlled = result.controller.kind != "none"
    extra: dict[str, Any] = {"controller": np.array(result.controller.name)}
    if controlled:
        extra["target_times_s"], extra["targets_q"] = result.targets()
    error_deg = result.final_attitude_error_deg()
    with atomic(paths["npz"]) as tmp:
        np.savez_compressed(tmp, x0=result.x0, redraws=result.redraws, unrecoverable=result.unrecoverable, **extra,
                            constraint_names=np.array(result.names), state_names=np.array(STATE_NAMES),
                            **{k: getattr(o, k) for k in ("violated_samples", "violated_substeps",
                                                          "first_violation_s", "min_h_samples", "qp_steps",
                                                          "fallback_steps", "qp_failures", "max_comm_slack",
                                                          "gate_steps", "x_final")})
    failed = result.failed()
    failed_sub = result.failed(substeps=True)
    with atomic(paths["csv"]) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", *STATE_NAMES[:13], "redraws", "failed", "failed_incl_substeps", "unrecoverable",
                    "unrecoverable_rules", "violated", "violated_incl_substeps", "first_violation_s", "qp_steps",
                    "fallback_steps", "qp_failures", "max_comm_slack_rad",
                    *[f"min_h_{n}" for n in result.names],
                    *(["final_attitude_error_deg"] if controlled else [])])
        for k in range(len(failed)):
            vs = [n for i, n in enumerate(result.names) if o.violated_samples[k, i]]
            vb = [n for i, n in enumerate(result.names) if o.violated_substeps[k, i]]
            fv = o.first_violation_s[k][result.counted]
            first = float(np.nanmin(fv)) if np.any(~np.isnan(fv)) else ""
            rules = result.rules[k] if failed[k] else ""
            w.writerow([k, *[repr(float(v)) for v in result.x0[k, :13]], int(result.redraws[k]), int(failed[k]),
                        int(failed_sub[k]), int(result.unrecoverable[k] and failed[k]), rules,
                        ";".join(vs), ";".join(vb), first, int(o.qp_steps[k]), int(o.fallback_steps[k]),
                        int(o.qp_failures[k]), repr(float(o.max_comm_slack[k])),
                        *[repr(float(v)) for v in o.min_h_samples[k]],
                        *([repr(float(error_deg[k]))] if controlled else [])])
    if plot:
        from rta_attitude.montecarlo.plots import plot_initial_conditions

        paths["png"] = plot_initial_conditions(result.x0, failed, result.cfg, out / "initial_conditions.png",
                                               title=f"{len(failed)} runs, preset {result.cfg.filter.preset}")
    return paths



__all__ = ["PAPER_RESULTS", "MonteCarloResult", "format_table", "format_verdict", "summary", "verdict",
           "write_outputs"]
