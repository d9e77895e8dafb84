"""Oracle (tests only): the first, numpy implementation of the safety constraints, one module each,
gathered into an ordered, named set.

| kind            | h (safe >= 0)                 | enforced through                          | module          |
|-----------------|-------------------------------|-------------------------------------------|-----------------|
| keep_out cone   | theta - alpha                 | HOCBF                                     | cone.py         |
| keep_in cone    | alpha - theta                 | HOCBF (+ slack where configured)          | cone.py         |
| temperature     | T_max - T                     | HOCBF on the angle-augmented Psi_temp     | temperature.py  |
| battery         | E - E_min                     | HOCBF on Psi_batt = h - delta2 theta_SI   | battery.py      |
| omega_x/y/z     | omega_max^2 - omega_i^2       | CBF (+ ZOH bound in the robust preset)    | angular_rate.py |
| psi_x/y/z       | psi_max^2 - psi_i^2           | CBF (+ ZOH bound in the robust preset)    | wheel_speed.py  |

Actuator and angular-acceleration limits are the box U of the filter (Config.u_max_rad_s2).

These modules are the definition (vectorised over state batches, checked against finite differences); the
filter evaluates its own compiled one-state code (rta_attitude/constraints), tested equal to these to
rounding at random states and at the poles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracles.constraints.angular_rate import AngularRate
from oracles.constraints.base import Array, BarrierValues, Constraint, Context
from oracles.constraints.battery import Battery
from oracles.constraints.cone import Cone
from oracles.constraints.temperature import Temperature
from oracles.constraints.wheel_speed import WheelSpeed
from rta_attitude.config.schema import Config


@dataclass(frozen=True)
class BarrierTable:
    """Every constraint evaluated on a state batch; the last axis m follows ConstraintSet.names.

    Attributes:
        h, psi0, psi1, drift: (..., m); gain: (..., m, 3). BC_i(u) = drift_i + gain_i . u.
    """

    h: Array
    psi0: Array
    psi1: Array
    drift: Array
    gain: Array


@dataclass(frozen=True)
class ConstraintSet:
    """The ordered, named safety constraints of one configuration."""

    constraints: tuple[Constraint, ...]
    cfg: Config

    @classmethod
    def from_config(cls, cfg: Config) -> ConstraintSet:
        """Every constraint of the configuration, in its row order (disabled ones included)."""
        items: list[Constraint] = [Cone.from_config(cfg, c) for c in cfg.pointing]
        items += [Temperature.from_config(cfg), Battery.from_config(cfg)]
        items += [AngularRate.from_config(cfg, i) for i in range(3)]
        items += [WheelSpeed.from_config(cfg, i) for i in range(3)]
        assert tuple(c.name for c in items) == cfg.constraint_names  # a programming error, not input
        return cls(tuple(items), cfg)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.constraints)

    @property
    def enabled(self) -> Array:
        """(m,) bool."""
        return np.array([c.gains.enabled for c in self.constraints])

    @property
    def slack_weights(self) -> Array:
        """(m,) slack weight p_i; 0 for hard constraints."""
        return np.array([c.gains.slack_weight for c in self.constraints], dtype=float)

    def context(self, x: Array, t_s: float | Array = 0.0) -> Context:
        return Context.from_state(x, self.cfg, t_s)

    def safety_values(self, x: Array, t_s: float | Array = 0.0) -> Array:
        """Physical h of every constraint (..., m) at times t_s; negative = violated."""
        ctx = self.context(x, t_s)
        return np.stack([c.safety_value(ctx) for c in self.constraints], axis=-1)

    def evaluate(self, x: Array, ctx: Context | None = None, t_s: float | Array = 0.0) -> BarrierTable:
        """h, Psi levels and the affine barrier conditions of every constraint at times t_s."""
        ctx = ctx if ctx is not None else self.context(x, t_s)
        vals: list[BarrierValues] = [c.evaluate(ctx) for c in self.constraints]
        return BarrierTable(
            h=np.stack([v.h for v in vals], axis=-1),
            psi0=np.stack([v.psi0 for v in vals], axis=-1),
            psi1=np.stack([v.psi1 for v in vals], axis=-1),
            drift=np.stack([v.drift for v in vals], axis=-1),
            gain=np.stack([v.gain for v in vals], axis=-2),
        )

    def zoh_bounds(self, ctx: Context, dt_s: float, margin: float) -> tuple[Array, Array]:
        """Intersection of the one-step-ahead rate and wheel-speed intervals on u (..., 3) each (with the
        gyrostat model the rate's are coupled rows, not intervals: left out here)."""
        lo = np.full((*ctx.batch_shape, 3), -np.inf)
        hi = np.full((*ctx.batch_shape, 3), np.inf)
        coupled = ctx.cfg.filter.model == "gyrostat"
        for c in self.constraints:
            if isinstance(c, AngularRate) and coupled:
                continue
            if isinstance(c, (AngularRate, WheelSpeed)) and c.gains.enabled:
                a, b = c.zoh_bounds(ctx, dt_s, margin)
                lo[..., c.axis] = np.maximum(lo[..., c.axis], a)
                hi[..., c.axis] = np.minimum(hi[..., c.axis], b)
        return lo, hi


__all__ = [
    "AngularRate", "BarrierTable", "BarrierValues", "Battery", "Cone", "Constraint",
    "ConstraintSet", "Context", "Temperature", "WheelSpeed",
]  # fmt: skip
