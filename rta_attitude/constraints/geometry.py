"""What every barrier of one state needs, computed once per state, and the angle kinematics.

`context` fills a CONTEXT_DTYPE record from a state x and the filter's plant model (a PLANT_DTYPE
record): the attitude matrix A(q) (Hill -> body), the body rate omega, the drift of omega_dot
(`dynamics.spacecraft.omega_drift`: Euler, wheel gyroscopic term, gravity gradient as the model
has them), the control gain G = d omega_dot / d u (a full matrix with products of inertia or skewed
wheels), and the sun and the Earth (nadir) in body axes with their first two *inertial* time derivatives
(`dynamics.environment`: the one place that says where a target is and how it moves). `target` does the
same for any target of the cone table (`constraints.cones`).

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

from rta_attitude.dynamics.environment import EARTH, EARTH_HILL, SUN, inertial_rates, sun_hill, target_hill
from rta_attitude.dynamics.quaternion import attitude_matrix
from rta_attitude.dynamics.spacecraft import omega_drift
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

CONTEXT_DTYPE = np.dtype([
    ("A", np.float64, (3, 3)),         # A(q), Hill -> body
    ("omega", np.float64, (3,)),       # body rate, rad/s
    ("omega_drift", np.float64, (3,)),  # omega_dot at u = 0, rad/s^2
    ("control_gain", np.float64, (3,)),  # d omega_dot_i / d u_i (principal axes)
    ("control_matrix", np.float64, (3, 3)),  # G = d omega_dot / d u
    ("sun", np.float64, (3,)),         # r_S in body
    ("sun_rate", np.float64, (3,)),    # inertial first derivative of r_S, in body, 1/s
    ("sun_acc", np.float64, (3,)),     # inertial second derivative of r_S, in body, 1/s^2
    ("earth", np.float64, (3,)),       # r_E in body
    ("earth_rate", np.float64, (3,)),
    ("earth_acc", np.float64, (3,)),
    ("tgt", np.float64, (3,)),         # `target`: a cone's target in body, its inertial rates (scratch)
    ("tgt_rate", np.float64, (3,)),
    ("tgt_acc", np.float64, (3,)),
    ("zoh_omega", np.float64, (3, 3)),   # scratch of angular_rate.zoh_rows: Omega, the linear wheel term
    ("zoh_sum", np.float64, (3, 3)),     # sum of (Omega tau)^n / (n + 1)!
    ("zoh_term", np.float64, (3, 3)),
    ("zoh_next", np.float64, (3, 3)),
    ("inertia_err", np.float64, (3,)),  # bound on omega_dot's error from the inertia's (`base.inertia_error`)
    ("diagonal", np.uint8),            # 1: G is diagonal (the per-axis arithmetic); last, so the floats
    # before it stay 8-byte aligned
])  # fmt: skip
"""Per-state quantities shared by the barriers (one record)."""



@numba.njit(**LEAF, inline="always")
def to_body(A: Array, r0: float, r1: float, r2: float, out: Array) -> None:
    """out = A r (3,): a Hill vector r in body axes (a zero z component skipped: the paper's arithmetic)."""
    if r2 != 0.0:
        for i in range(3):
            out[i] = A[i, 0] * r0 + A[i, 1] * r1 + A[i, 2] * r2
    else:
        for i in range(3):
            out[i] = A[i, 0] * r0 + A[i, 1] * r1


@numba.njit(**LEAF, inline="always")
def _target_in_body(kind: int, v: Array, theta_S: float, p: np.void, rates: bool, ctx: np.void, r: Array,
                    rd: Array, rdd: Array) -> None:
    """A target (`dynamics.environment.target_hill`) in body axes into r and, with rates, its inertial rates
    into rd, rdd (ctx.A set)."""
    r0, r1, r2, d0, d1, d2, a0, a1, a2 = target_hill(kind, v, theta_S, p.sun_cos_beta, p.sun_sin_beta,
                                                     p.mean_motion_rad_s)
    to_body(ctx.A, r0, r1, r2, r)
    if rates:
        d0, d1, a0, a1 = inertial_rates(r0, r1, d0, d1, a0, a1, p.frame_rate_rad_s)
        to_body(ctx.A, d0, d1, d2, rd)
        to_body(ctx.A, a0, a1, a2, rdd)


@numba.njit(**LEAF)
def context(x: Array, p: np.void, rates: bool, ctx: np.void) -> None:
    """Fill ctx (CONTEXT_DTYPE) for state x (19,) with plant model p (PLANT_DTYPE). With rates False,
    only A, omega and the sun and the Earth in body axes (what the safety values need)."""
    A = ctx.A
    attitude_matrix(x[0], x[1], x[2], x[3], A)
    for a in range(3):
        ctx.omega[a] = x[4 + a]
    if not rates:  # the directions alone (the safety values, 11 times a sample in a simulation)
        sx, sy, sz = sun_hill(x[12], p.sun_cos_beta, p.sun_sin_beta)
        to_body(A, sx, sy, sz, ctx.sun)
        to_body(A, EARTH_HILL[0], EARTH_HILL[1], EARTH_HILL[2], ctx.earth)
        return
    e = ctx.tgt  # (a vector's storage for EARTH_HILL: the Earth's kind reads its direction from it)
    e[0], e[1], e[2] = EARTH_HILL
    _target_in_body(SUN, e, x[12], p, True, ctx, ctx.sun, ctx.sun_rate, ctx.sun_acc)
    _target_in_body(EARTH, e, x[12], p, True, ctx, ctx.earth, ctx.earth_rate, ctx.earth_acc)
    omega_drift(x, A, p, ctx.omega_drift)
    for a in range(3):
        ctx.control_gain[a] = p.control_gain[a]
        for b in range(3):
            ctx.control_matrix[a, b] = p.control_matrix[a, b]
    ctx.diagonal = p.diagonal


@numba.njit(**LEAF, inline="always")
def through_control(ctx: np.void, m0: float, m1: float, m2: float) -> tuple[float, float, float]:
    """The gain on u of a quantity whose gain on omega_dot is m (3): m_a G_a per wheel where G is diagonal, m^T G
    in general (products of inertia, wheels off the body axes; ctx: `context` with rates)."""
    if ctx.diagonal:
        cg = ctx.control_gain
        return m0 * cg[0], m1 * cg[1], m2 * cg[2]
    return _general_through_control(ctx, m0, m1, m2)


@numba.njit(**LEAF)
def _general_through_control(ctx: np.void, m0: float, m1: float, m2: float) -> tuple[float, float, float]:
    """`through_control` in general: m^T G."""
    G = ctx.control_matrix
    return (m0 * G[0, 0] + m1 * G[1, 0] + m2 * G[2, 0], m0 * G[0, 1] + m1 * G[1, 1] + m2 * G[2, 1],
            m0 * G[0, 2] + m1 * G[1, 2] + m2 * G[2, 2])


@numba.njit(**LEAF, inline="always")
def target(kind: int, v: Array, x: Array, p: np.void, rates: bool, ctx: np.void) -> tuple[Array, Array, Array]:
    """A cone's target in body axes with its inertial rates (context must have run on x): the sun's and the
    Earth's from ctx, any other's computed into ctx.tgt, tgt_rate, tgt_acc. kind: `dynamics.environment`'s
    code; v: its fixed vector (Hill or inertial)."""
    if kind == SUN:
        return ctx.sun, ctx.sun_rate, ctx.sun_acc
    if kind == EARTH:
        return ctx.earth, ctx.earth_rate, ctx.earth_acc
    _target_in_body(kind, v, x[12], p, rates, ctx, ctx.tgt, ctx.tgt_rate, ctx.tgt_acc)
    return ctx.tgt, ctx.tgt_rate, ctx.tgt_acc


@numba.njit(**LEAF, inline="always")
def angle_between(ex: float, ey: float, ez: float, r0: float, r1: float, r2: float) -> float:
    """theta = atan2(|e x r|, e . r) between a unit vector e and a unit vector r in the same axes, rad."""
    m0 = ey * r2 - ez * r1
    m1 = ez * r0 - ex * r2
    m2 = ex * r1 - ey * r0
    c = ex * r0 + ey * r1 + ez * r2
    return math.atan2(math.sqrt(m0 * m0 + m1 * m1 + m2 * m2), c)


@numba.njit(**LEAF)
def angle(ex: float, ey: float, ez: float, r: Array) -> float:
    """`angle_between` a unit body axis e and a body-frame direction r (3,), rad."""
    return angle_between(ex, ey, ez, r[0], r[1], r[2])


@numba.njit(**LEAF)
def pointing(ex: float, ey: float, ez: float, r: Array, rd: Array, rdd: Array, ctx: np.void,
             sin_guard: float) -> tuple[float, float, float, float, float, float, float, float]:
    """Angle kinematics of unit body axis e and target r (body axes, with inertial rates rd, rdd).

    Returns (cos, cos_dot, theta, theta_dot, theta_ddot drift, and d theta_ddot / d u as three
    floats). Within the pole guard the angle is held stationary (zero rates and gain).
    """
    w, wd = ctx.omega, ctx.omega_drift
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
        g0, g1, g2 = through_control(ctx, m0, m1, m2)
        return c, c_dot, theta, -c_dot / s, -c_dd_drift / s - c * c_dot**2 / s**3, -g0 / s, -g1 / s, -g2 / s
    return c, c_dot, theta, 0.0, 0.0, 0.0, 0.0, 0.0  # within the pole guard: held stationary


def new_context() -> NDArray[np.void]:
    """An empty context record array (1,)."""
    return np.zeros(1, CONTEXT_DTYPE)


__all__ = ["CONTEXT_DTYPE", "angle", "angle_between", "context", "new_context", "pointing", "target", "through_control",
           "to_body"]
