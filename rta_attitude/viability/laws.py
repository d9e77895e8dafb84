"""Warm-start laws: simple closed-loop attitude laws whose exactly simulated trajectory is either a
witness by itself or the optimiser's initial guess.

The sun-safe attitude (`sun_safe_matrix`): the panel's normal p (`power.panel_normal_body`) on the sun, r_S,
and, about that line, the part of the thermal face's inward normal -f (`thermal.face_normal_body`)
perpendicular to p turned to the unit part of r_E perpendicular to r_S: the panel charges and the face looks
away from the Earth. In the paper's layout (p = k_B, f = -j_B) that is k_B = r_S, j_B = the Earth side of r_S
(antenna on the Earth side), i_B = j_B x k_B (the +i_B sensor perpendicular to the sun, outside its keep-out
cone). The laws know no pointing constraint: with another layout a law may cross a cone, and its trajectory is
then no witness (every candidate is checked against every enforced group). Laws (tried in LAWS order):

- `sun_safe_ff`: rate command w_ref = clip(-(kp/kd) dq_v, +-0.7 w_max) towards the sun-safe attitude,
  tracked by u = clip(s (w x H)/D + s J (w_ref - w) / (tau D), U): the gyroscopic feed-forward
  cancels w x H (H = J w - D psi, gyrostat; J w, paper), a first-order rate loop of time constant tau.
  Why: with large wheel momentum, w x D psi is as large as the PD law's rate-loop torque and drags
  the rates past w_max. The drift is taken at the hold's middle (one predictor step), and each wheel's
  acceleration is clipped so that its speed stays within psi_max at the hold's end (psi_dot = u).
- `hold`: the same with w_ref = 0 (stop and hold the attitude).
- `sun_safe`: the PD law of the primary controller aimed at the sun-safe attitude,
  u = clip(s psi_dot_max tanh(-kp dq_v - kd w), U) (dq sign-fixed to the shorter rotation).

s is the config's torque sign; kp, kd, psi_dot_max are the config's controller gains and actuator limit.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.dynamics.environment import EARTH_HILL
from rta_attitude.viability.model import constraint_values, exact_step, sun_hill
from rta_attitude.viability.params import N_X, OracleModel, substep_times

Array = NDArray[np.float64]

LAWS: tuple[str, ...] = ("sun_safe_ff", "hold", "sun_safe")
"""Warm-start laws, in the order they are tried."""
RATE_LIMIT_FRACTION = 0.7
"""The feed-forward laws command |w_ref_i| <= this fraction of w_max."""
RATE_TIME_CONSTANT_S = 2.0
"""Rate-loop time constant of the feed-forward laws, s."""
WHEEL_SPEED_RTOL = 1e-12
"""The feed-forward laws keep each wheel's speed within (1 - this) psi_max at their hold's end."""


def quat_product(q: Array, p: Array) -> Array:
    """q (x) p = [q4 p_v + p4 q_v - q_v x p_v; q4 p4 - q_v . p_v], so A(q (x) p) = A(q) A(p)."""
    qv, q4, pv, p4 = q[:3], q[3], p[:3], p[3]
    return np.concatenate([q4 * pv + p4 * qv - np.cross(qv, pv), [q4 * p4 - qv @ pv]])


def quat_from_matrix(a: Array) -> Array:
    """The unit quaternion (scalar last, q4 >= 0) with attitude_matrix(q) == a (Shepperd)."""
    tr = float(np.trace(a))
    i = int(np.argmax([a[0, 0], a[1, 1], a[2, 2], tr]))
    q = np.empty(4)
    if i == 3:
        q[3] = 0.5 * math.sqrt(1.0 + tr)
        f = 0.25 / q[3]
        q[0], q[1], q[2] = (a[1, 2] - a[2, 1]) * f, (a[2, 0] - a[0, 2]) * f, (a[0, 1] - a[1, 0]) * f
    else:
        j, k = (i + 1) % 3, (i + 2) % 3
        q[i] = 0.5 * math.sqrt(1.0 + 2.0 * a[i, i] - tr)
        f = 0.25 / q[i]
        q[j], q[k], q[3] = (a[i, j] + a[j, i]) * f, (a[i, k] + a[k, i]) * f, (a[j, k] - a[k, j]) * f
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def _triad(a: Array, b: Array) -> tuple[Array, Array, Array]:
    """The right-handed orthonormal triad (a, b', a x b') of a unit vector a and b' the unit part of b
    perpendicular to a."""
    b = b - (b @ a) * a
    b = b / np.linalg.norm(b)
    return a, b, np.cross(a, b)


def sun_safe_matrix(theta_S_rad: float, m: OracleModel) -> Array:
    """The sun-safe attitude A (Hill -> body, (3, 3); its rows are the body axes in Hill), module docstring:
    A r_S = p and A r_E_perp = -f_perp (p the panel's normal, f the face's, r_E_perp and f_perp the unit parts of
    r_E and -f perpendicular to r_S and p). At a Sun-Earth conjunction (r_E parallel to r_S) r_E_perp is taken as
    z_Hill x r_S (in its orbit-plane part); with the face along the panel, f_perp is the body axis farthest from p
    made perpendicular to it."""
    s = sun_hill(theta_S_rad, m)
    e = np.array(EARTH_HILL)
    j = e - (e @ s) * s
    if np.linalg.norm(j) < 1e-6:
        j = np.array([-s[1], s[0], 0.0])
    p = np.array(m.panel_normal_body)
    g = -np.array(m.face_normal_body)
    if np.linalg.norm(g - (g @ p) * p) < 1e-6:
        g = np.eye(3)[int(np.argmin(np.abs(p)))]
    j = j / np.linalg.norm(j)
    hill = (s, j, np.cross(s, j))
    body = _triad(p, g)
    return np.outer(body[0], hill[0]) + np.outer(body[1], hill[1]) + np.outer(body[2], hill[2])


def attitude_error(x: Array, m: OracleModel) -> Array:
    """dq_v (3,) of dq = q (x) q_c^-1 towards the sun-safe attitude q_c, sign so that dq4 >= 0."""
    qc = quat_from_matrix(sun_safe_matrix(float(x[12]), m))
    dq = quat_product(x[0:4], np.array([-qc[0], -qc[1], -qc[2], qc[3]]))
    return -dq[:3] if dq[3] < 0 else dq[:3]


def law_command(x: Array, law: str, m: OracleModel, rate_limit_fraction: float = RATE_LIMIT_FRACTION) -> Array:
    """The command (3,) of a warm-start law at state x (13,), inside U; `rate_limit_fraction` bounds the
    feed-forward laws' rate command (a test sets the filter's backup law's to compare the two)."""
    s, J, D = m.torque_sign, m.J, m.wheel_inertia_kgm2
    w = x[4:7]
    if law == "sun_safe":
        u = s * m.wheel_accel_max_rad_s2 * np.tanh(-m.kp * attitude_error(x, m) - m.kd * w)
        return np.clip(u, -m.u_max, m.u_max)
    if law == "hold":
        w_ref = np.zeros(3)
    elif law == "sun_safe_ff":
        lim = rate_limit_fraction * m.omega_max_rad_s
        w_ref = np.clip(-(m.kp / m.kd) * attitude_error(x, m), -lim, lim)
    else:
        raise ValueError(f"unknown law {law!r}; known: {', '.join(LAWS)}")
    psi = x[7:10]
    top = (1.0 - WHEEL_SPEED_RTOL) * m.psi_keep_rad_s

    def inertia(v: Array) -> Array:  # J v: J_i v_i on principal axes, the tensor's product with products
        return J * v if m.principal else m.J_matrix @ v

    A = m.A  # the wheels' spin axes: body torque s D A u, momentum -s D A psi

    def held(w_d: Array, psi_d: Array) -> Array:  # the command cancelling the drift of state (w_d, psi_d)
        h = inertia(w_d) - D * (A @ psi_d) if m.gyrostat else inertia(w_d)
        u = s * np.cross(w_d, h) / D + s * inertia(w_ref - w) / (RATE_TIME_CONSTANT_S * D)
        u = u if m.wheels_on_body_axes else np.linalg.solve(A, u)  # the wheels that give that torque
        u = np.clip(u, (-top - psi) / m.dt_s, (top - psi) / m.dt_s)  # each wheel within psi_max at the hold's end
        return np.clip(u, -m.u_max, m.u_max)

    # as the backup law: the drift at the hold's middle, one predictor step of the command at its start
    u0 = held(w, psi)
    torque = -np.cross(w, inertia(w) - D * (A @ psi) if m.gyrostat else inertia(w)) + s * D * (A @ u0)
    w_dot = torque / J if m.principal else np.linalg.solve(m.J_matrix, torque)
    return held(w + 0.5 * m.dt_s * w_dot, psi + 0.5 * m.dt_s * u0)


def simulate_law(x0: Array, steps: int, m: OracleModel, law: str,
                 stop_enforce: tuple[str, ...] | None = None, t0_s: float = 0.0) -> tuple[Array, Array, Array]:
    """Closed loop of a law (command at each sample, held over the step), exact model, from x0 at time t0_s (s).

    With `stop_enforce`, stops after the first step in which an enforced constraint has h < 0 at a
    substep (the arrays are then shorter).

    Returns:
        (u (k, 3), samples (k + 1, 13), substep states (k * substeps, 13)), k = steps simulated.
    """
    S = m.substeps
    us = np.empty((steps, 3))
    xs = np.empty((steps + 1, N_X))
    subs = np.empty((steps * S, N_X))
    xs[0] = x0
    step = exact_step(m)
    times = substep_times(t0_s, steps * S + 1, m)[1:]
    for k in range(steps):
        us[k] = law_command(xs[k], law, m)
        xn, sb = step(xs[k], us[k])
        xs[k + 1] = np.asarray(xn).ravel()
        subs[k * S:(k + 1) * S] = np.asarray(sb).T
        if stop_enforce:
            h = constraint_values(subs[k * S:(k + 1) * S], m, times[k * S:(k + 1) * S])
            if any(float(np.min(h[g])) < 0.0 for g in stop_enforce):
                return us[:k + 1], xs[:k + 2], subs[:(k + 1) * S]
    return us, xs, subs


__all__ = ["LAWS", "RATE_LIMIT_FRACTION", "RATE_TIME_CONSTANT_S", "attitude_error",
           "law_command", "quat_from_matrix", "quat_product", "simulate_law", "sun_safe_matrix"]
