"""Violation detection and run summaries, shared by the CLI, the nodes' launcher, bag analysis,
Monte Carlo and the benchmarks."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.registry import Registry, registry
from rta_attitude.dynamics.state import AXES

Array = NDArray[np.float64]


def first_violation(t_s: Array, h: Array) -> float | None:
    """Earliest time (s) at which h < 0, or None. t_s, h: (N,)."""
    idx = np.flatnonzero(h < 0)
    return float(t_s[idx[0]]) if idx.size else None


def summarize(
    constraints: Registry,
    t_s: Array,
    h: Array,
    h_substep_min: Array | None = None,
    h_substep_argmin_s: Array | None = None,
    omega_dot: Array | None = None,
    omega_dot_max_rad_s2: float | None = None,
    slack: Array | None = None,
    intervening: Array | None = None,
    box_active: Array | None = None,
    status: NDArray[np.str_] | None = None,
    fallback: NDArray[np.str_] | None = None,
    solve_time_s: Array | None = None,
    slacked: tuple[str, ...] = (),
    meta: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A run's summary as a JSON-ready dict.

    Args:
        constraints: the run's constraints (`constraints.registry`): names (m,), units, how h reads in
            engineers' units (each constraint's `display`: deg, deg/s, K, J, rad/s).
        t_s: sample times (N + 1,), s.
        h: physical h at the samples (N + 1, m).
        h_substep_min, h_substep_argmin_s: minimum of h within each step and its time (N, m);
            when given, violations between samples count too.
        omega_dot: angular acceleration per step (N, 3), rad/s^2; with omega_dot_max_rad_s2.
        slack, intervening: (N, m); box_active: (N, 3); status, fallback: (N,); solve_time_s: (N,).
        slacked: names of the constraints that carry a slack (reported, not counted as failures).
        meta: extra fields copied into the summary.
    """
    names = constraints.names
    out: dict[str, Any] = dict(meta or {})
    out["steps"] = int(len(t_s) - 1)
    out["duration_s"] = float(t_s[-1] - t_s[0])
    cons: dict[str, Any] = {}
    for i, name in enumerate(names):
        info = constraints[name]
        hi = h[:, i]
        min_h, first = float(hi.min()), first_violation(t_s, hi)
        steps_violated = int(np.count_nonzero(hi < 0))
        if h_substep_min is not None and h_substep_argmin_s is not None:
            min_h = min(min_h, float(h_substep_min[:, i].min()))
            sub = first_violation(h_substep_argmin_s[:, i], h_substep_min[:, i])
            if sub is not None and (first is None or sub < first):
                first = sub
        active = math.isfinite(min_h)  # a windowed cone has h = +inf outside its windows
        cons[name] = {
            "min_h": min_h if active else None, "unit": info.unit,
            "min_margin": info.display(min_h) if active else None, "margin_unit": info.display_unit,
            "first_violation_s": first, "violated_samples": steps_violated, "slacked": name in slacked,
            "violated_initially": bool(hi[0] < 0), "active": active,
        }  # fmt: skip
    out["constraints"] = cons
    out["violated"] = sorted(n for n, c in cons.items() if c["first_violation_s"] is not None and not c["slacked"])
    out["safe"] = not out["violated"]
    if omega_dot is not None and omega_dot_max_rad_s2 is not None:
        acc = {}
        for a, axis in enumerate(AXES):
            over = np.abs(omega_dot[:, a]) > omega_dot_max_rad_s2 * (1 + 1e-9)
            acc[f"omega_dot_{axis}"] = {
                "max_abs_deg_s2": float(np.degrees(np.abs(omega_dot[:, a]).max())) if len(omega_dot) else 0.0,
                "limit_deg_s2": math.degrees(omega_dot_max_rad_s2),
                "first_exceed_s": float(t_s[np.flatnonzero(over)[0]]) if over.any() else None,
            }
        out["angular_acceleration"] = acc
    if intervening is not None:
        inter = intervening.any(axis=1)
        if box_active is not None:
            inter = inter | box_active.any(axis=1)
        out["intervening_steps"] = int(inter.sum())
        out["intervening_by_constraint"] = {n: int(intervening[:, i].sum()) for i, n in enumerate(names)}
    if slack is not None:
        out["slack_active_steps"] = int((np.abs(slack) > 1e-12).any(axis=1).sum())
        out["max_slack"] = {n: float(np.abs(slack[:, i]).max()) for i, n in enumerate(names) if n in slacked}
    if status is not None:
        vals, counts = np.unique(np.asarray(status, dtype=str), return_counts=True)
        out["status_counts"] = {str(v): int(c) for v, c in zip(vals, counts)}
        out["qp_solves"] = int(sum(c for v, c in zip(vals, counts) if v in ("solved", "fallback")))
    if fallback is not None:
        out["fallbacks"] = int(np.count_nonzero(np.asarray(fallback, dtype=str) != ""))
    if solve_time_s is not None and len(solve_time_s) and np.any(solve_time_s > 0):
        st = solve_time_s[solve_time_s > 0]
        out["filter_time_us"] = {"median": float(np.median(st) * 1e6), "p99": float(np.percentile(st, 99) * 1e6),
                                 "max": float(st.max() * 1e6)}
    return out


def summarize_trajectory(traj: Any, cfg: Config) -> dict[str, Any]:
    """`summarize` of a simulation.Trajectory run with the configuration cfg (the scenario's: its slack
    weights applied, `Config.for_scenario`)."""
    meta = {"scenario": traj.scenario, "rta": traj.rta, "preset": traj.preset if traj.rta else None}
    meta.update({k: v for k, v in traj.meta.items() if isinstance(v, (str, int, float, bool))})
    return summarize(
        registry(cfg), traj.t_s, traj.h, traj.h_substep_min, traj.h_substep_argmin_s, traj.omega_dot,
        cfg.limits.omega_dot_max_rad_s2, traj.slack if traj.rta else None, traj.intervening if traj.rta else None,
        traj.box_active if traj.rta else None, traj.status if traj.rta else None,
        traj.fallback if traj.rta else None, traj.solve_time_s if traj.rta else None, cfg.slacked_constraints, meta,
    )  # fmt: skip


def format_summary(summary: dict[str, Any]) -> str:
    """A fixed-width table of a summary, for terminals and logs."""
    rta = f"on ({summary.get('preset')})" if summary.get("rta") else "off"
    title = f"scenario {summary.get('scenario', '?')}  rta={rta}  duration {summary['duration_s']:.0f} s"
    if "simulator" in summary:
        title += f"  plant: {summary['simulator']}, filter model: {summary.get('filter_model', '?')}"
    lines = [title, f"{'constraint':<16}{'min h':>12} {'unit':<10}{'min margin':>12} {'unit':<6}"
                     f"{'first violation':>16}  note"]
    for name, c in summary["constraints"].items():
        fv = "-" if c["first_violation_s"] is None else f"{c['first_violation_s']:.1f} s"
        note = "slacked" if c["slacked"] else ("VIOLATED" if c["first_violation_s"] is not None else "ok")
        if c.get("violated_initially"):
            note += " (initial state outside the safe set)"
        if c["min_h"] is None:
            lines.append(f"{name:<16}{'-':>12} {c['unit']:<10}{'-':>12} {c['margin_unit']:<6}{fv:>16}  "
                         f"not active (outside its windows)")
            continue
        lines.append(f"{name:<16}{c['min_h']:>12.4g} {c['unit']:<10}{c['min_margin']:>12.4g} {c['margin_unit']:<6}"
                     f"{fv:>16}  {note}")
    for name, a in summary.get("angular_acceleration", {}).items():
        fv = "-" if a["first_exceed_s"] is None else f"{a['first_exceed_s']:.1f} s"
        lines.append(f"{name:<16}{a['max_abs_deg_s2']:>14.4g} {'deg/s^2 max':<10}{fv:>16}  limit {a['limit_deg_s2']:g}")
    extra = [f"{k}={summary[k]}" for k in ("intervening_steps", "slack_active_steps", "qp_solves", "fallbacks")
             if k in summary]
    if extra:
        lines.append("  ".join(extra))
    if "filter_time_us" in summary:
        ft = summary["filter_time_us"]
        lines.append(f"filter call: median {ft['median']:.0f} us, p99 {ft['p99']:.0f} us, max {ft['max']:.0f} us")
    # a bag's summary qualifies its verdict (recording.summary.verdict_qualifiers): where a truncated bag ends,
    # and the commands the run did not fly as the controller sent them
    qualifiers = summary.get("bag", {}).get("verdict", {})
    verdict = "SAFE" if summary["safe"] else "UNSAFE"
    if qualifiers.get("data_ends_s") is not None:
        t = f"{qualifiers['data_ends_s']:,.1f}".rstrip("0").rstrip(".")
        verdict += f" up to t = {t} s (bag truncated)" if summary["safe"] else f" (bag truncated at t = {t} s)"
    if qualifiers.get("caveats"):
        verdict += ", but " + "; ".join(qualifiers["caveats"])
    lines.append(f"{verdict}: no non-slacked constraint violated" if summary["safe"]
                 else f"{verdict}: {', '.join(summary['violated'])}")
    return "\n".join(lines)


__all__ = ["first_violation", "format_summary", "summarize", "summarize_trajectory"]
