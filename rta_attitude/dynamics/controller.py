"""The paper's primary controller: a saturated PD attitude law (SPEC sec. 5.1), compiled.

    u_des = psi_dot_max tanh(-kp dq_{1:3} - kd omega),    dq = q (x) q_c^-1 (no sign flip)

omega in rad/s; psi_dot_max is the actuator limit, so u_des can exceed the tighter
angular-acceleration bounds of U, which the filter enforces. `pd_command` is the compiled law of one
state (the closed loop and the Monte Carlo call it); `desired_command` its face for the controller
node and tools.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.quaternion import error_vector
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

CONTROLLER_DTYPE = np.dtype([
    ("pd", np.uint8),                        # 1: the PD law; 0: no primary controller (u_des = 0)
    ("kp", np.float64),
    ("kd", np.float64),
    ("wheel_accel_max_rad_s2", np.float64),  # psi_dot_max
])  # fmt: skip


def controller_record(cfg: Config, pd: bool = True) -> NDArray[np.void]:
    """The CONTROLLER_DTYPE record (1,) of a configuration; pd False: no primary controller."""
    rec = np.zeros(1, CONTROLLER_DTYPE)
    rec[0]["pd"] = pd
    rec[0]["kp"], rec[0]["kd"] = cfg.controller.kp, cfg.controller.kd
    rec[0]["wheel_accel_max_rad_s2"] = cfg.limits.wheel_accel_max_rad_s2
    return rec


@numba.njit(**LEAF)
def pd_command(x: Array, q_c: Array, k: np.void, out: Array) -> None:
    """Desired wheel accelerations (3,) into out, rad/s^2, at state x (19,) and command q_c (4,)."""
    if not k.pd:
        out[0] = out[1] = out[2] = 0.0
        return
    error_vector(x[0:4], q_c, out)  # dq, then the command in place
    for a in range(3):
        out[a] = k.wheel_accel_max_rad_s2 * math.tanh(-k.kp * out[a] - k.kd * x[4 + a])


@numba.njit(**LEAF)
def _pd_command(x: Array, q_c: Array, k: NDArray[np.void], out: Array) -> None:
    pd_command(x, q_c, k[0], out)


def desired_command(x: Array, q_c: Array, k: NDArray[np.void]) -> Array:
    """`pd_command` of one state (19,) and command (4,) with controller record k (1,): u_des (3,)."""
    out = np.empty(3)
    _pd_command(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(q_c, dtype=float), k, out)
    return out


__all__ = ["CONTROLLER_DTYPE", "controller_record", "desired_command", "pd_command"]
