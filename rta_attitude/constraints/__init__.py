"""The safety constraints of a configuration, gathered into an ordered, named set.

| kind            | h (safe >= 0)                 | enforced through                          | module         |
|-----------------|-------------------------------|-------------------------------------------|----------------|
| keep_out cone   | theta - alpha                 | HOCBF                                     | cones.py       |
| keep_in cone    | alpha - theta                 | HOCBF (+ slack where configured)          | cones.py       |
| temperature     | T_max - T                     | HOCBF on the angle-augmented Psi_temp     | temperature.py |
| battery         | E - E_min                     | HOCBF on Psi_batt = h - delta2 theta_SI   | battery.py     |
| omega_x/y/z     | omega_max^2 - omega_i^2       | CBF (+ ZOH bound in the robust preset)    | angular_rate.py |
| psi_x/y/z       | psi_max^2 - psi_i^2           | CBF (+ ZOH bound in the robust preset)    | wheel_speed.py |

The cones are the configuration's `constraints.pointing` entries (any number up to MAX_CONES, each a
boresight, a target, a half-angle, gains and optional time windows: `cones`, `windows`); the paper's exclusion
zone and communication are two of them. Actuator and angular-acceleration limits are the box U of the filter
(Config.u_max_rad_s2).

Each module holds the formula (docstring) and the compiled one-state code of its constraint: `h`
(the physical safety value) and `row` (h, the HOCBF levels and the affine barrier condition
BC = drift + gain . u). `geometry` computes what they share once per state; `rows` runs them in
order; `base` has the records their parameters travel in; `registry` names the rows for every consumer.
`ConstraintSet` is the Python face for batches of states (reports, sampling, tests): a compiled loop over
the same one-state code.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.base import (
    CONSTRAINT_DTYPE,
    MAX_ROWS,
    TABLE_DTYPE,
    constraint_record,
)
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.registry import Registry, angle_names, registry
from rta_attitude.constraints.rows import pointing_angles, rollout_safety_values, rows, safety_values
from rta_attitude.dynamics.spacecraft import plant_record
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.jit import JIT

Array = NDArray[np.float64]

ROW_FIELDS = ("h", "psi0", "psi1", "drift", "gain")
"""TABLE_DTYPE's per-row fields (the others are the box and the coupled rate rows)."""


def table_dtype(n: int) -> np.dtype:
    """TABLE_DTYPE with n rows (a configuration's n_rows instead of the MAX_ROWS capacity)."""
    return np.dtype([(name, dt.base, (n, *dt.shape[1:]) if name in ROW_FIELDS else dt.shape)
                     for name, (dt, _) in TABLE_DTYPE.fields.items()])  # type: ignore[union-attr]


@numba.njit(**JIT)
def rows_many(X: Array, t_s: Array, p: NDArray[np.void], c: NDArray[np.void], T: NDArray[np.void]) -> None:
    """`rows` of states X (N, 19) at times t_s (N,) into tables T (N,), with the box a drive in any state
    holds."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    hi0 = c[0].u_reach_rad_s2.copy()  # what a drive in any state holds (U without lag compensation)
    lo0 = -hi0
    for k in range(X.shape[0]):
        rows(X[k], t_s[k], p[0], c[0], ctx[0], T[k], lo0, hi0)


@numba.njit(**JIT)
def safety_many(X: Array, t_s: Array, p: NDArray[np.void], c: NDArray[np.void], rollout: bool, H: Array) -> None:
    """`safety_values` (with rollout, `rollout_safety_values`) of states X (N, 19) at times t_s (N,) into H (N,
    n_rows)."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    for k in range(X.shape[0]):
        if rollout:
            rollout_safety_values(X[k], t_s[k], p[0], c[0], ctx[0], H[k])
        else:
            safety_values(X[k], t_s[k], p[0], c[0], ctx[0], H[k])


@numba.njit(**JIT)
def angles_many(X: Array, p: NDArray[np.void], c: NDArray[np.void], out: Array) -> None:
    """`pointing_angles` of states X (N, 19) into out (N, n_cones + 3)."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    for k in range(X.shape[0]):
        pointing_angles(X[k], p[0], c[0], ctx[0], out[k])


class ConstraintSet:
    """The ordered, named safety constraints of one configuration (Python face of the compiled rows).

    Args:
        cfg: configuration (limits, gains, preset; `filter.model`, the plant model the barriers assume).
    """

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.plant = plant_record(cfg, cfg.filter.model)
        self.record = constraint_record(cfg)
        self.registry: Registry = registry(cfg)
        self.names: tuple[str, ...] = self.registry.names

    @classmethod
    def from_config(cls, cfg: Config) -> ConstraintSet:
        return cls(cfg)

    def __len__(self) -> int:
        return len(self.names)

    @property
    def enabled(self) -> NDArray[np.bool_]:
        """(m,) bool."""
        return self.record[0]["gains"]["enabled"][: len(self)].astype(bool)

    @property
    def slack_weights(self) -> Array:
        """(m,) slack weight p_i; 0 for hard constraints."""
        return self.record[0]["gains"]["slack_weight"][: len(self)].copy()

    @property
    def slacked(self) -> tuple[str, ...]:
        """Names of the enabled constraints that carry a slack."""
        return tuple(n for n, w in zip(self.names, self.slack_weights) if w > 0)

    def evaluate(self, x: Array, t_s: float | Array = 0.0) -> NDArray[np.void]:
        """Tables (`table_dtype(m)`) of states x (..., 19) (unit quaternions) at times t_s (s, broadcast to
        x's leading shape), shape (...), as a numpy record array: h, psi0, psi1, drift (..., m), gain (..., m, 3),
        lo, hi (..., 3) read as `table.h` or `table["h"]`."""
        X = _as_states(x)
        T = np.zeros(X.shape[0], TABLE_DTYPE)
        rows_many(X, _times(t_s, x), self.plant, self.record, T)
        out = np.zeros(X.shape[0], table_dtype(len(self)))
        for name in TABLE_DTYPE.names or ():
            out[name] = T[name][:, : len(self)] if name in ROW_FIELDS else T[name]
        return out.reshape(np.shape(x)[:-1]).view(np.recarray)

    def safety_values(self, x: Array, t_s: float | Array = 0.0) -> Array:
        """Physical h of every constraint (..., m) of states x (..., 19) at times t_s (s); negative = violated."""
        return self._values(x, t_s, False)

    def rollout_values(self, x: Array, t_s: float | Array = 0.0) -> Array:
        """What the gatekeeper's rollouts keep >= their margins (..., m), at states x (..., 19) and times t_s:
        `safety_values` for the hard constraints, +inf for the slacked ones, and ahead of a window (its ramp)
        the cone's barrier h + rho(t) (`constraints.cones.cone_h`)."""
        return self._values(x, t_s, True)

    def _values(self, x: Array, t_s: float | Array, rollout: bool) -> Array:
        X = _as_states(x)
        H = np.empty((X.shape[0], MAX_ROWS))
        safety_many(X, _times(t_s, x), self.plant, self.record, rollout, H)
        return H[:, : len(self)].reshape((*np.shape(x)[:-1], len(self)))

    @property
    def angle_names(self) -> tuple[str, ...]:
        """The names of `angles` (`registry.angle_names`)."""
        return angle_names(self.cfg)

    def angles(self, x: Array) -> dict[str, Array]:
        """The pointing angles of states x (..., 19) by `angle_names`, each (...), rad: each pointing
        constraint's boresight to its target, the thermal face's to the sun and the Earth, the panel's to the
        sun."""
        X = _as_states(x)
        names = self.angle_names
        out = np.empty((X.shape[0], len(names)))
        angles_many(X, self.plant, self.record, out)
        return {n: out[:, i].reshape(np.shape(x)[:-1]) for i, n in enumerate(names)}


def _times(t_s: float | Array, x: Array) -> Array:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(t_s, dtype=float), np.shape(x)[:-1]).reshape(-1))


def _as_states(x: Array) -> Array:
    x = np.asarray(x, dtype=float)
    if x.shape[-1:] != (STATE_SIZE,):
        raise ValueError(f"states must be (..., {STATE_SIZE}), got {x.shape}")
    return np.ascontiguousarray(x.reshape(-1, STATE_SIZE))


__all__ = [
    "CONSTRAINT_DTYPE", "MAX_ROWS", "TABLE_DTYPE", "ConstraintSet", "Registry", "angles_many", "constraint_record",
    "registry", "rows_many", "safety_many", "table_dtype",
]  # fmt: skip
