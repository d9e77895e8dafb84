"""The paper's primary controller: a saturated PD attitude law (SPEC sec. 5.1), compiled; and the
convention any other primary controller follows.

    u_des = psi_dot_max tanh(-kp dq_{1:3} - kd omega),    dq = q (x) q_c^-1 (no sign flip)

omega in rad/s; psi_dot_max is the actuator limit, so u_des can exceed the tighter
angular-acceleration bounds of U, which the filter enforces. `pd_command` is the compiled law of one
state (the closed loop and the Monte Carlo call it); `desired_command` its face for the controller
node and tools.

A primary controller of your own (`PrimaryController`, for `simulation.closed_loop.run_stepped` and
`rta-attitude montecarlo --controller module:function`) answers what `desired_command` answers:
u_des = f(y, q_c, t_s), the desired wheel accelerations (3,) in rad/s^2 (the filter's u, not a torque:
the loop sends tau = D u_des across the torque interface itself, as the controller node does), from
the state y (19,) as the filter reads it (measured, `dynamics.state` layout, quaternion scalar last),
the commanded attitude q_c (4,, scalar last, Hill to body as x's) and the time t_s since the run's
start. `checked_command` holds it to that.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.quaternion import error_vector
from rta_attitude.errors import RtaError
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

PrimaryController = Callable[[Array, Array, float], ArrayLike]
"""u_des = f(y (19,), q_c (4,), t_s): desired wheel accelerations (3,), rad/s^2 (the module's docstring)."""


class ControllerError(RtaError):
    """A primary controller answered something other than 3 finite wheel accelerations."""

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


def checked_command(u_des: ArrayLike, t_s: float) -> Array:
    """A primary controller's answer at t_s as the float array (3,) the loop sends on.

    Raises:
        ControllerError: not 3 finite numbers (one line: what came back, and when).
    """
    try:
        u = np.asarray(u_des, dtype=float)
    except (TypeError, ValueError):
        u = None
    if u is None or u.shape != (3,) or not np.all(np.isfinite(u)):
        shown = " ".join(repr(u_des).split())
        shown = shown if len(shown) <= 80 else shown[:77] + "..."
        raise ControllerError(f"the primary controller returned {shown} at t = {t_s:g} s: it must return 3 finite "
                              "wheel accelerations, rad/s^2")
    return u


__all__ = ["CONTROLLER_DTYPE", "ControllerError", "PrimaryController", "checked_command", "controller_record",
           "desired_command", "pd_command"]
