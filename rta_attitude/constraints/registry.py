"""The registry: a configuration's constraints as one ordered table that every consumer reads.

Rows (`Config.constraint_names`): the pointing constraints, in the order the configuration lists them, then
temperature, battery, omega_x/y/z, a psi_ per wheel (the paper's psi_x/y/z). Per constraint: its name, group (a
section of `constraints:`, the name `filter.priorities` uses), kind, row, the unit of its h, whether it is enabled
and slacked, its priority level, and how its h reads in an engineer's units (`display`). The QP's rows, the safety
values, the gatekeeper's rollout margins, the Monte Carlo's columns and classification, filter_status and
/diagnostics keys, bag analysis, figures and the scene all take names and units from here; a new pointing constraint
is a configuration entry, and nothing else names it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import AXIS_NAMES, Config, group_of, wheel_constraint_name

KINDS: tuple[str, ...] = ("keep_out", "keep_in", "temperature", "battery", "rate", "wheel_speed")
"""What a constraint is: a pointing cone (keep_out, keep_in), the thermal node's temperature, the battery's
charge, a body rate, a wheel speed."""
H_UNIT = {"keep_out": "rad", "keep_in": "rad", "temperature": "K", "battery": "J", "rate": "rad^2/s^2",
          "wheel_speed": "rad^2/s^2"}
"""The unit of h of each kind (model units)."""


@dataclass(frozen=True)
class ConstraintInfo:
    """One row of the registry."""

    name: str
    group: str
    """The section of `constraints:` (omega_y -> omega): what `filter.priorities` names."""
    kind: str
    """KINDS."""
    row: int
    unit: str
    """The unit of h (model units)."""
    enabled: bool
    slack_weight: float
    """> 0: slacked (reported, not counted as a failure)."""
    level: int
    """Its priority level (`Config.priority_levels`, 0 most important)."""
    limit: float
    """The limit h is measured from, model units: a cone's half-angle (rad), T_max (K), E_min (J), omega_max
    (rad/s), psi_max (rad/s)."""
    windowed: bool = False
    """A pointing constraint that applies only within its time windows (h is +inf outside)."""

    @property
    def hard(self) -> bool:
        """Enabled and not slacked: a violation is a failure."""
        return self.enabled and not self.slack_weight > 0

    @property
    def pointing(self) -> bool:
        return self.kind in ("keep_out", "keep_in")

    @property
    def display_unit(self) -> str:
        """The unit `display` gives h in: deg for angles, degC-difference K, J, deg/s and rad/s for speeds."""
        return {"keep_out": "deg", "keep_in": "deg", "temperature": "K", "battery": "J", "rate": "deg/s",
                "wheel_speed": "rad/s"}[self.kind]

    def display(self, h: float | NDArray[np.float64]) -> float | NDArray[np.float64]:
        """h in `display_unit`: angles in deg; for a speed v (h = v_max^2 - v^2) the margin v_max - |v| =
        v_max - sqrt(v_max^2 - h) (negative past the limit), in deg/s (rates) or rad/s (wheels)."""
        h = np.asarray(h, dtype=float)
        if self.pointing:
            out = np.degrees(h)
        elif self.kind in ("rate", "wheel_speed"):
            v = np.sqrt(np.maximum(self.limit**2 - h, 0.0))
            out = self.limit - v
            if self.kind == "rate":
                out = np.degrees(out)
        else:
            out = h
        return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class Registry:
    """A configuration's constraints, in row order."""

    constraints: tuple[ConstraintInfo, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.constraints)

    def __len__(self) -> int:
        return len(self.constraints)

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.constraints)

    def __getitem__(self, name: str) -> ConstraintInfo:
        for c in self.constraints:
            if c.name == name:
                return c
        raise KeyError(f"unknown constraint {name!r}; known: {', '.join(self.names)}")

    def index(self, name: str) -> int:
        return self[name].row

    @property
    def units(self) -> dict[str, str]:
        """{name: unit of h}."""
        return {c.name: c.unit for c in self.constraints}

    @property
    def hard(self) -> NDArray[np.bool_]:
        """(m,) enabled and not slacked: the constraints whose violation fails a run."""
        return np.array([c.hard for c in self.constraints], dtype=bool)

    @property
    def slacked(self) -> tuple[str, ...]:
        """Names of the enabled constraints that carry a slack."""
        return tuple(c.name for c in self.constraints if c.enabled and c.slack_weight > 0)

    @property
    def pointing(self) -> tuple[ConstraintInfo, ...]:
        return tuple(c for c in self.constraints if c.pointing)


def registry(cfg: Config) -> Registry:
    """The registry of a configuration (its constraints in row order)."""
    level_of = {g: k for k, level in enumerate(cfg.priority_levels) for g in level}
    L = cfg.limits
    out: list[ConstraintInfo] = []
    for cone in cfg.pointing:
        g = cone.gains
        out.append(ConstraintInfo(cone.name, cone.name, cone.kind, len(out), H_UNIT[cone.kind], g.enabled,
                                  g.slack_weight if g.enabled else 0.0, level_of[cone.name], cone.half_angle_rad,
                                  bool(cone.windows_s)))
    fixed = [("temperature", "temperature", L.temperature_max_K), ("battery", "battery", L.energy_min_J)]
    fixed += [(f"omega_{a}", "rate", L.omega_max_rad_s) for a in AXIS_NAMES]
    fixed += [(wheel_constraint_name(w), "wheel_speed", L.psi_max_rad_s) for w in cfg.spacecraft.wheel_names]
    for name, kind, limit in fixed:
        g = cfg.gains(name)
        group = group_of(name)
        out.append(ConstraintInfo(name, group, kind, len(out), H_UNIT[kind], g.enabled,
                                  g.slack_weight if g.enabled else 0.0, level_of[group], limit))
    return Registry(tuple(out))


def levels(cfg: Config) -> NDArray[np.int64]:
    """The priority level (n_rows,) of each constraint, in row order."""
    return np.array([c.level for c in registry(cfg)], dtype=np.int64)


def angle_names(cfg: Config) -> tuple[str, ...]:
    """The names of `ConstraintSet.angles`: each pointing constraint's (its boresight to its target), then the
    thermal face's sun and Earth incidence and the panel's sun incidence (`rows.BODY_ANGLE_NAMES`)."""
    from rta_attitude.constraints.rows import BODY_ANGLE_NAMES

    return (*(c.name for c in cfg.pointing), *BODY_ANGLE_NAMES)


__all__ = ["H_UNIT", "KINDS", "ConstraintInfo", "Registry", "angle_names", "levels", "registry"]
