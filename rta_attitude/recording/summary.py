"""A bag run's summary (the keys and values of `simulate`'s, plus a `bag` section), its printed lines,
and the comparison of two runs (`rta-attitude analyze --compare`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rta_attitude import topics
from rta_attitude.config.schema import Config
from rta_attitude.constraints.registry import registry
from rta_attitude.dynamics.state import STATE_NAMES
from rta_attitude.files import atomic
from rta_attitude.recording.analysis import RESIDUAL_TOLERANCE, BagRun
from rta_attitude.simulation.metrics import summarize


def summarize_run(run: BagRun, cfg: Config) -> dict[str, Any]:
    """`metrics.summarize` of a bag run: the keys and values of `simulate`'s summary, plus `bag`.

    `bag` holds the file, topics and counts, truncation (`truncated`, `data_ends_s`), the
    re-integration residual and how the minima between samples were obtained, what the filter made of the
    controller's commands (`commands`) and what qualifies the verdict (`verdict`: `verdict_qualifiers`).
    """
    meta = {"scenario": run.scenario, "rta": run.rta, "preset": run.preset if run.rta else None,
            "config": cfg.source, "dt_s": run.dt_s, "substeps": cfg.substeps}
    constraints = registry(cfg)
    if constraints.names != run.names:
        raise ValueError(f"the run's constraints {run.names} are not the configuration's {constraints.names}")
    out = summarize(
        constraints, run.t_s, run.h, run.h_substep_min, run.h_substep_argmin_s, run.omega_dot,
        cfg.limits.omega_dot_max_rad_s2, run.slack if run.rta else None, run.intervening if run.rta else None,
        run.box_active if run.rta else None, run.status if run.rta else None, run.fallback if run.rta else None,
        run.solve_time_s if run.rta else None, run.slacked, meta,
    )  # fmt: skip
    exact = run.reintegration_residual <= RESIDUAL_TOLERANCE
    out["bag"] = {
        "path": str(run.path),
        "namespace": run.namespace,
        "topics": run.topic_types,
        "messages": {t: run.counts.get(t, 0) for t in run.topic_types},
        "truncated": run.truncated,
        "data_ends_s": run.data_end_s,
        "reintegration_residual": run.reintegration_residual,
        "substep_minima": ("recomputed exactly: each recorded step re-integrated from its recorded state and "
                           "command reproduces the next recorded state" if exact else
                           "estimated: re-integration does not reproduce the recorded states"),
        "run": dict(run.run_facts),
        "notes": list(run.notes),
        "commands": command_facts(run),
    }
    out["bag"]["verdict"] = verdict_qualifiers(out["bag"], run.steps)
    return out


def command_facts(run: BagRun) -> dict[str, Any]:
    """What the filter made of the controller's commands, from the bag: `received` (torque_des messages
    recorded), `rejected` (topics.REJECTED_COMMANDS: wrong frame, not finite, invalid stamp, stale), `reason`
    (the latest rejection's, e.g. "frame 'base_link'"), `missing` (states answered without a command: u_des
    = 0) and `answered` (the filter's calls); counts from the last filter_status (0 without one)."""
    counts = run.input_counts
    rejected = sum(counts.get(k, 0) for k in topics.REJECTED_COMMANDS)
    received = run.counts.get(f"{run.namespace.rstrip('/')}/{topics.TORQUE_DES}", 0)
    return {"received": max(received, rejected), "rejected": rejected, "reason": run.rejection,
            "missing": counts.get("torque_des_missing", 0), "answered": counts.get("calls", 0)}


def verdict_qualifiers(bag: Mapping[str, Any], steps: int) -> dict[str, Any]:
    """What qualifies the SAFE/UNSAFE verdict of a bag (`metrics.format_summary` prints it in the verdict line):
    `data_ends_s` (a truncated bag: judged only up to there; None otherwise) and `caveats`, one phrase each for
    commands the filter rejected, states answered without a command and deadline misses of the plant: a run
    that flew u_des = 0 instead of the controller's commands is safe, but not the run that was meant."""
    c = bag["commands"]
    caveats = []
    if c["rejected"]:
        caveats.append(f"{c['rejected']:,} of {c['received']:,} commands were rejected"
                       + (f" ({c['reason']})" if c["reason"] else ""))
    if c["missing"]:
        caveats.append(f"{c['missing']:,} of {max(c['answered'], c['missing']):,} states were answered without a "
                       "command (u_des = 0)")
    misses = bag["run"].get("deadline_misses")
    if isinstance(misses, int) and not isinstance(misses, bool) and misses > 0:
        caveats.append(f"{misses:,} of {max(steps, misses):,} steps missed their command deadline (the plant's "
                       "fallback was applied)")
    return {"data_ends_s": bag["data_ends_s"] if bag["truncated"] else None, "caveats": caveats}


def format_bag_lines(summary: Mapping[str, Any]) -> str:
    """The bag-specific lines printed under the `simulate`-style table."""
    b = summary["bag"]
    lines = [f"bag {b['path']} ({b['namespace']}): {summary['steps']} steps, "
             f"re-integration residual {b['reintegration_residual']:.2g}"]
    if b["truncated"]:
        lines.append(f"bag truncated: data ends at t = {b['data_ends_s']:.1f} s (the file has no MCAP footer; "
                     "the writer was killed)")
    lines += [f"note: {n}" for n in b["notes"]]
    return "\n".join(lines)


def _fmt(v: Any, spec: str = ".5g") -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return format(v, spec)
    return str(v)


def compare_summaries(a: Mapping[str, Any], b: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Rows (quantity, a, b, difference) comparing two run summaries, for the table and JSON."""
    rows: list[dict[str, Any]] = []

    def row(name: str, va: Any, vb: Any) -> None:
        diff = vb - va if isinstance(va, (int, float)) and isinstance(vb, (int, float)) \
            and not isinstance(va, bool) and not isinstance(vb, bool) else None
        rows.append({"quantity": name, "a": va, "b": vb, "b_minus_a": diff})

    for name, ca in a["constraints"].items():
        cb = b["constraints"].get(name)
        if cb is None:
            continue
        row(f"{name} min h [{ca['unit']}]", ca["min_h"], cb["min_h"])
        row(f"{name} first violation [s]", ca["first_violation_s"], cb["first_violation_s"])
    for name, acc in a.get("angular_acceleration", {}).items():
        other = b.get("angular_acceleration", {}).get(name)
        if other is not None:
            row(f"{name} max |.| [deg/s^2]", acc["max_abs_deg_s2"], other["max_abs_deg_s2"])
    for key in ("intervening_steps", "fallbacks"):
        row(key, a.get(key), b.get(key))
    row("violated", ", ".join(a["violated"]) or "none", ", ".join(b["violated"]) or "none")
    row("safe", a["safe"], b["safe"])
    return rows


def format_comparison(rows: Sequence[Mapping[str, Any]], label_a: str, label_b: str) -> str:
    """Fixed-width table of `compare_summaries` rows (columns as wide as their longest entry)."""
    cells = [("quantity", "A: " + label_a, "B: " + label_b, "B - A")]
    cells += [(str(r["quantity"]), _fmt(r["a"]), _fmt(r["b"]), _fmt(r["b_minus_a"], ".4g")) for r in rows]
    w = [max(len(c[i]) for c in cells) for i in range(4)]
    return "\n".join(f"{q:<{w[0]}}  {a:>{w[1]}}  {b:>{w[2]}}  {d:>{w[3]}}" for q, a, b, d in cells)


def label(summary: Mapping[str, Any]) -> str:
    return f"RTA on ({summary.get('preset')})" if summary.get("rta") else "RTA off"


def write_timeseries(run: BagRun, path: Path) -> Path:
    """Save the rebuilt series as a compressed NPZ with named columns (as `simulate`'s timeseries.npz)."""
    with atomic(path) as tmp:
        np.savez_compressed(
            tmp, t_s=run.t_s, x=run.x, state_names=np.array(STATE_NAMES), u_des=run.u_des, u=run.u,
            omega_dot=run.omega_dot, constraint_names=np.array(run.names), h=run.h, h_substep_min=run.h_substep_min,
            slack=run.slack, intervening=run.intervening, box_active=run.box_active, status=run.status,
            fallback=run.fallback, solve_time_s=run.solve_time_s,
        )  # fmt: skip
    return path


__all__ = ["command_facts", "compare_summaries", "format_bag_lines", "format_comparison", "label", "summarize_run",
           "verdict_qualifiers", "write_timeseries"]
