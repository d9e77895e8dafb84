"""The safety constraints of the paper, one module each, gathered into an ordered, named set.

| name            | h (safe >= 0)                 | enforced through                          | module            |
|-----------------|-------------------------------|-------------------------------------------|-------------------|
| exclusion_zone  | theta_EZ - FOV/2 - beta       | HOCBF                                     | exclusion_zone.py |
| communication   | FOV/2 - theta_GS              | HOCBF (+ slack in the paper)              | communication.py  |
| temperature     | T_max - T                     | HOCBF on the angle-augmented Psi_temp     | temperature.py    |
| battery         | E - E_min                     | HOCBF on Psi_batt = h - delta2 theta_SI   | battery.py        |
| omega_x/y/z     | omega_max^2 - omega_i^2       | CBF (+ ZOH bound in the robust preset)    | angular_rate.py   |
| psi_x/y/z       | psi_max^2 - psi_i^2           | CBF (+ ZOH bound in the robust preset)    | wheel_speed.py    |

Actuator and angular-acceleration limits are the box U of the filter (Config.u_max_rad_s2).

Each module holds the formula (docstring) and the compiled one-state code of its constraint: `h`
(the physical safety value) and `row` (h, the HOCBF levels and the affine barrier condition
BC = drift + gain . u). `geometry` computes what they share once per state; `rows` runs them in
order; `base` has the records their parameters travel in. `ConstraintSet` is the Python face for
batches of states (reports, sampling, tests): a compiled loop over the same one-state code.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import CONSTRAINT_NAMES, Config
from rta_attitude.constraints.base import (
    CONSTRAINT_DTYPE,
    N_CONSTRAINTS,
    TABLE_DTYPE,
    constraint_record,
    group_of,
)
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.rows import ANGLE_NAMES, pointing_angles, rows, safety_values
from rta_attitude.dynamics.spacecraft import plant_record
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.jit import JIT

Array = NDArray[np.float64]


@numba.njit(**JIT)
def rows_many(X: Array, p: NDArray[np.void], c: NDArray[np.void], T: NDArray[np.void]) -> None:
    """`rows` of states X (N, 19) into tables T (N,), with the box a drive in any state holds."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    hi0 = c[0].u_reach_rad_s2.copy()  # what a drive in any state holds (U without lag compensation)
    lo0 = -hi0
    for k in range(X.shape[0]):
        rows(X[k], p[0], c[0], ctx[0], T[k], lo0, hi0)


@numba.njit(**JIT)
def safety_many(X: Array, p: NDArray[np.void], c: NDArray[np.void], H: Array) -> None:
    """`safety_values` of states X (N, 19) into H (N, m)."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    for k in range(X.shape[0]):
        safety_values(X[k], p[0], c[0], ctx[0], H[k])


@numba.njit(**JIT)
def angles_many(X: Array, p: NDArray[np.void], out: Array) -> None:
    """`pointing_angles` of states X (N, 19) into out (N, 5)."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    for k in range(X.shape[0]):
        pointing_angles(X[k], p[0], ctx[0], out[k])


class ConstraintSet:
    """The ordered, named safety constraints of one configuration (Python face of the compiled rows).

    Args:
        cfg: configuration (limits, gains, preset; `filter.model`, the plant model the barriers assume).
    """

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.plant = plant_record(cfg, cfg.filter.model)
        self.record = constraint_record(cfg)
        self.names: tuple[str, ...] = CONSTRAINT_NAMES

    @classmethod
    def from_config(cls, cfg: Config) -> ConstraintSet:
        return cls(cfg)

    @property
    def enabled(self) -> NDArray[np.bool_]:
        """(m,) bool."""
        return self.record[0]["gains"]["enabled"].astype(bool)

    @property
    def slack_weights(self) -> Array:
        """(m,) slack weight p_i; 0 for hard constraints."""
        return self.record[0]["gains"]["slack_weight"].copy()

    @property
    def slacked(self) -> tuple[str, ...]:
        """Names of the enabled constraints that carry a slack."""
        return tuple(n for n, w in zip(self.names, self.slack_weights) if w > 0)

    def evaluate(self, x: Array) -> NDArray[np.void]:
        """TABLE_DTYPE records of states x (..., 19) (unit quaternions), shape (...), as a numpy record
        array: h, psi0, psi1, drift (..., m), gain (..., m, 3), lo, hi (..., 3) read as `table.h` or
        `table["h"]`."""
        X = _as_states(x)
        T = np.zeros(X.shape[0], TABLE_DTYPE)
        rows_many(X, self.plant, self.record, T)
        return T.reshape(np.shape(x)[:-1]).view(np.recarray)

    def safety_values(self, x: Array) -> Array:
        """Physical h of every constraint (..., m) of states x (..., 19); negative = violated."""
        X = _as_states(x)
        H = np.empty((X.shape[0], N_CONSTRAINTS))
        safety_many(X, self.plant, self.record, H)
        return H.reshape((*np.shape(x)[:-1], N_CONSTRAINTS))


    def angles(self, x: Array) -> dict[str, Array]:
        """The pointing angles of states x (..., 19) by ANGLE_NAMES, each (...), rad."""
        X = _as_states(x)
        out = np.empty((X.shape[0], len(ANGLE_NAMES)))
        angles_many(X, self.plant, out)
        return {n: out[:, i].reshape(np.shape(x)[:-1]) for i, n in enumerate(ANGLE_NAMES)}


def _as_states(x: Array) -> Array:
    x = np.asarray(x, dtype=float)
    if x.shape[-1:] != (STATE_SIZE,):
        raise ValueError(f"states must be (..., {STATE_SIZE}), got {x.shape}")
    return np.ascontiguousarray(x.reshape(-1, STATE_SIZE))


__all__ = [
    "ANGLE_NAMES", "CONSTRAINT_DTYPE", "CONSTRAINT_NAMES", "N_CONSTRAINTS", "TABLE_DTYPE", "ConstraintSet",
    "angles_many", "constraint_record", "group_of", "rows_many", "safety_many",
]  # fmt: skip
