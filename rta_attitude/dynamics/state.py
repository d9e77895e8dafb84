"""The named state layout: one place that says which entry of the state vector is what.

The state has 19 entries (SPEC.md says 17, but its own list q(4), omega(3), psi(3), T, E,
theta_S and the 6 Clohessy-Wiltshire entries adds up to 19; see docs/decisions.md):

| entries            | meaning                                        | unit      |
|--------------------|------------------------------------------------|-----------|
| q1 q2 q3 q4        | quaternion Hill -> body, vector first          | -         |
| omega_x/y/z        | body angular rate                              | rad/s     |
| psi_x/y/z          | reaction-wheel spin rates                      | rad/s     |
| T                  | temperature of the -j_B face node              | K         |
| E                  | battery energy                                 | J         |
| theta_S            | sun angle in the Hill x-y plane                | rad       |
| x y z              | deputy position relative to the chief (Hill)   | m         |
| x_dot y_dot z_dot  | deputy velocity relative to the chief (Hill)   | m/s       |

Every function takes a batch `(..., 19)`; a single state is a batch of one.

**Arrays of more than three wheels** (`spacecraft.wheel_spin_axes_body`) keep this layout and append the
speeds of wheels 4..N after z_dot: the state has 16 + N entries, wheel i's speed is entry `wheel_column(i)`
(7, 8, 9, then 19, 20, ...). Every entry of the three-wheel layout keeps its index, so the paper's state,
its messages and its bags are one case of the general one.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.jit import LEAF

STATE_NAMES: tuple[str, ...] = (
    "q1", "q2", "q3", "q4",
    "omega_x", "omega_y", "omega_z",
    "psi_x", "psi_y", "psi_z",
    "T", "E", "theta_S",
    "x", "y", "z", "x_dot", "y_dot", "z_dot",
)  # fmt: skip
"""Names of the state entries, in order; also JointState.name and table columns."""

STATE_UNITS: tuple[str, ...] = (
    "-", "-", "-", "-",
    "rad/s", "rad/s", "rad/s",
    "rad/s", "rad/s", "rad/s",
    "K", "J", "rad",
    "m", "m", "m", "m/s", "m/s", "m/s",
)  # fmt: skip
"""Units of the state entries, in the order of STATE_NAMES."""

STATE_SIZE = len(STATE_NAMES)
CONTROL_SIZE = 3
"""u = psi_dot, the three wheel accelerations in rad/s^2."""

Q = slice(0, 4)
OMEGA = slice(4, 7)
PSI = slice(7, 10)
TEMP = 10
ENERGY = 11
THETA_S = 12
POS = slice(13, 16)
VEL = slice(16, 19)
CW = slice(13, 19)

AXES: tuple[str, ...] = ("x", "y", "z")


def state_size(n_wheels: int) -> int:
    """Entries of the state of an array of n_wheels wheels: 16 + n_wheels (STATE_SIZE for three)."""
    return STATE_SIZE + n_wheels - 3


@numba.njit(**LEAF, inline="always")
def wheel_column(i: int) -> int:
    """The state entry of wheel i's speed: 7 + i for the first three, 16 + i after (appended after z_dot); compiled,
    so the kernels index the wheels past the third by it."""
    return 7 + i if i < 3 else STATE_SIZE + i - 3


def wheel_columns(n_wheels: int) -> tuple[int, ...]:
    """The state entries of the wheel speeds of an array of n_wheels, in wheel order (`wheel_column`)."""
    return tuple(wheel_column(i) for i in range(n_wheels))


def make_state(
    q: ArrayLike,
    omega_rad_s: ArrayLike = (0.0, 0.0, 0.0),
    psi_rad_s: ArrayLike = (0.0, 0.0, 0.0),
    T_K: float = 273.15,
    E_J: float = 1000.0,
    theta_S_rad: float = 0.0,
    cw: ArrayLike = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
) -> NDArray[np.float64]:
    """Pack one state vector (shape (19,)); the quaternion is normalised.

    Args:
        q: quaternion Hill -> body, scalar last, shape (4,), any nonzero norm.
        omega_rad_s: body rates, rad/s, shape (3,).
        psi_rad_s: wheel speeds, rad/s, shape (3,).
        T_K: face temperature, K.
        E_J: battery energy, J.
        theta_S_rad: sun angle, rad.
        cw: Clohessy-Wiltshire position (m) and velocity (m/s), shape (6,).

    Returns:
        The state, shape (19,).
    """
    x = np.zeros(STATE_SIZE)
    qa = np.asarray(q, dtype=float)
    x[Q] = qa / np.linalg.norm(qa)
    x[OMEGA] = omega_rad_s
    x[PSI] = psi_rad_s
    x[TEMP] = T_K
    x[ENERGY] = E_J
    x[THETA_S] = theta_S_rad
    x[CW] = cw
    return x


def as_dict(x: NDArray[np.float64]) -> dict[str, float]:
    """One state (19,) as {name: value}, in model units."""
    return {name: float(v) for name, v in zip(STATE_NAMES, np.asarray(x, dtype=float))}


__all__ = [
    "AXES", "CONTROL_SIZE", "CW", "ENERGY", "OMEGA", "POS", "PSI", "Q", "STATE_NAMES",
    "STATE_SIZE", "STATE_UNITS", "TEMP", "THETA_S", "VEL", "as_dict", "make_state", "state_size", "wheel_column",
    "wheel_columns",
]  # fmt: skip
