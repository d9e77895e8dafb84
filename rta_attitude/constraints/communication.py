"""Communication: the +j_B antenna stays within FOV/2 of the ground station (the Earth, -x Hill).

    h_comm = FOV/2 - theta_GS                     theta_GS = angle(+j_B, r_E), rad
    Psi_0  = h_comm - margin
    Psi_1  = -theta_dot + k1 Psi_0
    BC     = -theta_ddot(u) - k1 theta_dot + k2 Psi_1 + bias >= 0        (relative degree 2, HOCBF)

The paper's slacked constraint. Safest at theta_GS = 0 (antenna at Earth), an arccos pole.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import COMMUNICATION, angle_rate_error, second_order
from rta_attitude.constraints.geometry import angle, pointing
from rta_attitude.jit import LEAF

NAME = "communication"
AXIS_BODY = (0.0, 1.0, 0.0)
"""Antenna boresight +j_B."""


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void) -> float:
    """FOV/2 - theta_GS (rad); negative = the ground station is outside the antenna's cone."""
    return c.comm_angle_rad - angle(0.0, 1.0, 0.0, ctx.earth)


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, t: np.void) -> None:
    """h, HOCBF levels and the barrier row of communication into table t."""
    i = COMMUNICATION
    g = c.gains[i]
    _, _, th, th_dot, th_ddot, g0, g1, g2 = pointing(0.0, 1.0, 0.0, ctx.earth, ctx.earth_rate, ctx.earth_acc, ctx,
                                                     c.sin_pole_guard)
    t.h[i] = c.comm_angle_rad - th
    robust = c.err_att_rad + angle_rate_error(math.sin(th), x, c) / g.k1  # 0 without sensor errors
    second_order(t, i, t.h[i] - g.margin - robust, -th_dot, -th_ddot, g)
    t.gain[i, 0], t.gain[i, 1], t.gain[i, 2] = -g0, -g1, -g2
