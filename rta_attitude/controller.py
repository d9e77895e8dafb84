"""The paper's primary controller: a saturated PD attitude law (SPEC sec. 5.1).

    u_des = psi_dot_max tanh(-kp dq_{1:3} - kd omega),    dq = q (x) q_c^-1 (no sign flip)

omega in rad/s; psi_dot_max is the actuator limit, so u_des can exceed the tighter
angular-acceleration bounds of U, which the filter enforces.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import quaternion as quat
from .params import Config
from .state import OMEGA, Q

Array = NDArray[np.float64]


def pd_command(x: Array, q_c: Array, cfg: Config) -> Array:
    """Desired wheel accelerations u_des (..., 3), rad/s^2.

    Args:
        x: states (..., 19).
        q_c: commanded quaternions (..., 4) or (4,), scalar last.
        cfg: configuration (gains, psi_dot_max).
    """
    x = np.asarray(x, dtype=float)
    dq = quat.error_vector(x[..., Q], np.broadcast_to(np.asarray(q_c, dtype=float), x[..., Q].shape))
    k = cfg.controller
    return cfg.limits.wheel_accel_max_rad_s2 * np.tanh(-k.kp * dq - k.kd * x[..., OMEGA])


def zero_command(x: Array) -> Array:
    """No primary controller: u_des = 0 (..., 3)."""
    return np.zeros((*np.shape(x)[:-1], 3))


__all__ = ["pd_command", "zero_command"]
