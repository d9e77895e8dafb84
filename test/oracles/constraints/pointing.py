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


PAIRS: tuple[tuple[tuple[float, float, float], str], ...] = (
    ((1.0, 0.0, 0.0), "sun"),     # sensor +i_B (exclusion zone)
    ((0.0, 1.0, 0.0), "earth"),   # antenna +j_B (communication)
    ((0.0, -1.0, 0.0), "sun"),    # thermal face -j_B (temperature)
    ((0.0, -1.0, 0.0), "earth"),  # thermal face -j_B (temperature)
    ((0.0, 0.0, 1.0), "sun"),     # panel +k_B (battery)
)
"""The axis-target pairs the constraints use; evaluated together, once per context."""


def _all_pairs(ctx: Context) -> Pointing:
    from oracles.model import EARTH_DIRECTION_HILL

    if "pointing" not in ctx.cache:
        shape = (*ctx.batch_shape, len(PAIRS), 3)
        r, rd, rdd = np.empty(shape), np.empty(shape), np.empty(shape)
        for k, (_axis, target) in enumerate(PAIRS):
            if target == "sun":
                r[..., k, :], rd[..., k, :], rdd[..., k, :] = ctx.sun, ctx.sun_dot, ctx.sun_ddot
            else:
                r[..., k, :], rd[..., k, :], rdd[..., k, :] = EARTH_DIRECTION_HILL, 0.0, 0.0
        ctx.cache["pointing"] = pointing(ctx, np.array([a for a, _ in PAIRS]), r, rd, rdd)
    return ctx.cache["pointing"]


def _pair(ctx: Context, axis_body: Array, target: str) -> Pointing:
    key = (tuple(float(v) for v in axis_body), target)
    k = [p for p in PAIRS].index(key)
    t = _all_pairs(ctx)
    return Pointing(t.cos[..., k], t.cos_dot[..., k], t.cos_ddot_drift[..., k], t.cos_ddot_gain[..., k, :],
                    t.theta[..., k], t.theta_dot[..., k], t.theta_ddot_drift[..., k], t.theta_ddot_gain[..., k, :])


def sun_pointing(ctx: Context, axis_body: Array) -> Pointing:
    """Angle of a body axis (one of PAIRS) to the (moving) sun direction."""
    return _pair(ctx, axis_body, "sun")


def earth_pointing(ctx: Context, axis_body: Array) -> Pointing:
    """Angle of a body axis (one of PAIRS) to the (fixed) Earth direction -x_Hill."""
    return _pair(ctx, axis_body, "earth")
