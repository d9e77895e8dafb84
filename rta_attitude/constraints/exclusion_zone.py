"""Attitude exclusion zone: the +i_B sensor stays >= FOV/2 + beta away from the sun.

    h_EZ  = theta_EZ - FOV/2 - beta              theta_EZ = angle(+i_B, r_S), rad
    Psi_0 = h_EZ - margin                         (margin: robust preset's sampled-data allowance)
    Psi_1 = theta_dot + k1 Psi_0
    BC    = theta_ddot(u) + k1 theta_dot + k2 Psi_1 + bias >= 0          (relative degree 2, HOCBF)

theta and its rates from `geometry.pointing` of +i_B and the sun. Safest at theta_EZ = pi (sensor
anti-sun), an arccos pole: there the angle is held stationary (pole guard).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import EXCLUSION_ZONE, angle_rate_error, second_order
from rta_attitude.constraints.geometry import angle, pointing
from rta_attitude.jit import LEAF

NAME = "exclusion_zone"
AXIS_BODY = (1.0, 0.0, 0.0)
"""Sensor boresight +i_B."""


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void) -> float:
    """theta_EZ - FOV/2 - beta (rad); negative = the sensor is inside the keep-out cone."""
    return angle(1.0, 0.0, 0.0, ctx.sun) - c.exclusion_angle_rad


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, t: np.void) -> None:
    """h, HOCBF levels and the barrier row of the exclusion zone into table t."""
    i = EXCLUSION_ZONE
    g = c.gains[i]
    _, _, th, th_dot, th_ddot, g0, g1, g2 = pointing(1.0, 0.0, 0.0, ctx.sun, ctx.sun_rate, ctx.sun_acc, ctx,
                                                     c.sin_pole_guard)
    t.h[i] = th - c.exclusion_angle_rad
    robust = c.err_att_rad + angle_rate_error(math.sin(th), x, c) / g.k1  # 0 without sensor errors
    second_order(t, i, t.h[i] - g.margin - robust, th_dot, th_ddot, g)
    t.gain[i, 0], t.gain[i, 1], t.gain[i, 2] = g0, g1, g2
