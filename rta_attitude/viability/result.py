"""The oracle's answer (`Result`), its JSON form and the verdict table."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

RECOVERABLE = "recoverable"
"""A witness was found and re-simulated exactly: every enforced h >= 0 at x0 and every substep."""
NO_WITNESS = "no witness found"
"""The search failed. Proves nothing."""
UNRECOVERABLE = "unrecoverable"
"""A rule (`Result.rule`) proves that no admissible command sequence keeps the enforced constraints."""
VERDICTS: tuple[str, ...] = (RECOVERABLE, NO_WITNESS, UNRECOVERABLE)


@dataclass
class Result:
    """The answer of `find_witness`.

    verdict: one of VERDICTS. rule: the proving rule (verdict unrecoverable) or None.
    u: (N, 3) witness commands in U, rad/s^2, or None. x: (N + 1, 13) samples of its exact
    re-simulation, or None. min_margins: the smallest h of every constraint group (the configuration's groups)
    over x0 and every substep (in `units`; of the best candidate when no witness was found; at x0 for a rule;
    +inf for a windowed cone that never applies within the horizon).
    method: rule | warm_start | direct | segmented. ipopt_status: IPOPT's status(es), or "not
    needed" / "not run". detail: a sentence. iterations: IPOPT iterations in all. segments: the
    receding-segment log. solve_time_s / cpu_time_s: wall and process CPU time of the call.
    """

    verdict: str
    rule: str | None
    u: Array | None
    x: Array | None
    min_margins: dict[str, float]
    solve_time_s: float
    ipopt_status: str
    method: str = ""
    detail: str = ""
    iterations: int = 0
    segments: list[dict[str, Any]] = field(default_factory=list)
    cpu_time_s: float = 0.0
    horizon_s: float = 0.0
    model: str = ""
    enforce: tuple[str, ...] = ()
    scales: dict[str, float] = field(default_factory=dict)
    """Scale of each group's h (the optimiser's margin unit); ranks margins across groups."""
    units: dict[str, str] = field(default_factory=dict)
    """Unit of each group's h in `min_margins` (`params.UNITS` by kind)."""
    start_s: float = 0.0
    """The time of x0, s from the run's t = 0 (windowed cones apply by it)."""

    def to_json(self, with_trajectory: bool = True) -> dict[str, Any]:
        """A JSON-ready dict (u and x as nested lists if with_trajectory)."""
        out: dict[str, Any] = {
            "verdict": self.verdict, "rule": self.rule, "method": self.method, "detail": self.detail,
            "ipopt_status": self.ipopt_status, "iterations": self.iterations, "horizon_s": self.horizon_s,
            "model": self.model, "enforce": list(self.enforce),
            "min_margins": {k: _finite(v) for k, v in self.min_margins.items()},
            "margin_units": dict(self.units), "solve_time_s": self.solve_time_s, "cpu_time_s": self.cpu_time_s,
            "segments": self.segments, "start_s": self.start_s,
        }
        if with_trajectory:
            out["u_rad_s2"] = None if self.u is None else self.u.tolist()
            out["x"] = None if self.x is None else self.x.tolist()
        return out


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def format_table(rows: list[tuple[str, Result]]) -> str:
    """The verdict table: one line per (label, result)."""
    head = (f"{'state':<10}{'verdict':<18}{'rule / method':<22}{'worst enforced h':<30}{'wall s':>8}{'CPU s':>8}"
            f"{'iters':>7}")
    lines = [head]
    for label, r in rows:
        enforced = [g for g in r.enforce if g in r.min_margins]
        worst = min(enforced, key=lambda g: r.min_margins[g] / r.scales.get(g, 1.0), default=None)
        w = f"{worst} {r.min_margins[worst]:.4g} {r.units.get(worst, '')}".rstrip() if worst else "-"
        how = r.rule or r.method
        lines.append(f"{label:<10}{r.verdict:<18}{how:<22}{w:<30}{r.solve_time_s:>8.1f}{r.cpu_time_s:>8.1f}"
                     f"{r.iterations:>7d}")
    return "\n".join(lines)


__all__ = ["NO_WITNESS", "RECOVERABLE", "UNRECOVERABLE", "VERDICTS", "Result", "format_table"]
