"""The oracle's own model of the plant (casadi), its exact re-simulation and its constraint values.

Written from the equations (docs/viability.md), not from the plant's compiled code, so the test
suite can hold it against the project's plant (`dynamics.spacecraft`, the code the simulator runs)
as an independent check. State (13,) = the project's first 13 entries; u = psi_dot (rad/s^2)::

    A(q)      = (q4^2 - |qv|^2) I + 2 qv qv^T - 2 q4 [qv x]              (Hill -> body)
    q_dot     = 1/2 Xi(q) (omega - n_f A [0, 0, 1])
    J w_dot   = -w x (J w - D psi) + s D u + tau_gg      gyrostat;  -w x J w + s D u + tau_gg   paper
    psi_dot   = u,   theta_S_dot = -n
    T_dot     = (aAS max(0, c_S) + (aAS A_f + sigma eps A T_E^4) F max(0, c_E) - sigma eps A T^4) / (m c_p)
    E_dot     = P_peak max(0, c_panel) - P_out

c_S, c_E: the thermal face's normal f (`thermal.face_normal_body`) against the sun and the Earth, f . A r_S and
f . A r_E; c_panel: the panel's normal (`power.panel_normal_body`) against the sun. r_S, r_E and every cone's
target are `dynamics.environment`'s (the sun with its beta angle, nadir, ...), theta_S the state's x[12].

One zero-order-hold step is `substeps` classical RK4 steps, the quaternion renormalised after each
(as the plant). `exact` expressions use max(0, .) itself; inside the optimiser the heat input uses a
smooth upper bound and the panel power a smooth lower bound of it (`smooth_over`, `smooth_under`), so
for one attitude history the optimiser's T is >= and its E is <= the exact ones.

Constraint values h (safe >= 0), natural units, per group (`constraint_values`): a keep_out cone
angle(e, r) - alpha, a keep_in cone alpha - angle(e, r) (rad; e its boresight, r its target in body axes, +inf
at times outside its windows); temperature T_max - T (K); battery E - E_min (J); the rates w_max - max_i |w_i|
and the wheels psi_max - max_i |psi_i| (rad/s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from rta_attitude.dynamics.environment import EARTH_HILL, INERTIAL_FIXED, SUN, sun_direction, target_direction
from rta_attitude.viability.params import (
    BATTERY,
    KEEP_IN,
    N_X,
    POINTING_KINDS,
    RATE,
    TEMPERATURE,
    WHEEL_SPEED,
    OracleCone,
    OracleModel,
    substep_times,
)

Array = NDArray[np.float64]

SMOOTH_EPS = 1e-3
"""Width of the smooth max(0, .) inside the optimiser (cosine units)."""


# ----------------------------------------------------------------------------- numpy
def attitude_matrix(q: Array) -> Array:
    """A(q) (3, 3), Hill -> body, scalar-last quaternion (unit)."""
    qv, q4 = q[:3], q[3]
    cx = np.array([[0.0, -qv[2], qv[1]], [qv[2], 0.0, -qv[0]], [-qv[1], qv[0], 0.0]])
    return (q4 * q4 - qv @ qv) * np.eye(3) + 2.0 * np.outer(qv, qv) - 2.0 * q4 * cx


def sun_hill(theta_S_rad: float, m: OracleModel) -> Array:
    """r_S (3,) in Hill at theta_S, with the configured beta angle (`dynamics.environment.sun_direction`)."""
    return sun_direction(float(theta_S_rad), m.sun_beta_rad)


def along(e: Sequence[float] | Array, v: Array) -> Array:
    """e . v over the last axis of body vectors v (..., 3) for a body axis e (3,); a zero component of e adds no
    term and a unit one reads v's component as it is (an axis along a body axis costs one entry of v)."""
    out = None
    for i in range(3):
        if e[i] == 0.0:
            continue
        term = v[..., i] if e[i] == 1.0 else (-v[..., i] if e[i] == -1.0 else e[i] * v[..., i])
        out = term if out is None else out + term
    return np.zeros(np.shape(v)[:-1]) if out is None else out


def _rotate(xs: Array, v: Array) -> Array:
    """A(q_k) v_k for a batch of states xs (n, 13) and vectors v (n, 3)."""
    qv, q4 = xs[:, 0:3], xs[:, 3]
    return ((q4**2 - np.sum(qv * qv, axis=1))[:, None] * v + 2.0 * qv * np.sum(qv * v, axis=1)[:, None]
            - 2.0 * q4[:, None] * np.cross(qv, v))


def cone_cos(xs: Array, cone: OracleCone, m: OracleModel) -> Array:
    """cos of the angle between a cone's boresight and its target (n,), at states xs (n, 13)."""
    r = target_direction(cone.target_kind, np.array(cone.target_vector), xs[:, 12], m.sun_beta_rad)
    return along(cone.boresight_body, _rotate(xs, r))


def constraint_values(xs: Array, m: OracleModel, t_s: float | Array = 0.0) -> dict[str, Array]:
    """h (n,) of every constraint group (`OracleModel.groups`) at states xs (n, 13) or (13,) and times t_s (s,
    broadcast to (n,); they matter to windowed cones only), natural units (module docstring)."""
    xs = np.atleast_2d(np.asarray(xs, dtype=float))
    out: dict[str, Array] = {}
    for group in m.groups:
        kind = m.kind(group)
        if kind in POINTING_KINDS:
            cone = m.cone(group)
            theta = np.arccos(np.clip(cone_cos(xs, cone, m), -1.0, 1.0))
            h = cone.half_angle_rad - theta if kind == KEEP_IN else theta - cone.half_angle_rad
            if cone.windows_s:
                h = np.where(cone.applies(np.broadcast_to(np.asarray(t_s, dtype=float), h.shape)), h, np.inf)
            out[group] = h
        elif kind == TEMPERATURE:
            out[group] = m.temperature_max_K - xs[:, 10]
        elif kind == BATTERY:
            out[group] = xs[:, 11] - m.energy_min_J
        elif kind == RATE:
            out[group] = m.omega_max_rad_s - np.max(np.abs(xs[:, 4:7]), axis=1)
        elif kind == WHEEL_SPEED:
            speed = xs[:, 7:10] + xs[:, 4:7] @ m.A if m.wheel_speed_relative else xs[:, 7:10]  # psi_i + a_i . w
            out[group] = m.psi_max_rad_s - np.max(np.abs(speed), axis=1)
        else:
            raise ValueError(f"constraint group {group!r} has kind {kind!r}, which the oracle does not model")
    return out


def min_margins(x0: Array, subs: Array, m: OracleModel, t0_s: float = 0.0) -> dict[str, float]:
    """The smallest h of every group over x0 (at time t0_s) and the substep states subs (k, 13) after it."""
    states = np.vstack([x0[None, :], subs])
    vals = constraint_values(states, m, substep_times(t0_s, len(states), m))
    return {g: float(np.min(vals[g])) for g in m.groups}


def is_safe(margins: dict[str, float], enforce: tuple[str, ...]) -> bool:
    """Every enforced group has h >= 0."""
    return all(margins[g] >= 0.0 for g in enforce)


def worst_normalised(margins: dict[str, float], enforce: tuple[str, ...], m: OracleModel) -> float:
    """min over the enforced groups of h / scale (the best candidate has the largest)."""
    return min((margins[g] / m.scale(g) for g in enforce), default=np.inf)


# ----------------------------------------------------------------------------- casadi
def smooth_over(z: ca.SX) -> ca.SX:
    """C^1 upper bound of max(0, z): 0 for z <= -eps, (z + eps)^2 / (4 eps) on |z| < eps, z above
    ((z + eps)^2 / (4 eps) - z = (z - eps)^2 / (4 eps) >= 0); error <= eps/4, exactly 0 for |z| >= eps."""
    e = SMOOTH_EPS
    return ca.if_else(z <= -e, 0.0, ca.if_else(z >= e, z, (z + e) ** 2 / (4.0 * e)))


def smooth_under(z: ca.SX) -> ca.SX:
    """C^1 lower bound of max(0, z): 0 for z <= 0, z^2 / (2 eps) on (0, eps), z - eps/2 above;
    error <= eps/2, exactly 0 for z <= 0 (no spurious power in the dark)."""
    e = SMOOTH_EPS
    return ca.if_else(z <= 0.0, 0.0, ca.if_else(z >= e, z - 0.5 * e, z * z / (2.0 * e)))


def ca_attitude(q: ca.SX) -> ca.SX:
    """A(q) as a casadi expression."""
    qv, q4 = q[0:3], q[3]
    return (q4 * q4 - ca.dot(qv, qv)) * ca.SX.eye(3) + 2.0 * (qv @ qv.T) - 2.0 * q4 * ca.skew(qv)


def ca_along(e: Sequence[float] | Array, v: ca.SX) -> ca.SX:
    """e . v for a body axis e (3,) and a body vector expression v (3,), as `along` (zero components of e add
    no term, unit ones read v's entry as it is)."""
    out = None
    for i in range(3):
        if e[i] == 0.0:
            continue
        term = v[i] if e[i] == 1.0 else (-v[i] if e[i] == -1.0 else e[i] * v[i])
        out = term if out is None else out + term
    return ca.SX(0.0) if out is None else out


def _times(c: float, z: ca.SX) -> ca.SX:
    return z if c == 1.0 else c * z


def ca_sun_hill(theta_S: ca.SX, m: OracleModel) -> ca.SX:
    """r_S in Hill, [cos beta cos theta_S, cos beta sin theta_S, sin beta] (`dynamics.environment.sun_hill`)."""
    cb = m.sun_cos_beta
    return ca.vertcat(_times(cb, ca.cos(theta_S)), _times(cb, ca.sin(theta_S)), m.sun_sin_beta)


def ca_target_hill(cone: OracleCone, theta_S: ca.SX, m: OracleModel) -> ca.SX | ca.DM:
    """A cone's target in Hill at theta_S (`dynamics.environment.target_direction`): the sun; a vector fixed in
    the inertial frame, R_z(theta_S) v; else the fixed Hill vector."""
    v = cone.target_vector
    if cone.target_kind == SUN:
        return ca_sun_hill(theta_S, m)
    if cone.target_kind == INERTIAL_FIXED:
        c, s = ca.cos(theta_S), ca.sin(theta_S)
        return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])
    return ca.DM(v)


def ca_cone_cos(x: ca.SX, a: ca.SX, cone: OracleCone, m: OracleModel) -> ca.SX:
    """cos(angle(boresight, target)) = e . A r of a state expression x (13,) with attitude matrix a = A(q)."""
    return ca_along(cone.boresight_body, a @ ca_target_hill(cone, x[12], m))


def ca_dynamics(m: OracleModel, exact: bool) -> ca.Function:
    """x_dot (13,) of (x, u); `exact`: max(0, .) itself, else the smooth bounds (module docstring)."""
    x = ca.SX.sym("x", N_X)
    u = ca.SX.sym("u", 3)
    q, w, psi, temp = x[0:4], x[4:7], x[7:10], x[10]
    a = ca_attitude(q)
    s_b = a @ ca_sun_hill(x[12], m)
    e_b = a @ ca.DM(EARTH_HILL)
    # J (x) as J_i x_i on principal axes, J @ x with products of inertia
    jd = ca.DM(m.inertia_kgm2) if m.principal else ca.DM(m.J_matrix)
    inertia = (lambda v: jd * v) if m.principal else (lambda v: jd @ v)
    d = m.wheel_inertia_kgm2
    wheels = (lambda v: v) if m.wheels_on_body_axes else (lambda v: ca.DM(m.A) @ v)  # A v: along the body axes
    h = inertia(w) - d * wheels(psi) if m.gyrostat else inertia(w)
    torque = -ca.cross(w, h) + m.torque_sign * d * wheels(u)
    if m.gravity_gradient:
        r = a[:, 0]
        torque = torque + 3.0 * m.mean_motion_rad_s**2 * ca.cross(r, inertia(r))
    w_rel = w - m.frame_rate_rad_s * a[:, 2] if m.frame_rate_rad_s != 0.0 else w
    q1, q2, q3, q4 = q[0], q[1], q[2], q[3]
    xi = ca.vertcat(ca.horzcat(q4, -q3, q2), ca.horzcat(q3, q4, -q1), ca.horzcat(-q2, q1, q4),
                    ca.horzcat(-q1, -q2, -q3))
    over = (lambda z: ca.fmax(0.0, z)) if exact else smooth_over
    under = (lambda z: ca.fmax(0.0, z)) if exact else smooth_under
    c_earth = ca_along(m.face_normal_body, e_b)
    view = m.earth_view_factor * (over(c_earth) if m.clamp_view_factor else c_earth)
    # the Earth's shadow (`environment.sunlit`): a function of theta_S, i.e. of time; 1.0 without an eclipse
    lit = ca.if_else(m.sun_cos_beta * ca.cos(x[12]) < m.shadow_sx, 0.0, 1.0) if math.isfinite(m.shadow_sx) else 1.0
    t_dot = (lit * m.solar_W * over(ca_along(m.face_normal_body, s_b))
             + (lit * m.albedo_W + m.sigma_eps_A_W_K4 * m.earth_T4_K4) * view
             - m.sigma_eps_A_W_K4 * temp**4) / m.heat_capacity_J_K
    e_dot = lit * m.panel_peak_W * under(ca_along(m.panel_normal_body, s_b)) - m.load_W
    w_dot = torque / jd if m.principal else ca.DM(np.linalg.inv(m.J_matrix)) @ torque
    xdot = ca.vertcat(0.5 * (xi @ w_rel), w_dot, u, t_dot, e_dot, -m.mean_motion_rad_s)
    return ca.Function("f", [x, u], [xdot])


def rk4_chain(f: ca.Function, x: ca.SX, u: ca.SX, m: OracleModel) -> list[ca.SX]:
    """The states after each of the `substeps` RK4 steps of one hold (q renormalised after each)."""
    h = m.dt_s / m.substeps
    out: list[ca.SX] = []
    xs = x
    for _ in range(m.substeps):
        k1 = f(xs, u)
        k2 = f(xs + 0.5 * h * k1, u)
        k3 = f(xs + 0.5 * h * k2, u)
        k4 = f(xs + h * k3, u)
        xs = xs + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        xs = ca.vertcat(xs[0:4] / ca.norm_2(xs[0:4]), xs[4:N_X])
        out.append(xs)
    return out


@lru_cache(maxsize=8)
def exact_step(m: OracleModel) -> ca.Function:
    """(x, u) -> (x after the hold, substep states (13, substeps)), exact max(0, .)."""
    x = ca.SX.sym("x", N_X)
    u = ca.SX.sym("u", 3)
    subs = rk4_chain(ca_dynamics(m, exact=True), x, u, m)
    return ca.Function("exact_step", [x, u], [subs[-1], ca.horzcat(*subs)])


@lru_cache(maxsize=32)
def _exact_sim(m: OracleModel, n_steps: int) -> ca.Function:
    return exact_step(m).mapaccum("exact_sim", n_steps)


def simulate(x0: Array, u: Array, m: OracleModel) -> tuple[Array, Array]:
    """Exact re-simulation of a command sequence u (N, 3) from x0 (13,).

    Returns:
        (samples (N+1, 13), substep states (N * substeps, 13)).
    """
    u = np.atleast_2d(np.asarray(u, dtype=float))
    if len(u) == 0:
        return np.asarray(x0, dtype=float)[None, :].copy(), np.zeros((0, N_X))
    xs, subs = _exact_sim(m, len(u))(x0, u.T)
    return np.vstack([np.asarray(x0, dtype=float)[None, :], np.asarray(xs).T]), np.asarray(subs).T.copy()


__all__ = ["SMOOTH_EPS", "along", "attitude_matrix", "ca_along", "ca_attitude", "ca_cone_cos", "ca_dynamics",
           "ca_sun_hill", "ca_target_hill", "cone_cos", "constraint_values", "exact_step", "is_safe", "min_margins",
           "rk4_chain", "simulate", "smooth_over", "smooth_under", "sun_hill", "worst_normalised"]
