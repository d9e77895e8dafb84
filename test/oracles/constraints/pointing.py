"""Angle between a body-fixed axis and a moving Hill-frame direction, with two time derivatives.

For a body axis e and a unit target r(t) in Hill, r_B = A(q) r is the target in body axes and

    c       = cos(theta) = e . r_B
    c_dot   = omega . (e x r_B) + e . (A r_dot)
    c_ddot  = omega_dot . (e x r_B) + omega . (e x (-omega x r_B)) + 2 omega . (e x A r_dot) + e . (A r_ddot)
    theta   = atan2(|e x r_B|, e . r_B),   s = sin(theta) = |e x r_B|
    theta_dot  = -c_dot / s
    theta_ddot = -c_ddot / s - c c_dot^2 / s^3

(using A_dot = -[omega x] A). omega_dot = omega_drift + G u, so c_ddot and theta_ddot split into a
drift and a gain on u.

Poles. theta is not differentiable at 0 and pi: passing through a pole, theta_dot jumps sign, and
near it theta_ddot ~ -c_ddot / s grows without bound (with the sun moving at n, BC of the
exclusion zone turns negative within ~1.5e-5 rad of theta_EZ = pi, its *safest* attitude, and the
filter would demand large torques there). Within `filter.pole_guard_rad` of a pole the angle is
therefore treated as stationary (theta_dot = theta_ddot = 0, no gain on u), so an HOCBF there
reduces to k1 k2 h: positive at a safe pole, which is >= 40 deg from every boundary, while one
1 s sample moves an axis by at most ~1 deg. Every value stays finite; see the pole tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from oracles.constraints.base import Context

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Pointing:
    """Cosine and angle of one axis-target pair with derivatives (shapes (...) or (..., 3))."""

    cos: Array
    cos_dot: Array
    cos_ddot_drift: Array
    cos_ddot_gain: Array
    theta: Array
    theta_dot: Array
    theta_ddot_drift: Array
    theta_ddot_gain: Array


def _dot(a: Array, b: Array) -> Array:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a: Array, b: Array) -> Array:
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def pointing(ctx: Context, axis_body: Array, target: Array, target_dot: Array, target_ddot: Array) -> Pointing:
    """Angle kinematics of body axes to Hill directions; broadcasts over leading axes.

    Args:
        ctx: evaluation context (its A, omega, omega_drift have batch shape B).
        axis_body: unit body axes e (K, 3) or (3,).
        target, target_dot, target_ddot: r, r_dot, r_ddot in Hill, shape B + (K, 3) (or B + (3,)
            with a (3,) axis), units 1, 1/s, 1/s^2.

    Returns:
        Pointing with fields of shape B + (K,) (gains B + (K, 3)), or B (B + (3,)) for one axis.
    """
    many = np.ndim(axis_body) == 2
    A = ctx.A[..., None, :, :] if many else ctx.A
    w = ctx.omega[..., None, :] if many else ctx.omega
    wd = ctx.omega_drift[..., None, :] if many else ctx.omega_drift
    r_B = np.einsum("...ij,...j->...i", A, target)
    rd_B = np.einsum("...ij,...j->...i", A, target_dot)
    rdd_B = np.einsum("...ij,...j->...i", A, target_ddot)
    e = np.broadcast_to(axis_body, r_B.shape)
    m = _cross(e, r_B)
    c = _dot(e, r_B)
    c_dot = _dot(w, m) + _dot(e, rd_B)
    c_dd_drift = (_dot(wd, m) + _dot(w, _cross(e, -_cross(w, r_B)))
                  + 2.0 * _dot(w, _cross(e, rd_B)) + _dot(e, rdd_B))
    c_dd_gain = m * ctx.cfg.spacecraft.control_gain
    sin_raw = np.sqrt(_dot(m, m))
    theta = np.arctan2(sin_raw, c)
    guard = np.sin(ctx.cfg.filter.pole_guard_rad)
    away = sin_raw > guard
    s = np.where(away, sin_raw, 1.0)
    theta_dot = np.where(away, -c_dot / s, 0.0)
    th_dd_drift = np.where(away, -c_dd_drift / s - c * c_dot**2 / s**3, 0.0)
    th_dd_gain = np.where(away[..., None], -c_dd_gain / s[..., None], 0.0)
    return Pointing(c, c_dot, c_dd_drift, c_dd_gain, theta, theta_dot, th_dd_drift, th_dd_gain)


def target_in_hill(kind: str, vector: Array | None, ctx: Context) -> tuple[Array, Array, Array]:
    """A target's unit vector in Hill and its first two time derivatives (batch (..., 3)), the Hill frame
    inertial (the oracle's model): the sun r_S(theta_S, beta); a vector fixed in the inertial frame I
    (x toward the sun's direction in the orbit plane at theta_S = 0, z the orbit normal) reads
    R_z(theta_S) v in Hill, with theta_S_dot = -n; the Earth, the orbit normal, the velocity and a vector
    fixed in Hill do not move."""
    from oracles.model import EARTH_DIRECTION_HILL

    shape = (*ctx.batch_shape, 3)
    if kind == "sun":
        return ctx.sun, ctx.sun_dot, ctx.sun_ddot
    if kind == "inertial":
        th = ctx.x[..., 12]
        n = ctx.cfg.environment.mean_motion_rad_s
        v = np.asarray(vector, dtype=float)
        c, s = np.cos(th), np.sin(th)
        r = np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1], np.full_like(th, v[2])], axis=-1)
        # d/dt with theta_S_dot = -n: R_z'(theta) v times -n
        rd = -n * np.stack([-s * v[0] - c * v[1], c * v[0] - s * v[1], np.zeros_like(th)], axis=-1)
        rdd = -(n**2) * np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1], np.zeros_like(th)], axis=-1)
        return r, rd, rdd
    fixed = {"earth": EARTH_DIRECTION_HILL, "orbit_normal": np.array([0.0, 0.0, 1.0]),
             "velocity": np.array([0.0, 1.0, 0.0])}
    v = fixed[kind] if kind in fixed else np.asarray(vector, dtype=float)
    return np.broadcast_to(v, shape), np.zeros(shape), np.zeros(shape)


def axis_pointing(ctx: Context, axis_body: Array, kind: str, vector: Array | None = None) -> Pointing:
    """Angle kinematics of one body axis to one target (`target_in_hill`), batch-first."""
    r, rd, rdd = target_in_hill(kind, vector, ctx)
    return pointing(ctx, np.asarray(axis_body, dtype=float), r, rd, rdd)


def sun_pointing(ctx: Context, axis_body: Array) -> Pointing:
    """Angle of a body axis to the (moving) sun direction."""
    return axis_pointing(ctx, axis_body, "sun")


def earth_pointing(ctx: Context, axis_body: Array) -> Pointing:
    """Angle of a body axis to the (fixed) Earth direction -x_Hill."""
    return axis_pointing(ctx, axis_body, "earth")
