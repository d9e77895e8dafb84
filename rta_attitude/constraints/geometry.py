"""What every barrier of one state needs, computed once per state, and the angle kinematics.

`context` fills a CONTEXT_DTYPE record from a state x and the filter's plant model (a PLANT_DTYPE
record): the attitude matrix A(q) (Hill -> body), the body rate omega, the drift of omega_dot
(`dynamics.spacecraft.omega_drift`: Euler, wheel gyroscopic term, gravity gradient as the model
has them), the control gain G = d omega_dot / d u, and the two targets in body axes with their
first two *inertial* time derivatives:

    sun   r_S = [cos theta_S, sin theta_S, 0] (Hill), theta_S_dot = -n
    Earth r_E = [-1, 0, 0] (Hill, the ground station's direction)

With the Hill frame turning at n_f about z (`frame_rate_rad_s`), a target's inertial derivatives
are r' = r_dot + W x r and r'' = r_ddot + 2 W x r_dot + W x (W x r), W = [0, 0, n_f]: the sun
(fixed in inertial space) then has r' = 0 exactly when n_f = n, and the Earth direction turns.

`pointing` gives, for a unit body axis e and a target r_B = A r (with r_B', r_B''), the angle
theta = angle(e, r_B) and its derivatives along f + g u:

    c       = cos(theta) = e . r_B
    c_dot   = omega . (e x r_B) + e . r_B'
    c_ddot  = omega_dot . (e x r_B) + omega . (e x (-omega x r_B)) + 2 omega . (e x r_B') + e . r_B''
    theta   = atan2(|e x r_B|, e . r_B),   s = sin(theta) = |e x r_B|
    theta_dot  = -c_dot / s
    theta_ddot = -c_ddot / s - c c_dot^2 / s^3

(A_dot = -[omega x] A for inertial derivatives.) omega_dot = drift + G u splits theta_ddot into a
drift and a gain on u. Poles: theta is not differentiable at 0 and pi; within the pole guard
(`sin_pole_guard`) the angle is held stationary (theta_dot = theta_ddot = 0, no gain), so an HOCBF
there reduces to k1 k2 h, positive at a safe pole (docs/decisions.md, "arccos poles").
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.dynamics.quaternion import attitude_matrix
from rta_attitude.dynamics.spacecraft import omega_drift, sun_hill
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

CONTEXT_DTYPE = np.dtype([
    ("A", np.float64, (3, 3)),         # A(q), Hill -> body
    ("omega", np.float64, (3,)),       # body rate, rad/s
    ("omega_drift", np.float64, (3,)),  # omega_dot at u = 0, rad/s^2
    ("control_gain", np.float64, (3,)),  # d omega_dot / d u
    ("sun", np.float64, (3,)),         # r_S in body
    ("sun_rate", np.float64, (3,)),    # inertial first derivative of r_S, in body, 1/s
    ("sun_acc", np.float64, (3,)),     # inertial second derivative of r_S, in body, 1/s^2
    ("earth", np.float64, (3,)),       # r_E in body
    ("earth_rate", np.float64, (3,)),
    ("earth_acc", np.float64, (3,)),
    ("zoh_omega", np.float64, (3, 3)),   # scratch of angular_rate.zoh_rows: Omega, the linear wheel term
    ("zoh_sum", np.float64, (3, 3)),     # sum of (Omega tau)^n / (n + 1)!
    ("zoh_term", np.float64, (3, 3)),
    ("zoh_next", np.float64, (3, 3)),
])  # fmt: skip
"""Per-state quantities shared by the barriers (one record)."""



@numba.njit(**LEAF)
def context(x: Array, p: np.void, rates: bool, ctx: np.void) -> None:
    """Fill ctx (CONTEXT_DTYPE) for state x (19,) with plant model p (PLANT_DTYPE). With rates False,
    only A, omega and the two targets (what the safety values need)."""
    A = ctx.A
    attitude_matrix(x[0], x[1], x[2], x[3], A)
    for a in range(3):
        ctx.omega[a] = x[4 + a]
    cs, sn = sun_hill(x[12])
    for i in range(3):  # A r_S with r_S = [cos, sin, 0]; A r_E with r_E = EARTH_HILL = [-1, 0, 0]
        ctx.sun[i] = A[i, 0] * cs + A[i, 1] * sn
        ctx.earth[i] = -A[i, 0]
    if not rates:
        return
    omega_drift(x, A, p, ctx.omega_drift)
    for a in range(3):
        ctx.control_gain[a] = p.control_gain[a]
    n = p.mean_motion_rad_s
    # Hill-frame derivatives of r_S (theta_S_dot = -n); r_E is fixed in Hill
    sd0, sd1 = n * sn, -n * cs
    sdd0, sdd1 = -(n * n) * cs, -(n * n) * sn
    ed0 = ed1 = edd0 = edd1 = 0.0
    nf = p.frame_rate_rad_s
    if nf != 0.0:  # inertial derivatives: r' = r_dot + W x r, r'' = r_ddot + 2 W x r_dot + W x (W x r)
        sdd0, sdd1 = sdd0 - 2.0 * nf * sd1 - nf * nf * cs, sdd1 + 2.0 * nf * sd0 - nf * nf * sn
        sd0, sd1 = sd0 - nf * sn, sd1 + nf * cs
        ed0, ed1 = 0.0, -nf
        edd0, edd1 = nf * nf, 0.0
    for i in range(3):  # z components are 0 (targets in the orbit plane, W along z)
        ctx.sun_rate[i] = A[i, 0] * sd0 + A[i, 1] * sd1
        ctx.sun_acc[i] = A[i, 0] * sdd0 + A[i, 1] * sdd1
        ctx.earth_rate[i] = A[i, 0] * ed0 + A[i, 1] * ed1
        ctx.earth_acc[i] = A[i, 0] * edd0 + A[i, 1] * edd1


@numba.njit(**LEAF)
def angle(ex: float, ey: float, ez: float, r: Array) -> float:
    """theta = atan2(|e x r|, e . r) between a unit body axis e and a body-frame direction r, rad."""
    m0 = ey * r[2] - ez * r[1]
    m1 = ez * r[0] - ex * r[2]
    m2 = ex * r[1] - ey * r[0]
    c = ex * r[0] + ey * r[1] + ez * r[2]
    return math.atan2(math.sqrt(m0 * m0 + m1 * m1 + m2 * m2), c)


@numba.njit(**LEAF)
def pointing(ex: float, ey: float, ez: float, r: Array, rd: Array, rdd: Array, ctx: np.void,
             sin_guard: float) -> tuple[float, float, float, float, float, float, float, float]:
    """Angle kinematics of unit body axis e and target r (body axes, with inertial rates rd, rdd).

    Returns (cos, cos_dot, theta, theta_dot, theta_ddot drift, and d theta_ddot / d u as three
    floats). Within the pole guard the angle is held stationary (zero rates and gain).
    """
    w, wd, cg = ctx.omega, ctx.omega_drift, ctx.control_gain
    # m = e x r_B, c = e . r_B
    m0 = ey * r[2] - ez * r[1]
    m1 = ez * r[0] - ex * r[2]
    m2 = ex * r[1] - ey * r[0]
    c = ex * r[0] + ey * r[1] + ez * r[2]
    c_dot = (w[0] * m0 + w[1] * m1 + w[2] * m2) + (ex * rd[0] + ey * rd[1] + ez * rd[2])
    # w x r_B, then e x (-(w x r_B))
    v0 = -(w[1] * r[2] - w[2] * r[1])
    v1 = -(w[2] * r[0] - w[0] * r[2])
    v2 = -(w[0] * r[1] - w[1] * r[0])
    ev0, ev1, ev2 = ey * v2 - ez * v1, ez * v0 - ex * v2, ex * v1 - ey * v0
    ed0, ed1, ed2 = ey * rd[2] - ez * rd[1], ez * rd[0] - ex * rd[2], ex * rd[1] - ey * rd[0]
    c_dd_drift = ((wd[0] * m0 + wd[1] * m1 + wd[2] * m2) + (w[0] * ev0 + w[1] * ev1 + w[2] * ev2)
                  + 2.0 * (w[0] * ed0 + w[1] * ed1 + w[2] * ed2) + (ex * rdd[0] + ey * rdd[1] + ez * rdd[2]))
    sin_raw = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    theta = math.atan2(sin_raw, c)
    if sin_raw > sin_guard:
        s = sin_raw
        return (c, c_dot, theta, -c_dot / s, -c_dd_drift / s - c * c_dot**2 / s**3,
                -(m0 * cg[0]) / s, -(m1 * cg[1]) / s, -(m2 * cg[2]) / s)
    return c, c_dot, theta, 0.0, 0.0, 0.0, 0.0, 0.0  # within the pole guard: held stationary


def new_context() -> NDArray[np.void]:
    """An empty context record array (1,)."""
    return np.zeros(1, CONTEXT_DTYPE)


__all__ = ["CONTEXT_DTYPE", "angle", "context", "new_context", "pointing"]
