"""The spacecraft plant of SPEC.md sec. 2 as a control-affine system x_dot = f(x) + g(x) u.

Batch-first: every function takes states (..., 19) and returns (..., k). u = psi_dot (rad/s^2).

- attitude: q_dot = 1/2 Xi(q) omega; J omega_dot + omega x J omega = tau, tau = sign D u;
- wheels: psi_dot = u;
- sun: theta_S_dot = -n, r_S = [cos b cos theta_S, cos b sin theta_S, sin b] (Hill, b the beta angle);
  Earth: r_E = [-1, 0, 0];
- thermal node on the configured face (the paper's -j_B): T_dot = (q_solar + q_albedo + q_IR - q_rejected) / (m c_p);
- battery: E_dot = P_I I_d A_panel max(0, cos theta_SI) - P_out, the configured panel (the paper's +k_B);
- translation: unforced Clohessy-Wiltshire (carried, not constrained).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from oracles import quaternion as quat
from rta_attitude.config.schema import Config
from rta_attitude.dynamics.state import CONTROL_SIZE, CW, ENERGY, OMEGA, PSI, STATE_SIZE, TEMP, THETA_S, Q

Array = NDArray[np.float64]

EARTH_DIRECTION_HILL = np.array([-1.0, 0.0, 0.0])
"""Unit vector from the spacecraft to the Earth (and the ground station), Hill frame."""

def face_normal(cfg: Config) -> Array:
    """The thermal node's face, outward normal in body axes (3,) (the paper's -j_B)."""
    return np.array(cfg.thermal.face_normal_body, dtype=float)


def panel_normal(cfg: Config) -> Array:
    """The solar panel's normal in body axes (3,) (the paper's +k_B)."""
    return np.array(cfg.power.panel_normal_body, dtype=float)


def sun_direction(theta_S_rad: Array, beta_rad: float = 0.0) -> Array:
    """r_S (..., 3): unit vector to the sun in Hill, from theta_S (...) and the beta angle."""
    th = np.asarray(theta_S_rad, dtype=float)
    cb = np.cos(beta_rad)
    return np.stack([cb * np.cos(th), cb * np.sin(th), np.full_like(th, np.sin(beta_rad))], axis=-1)


def sun_direction_rates(theta_S_rad: Array, n_rad_s: float, beta_rad: float = 0.0) -> tuple[Array, Array]:
    """(r_S_dot, r_S_ddot) (..., 3) with theta_S_dot = -n; 1/s and 1/s^2."""
    th = np.asarray(theta_S_rad, dtype=float)
    zero = np.zeros_like(th)
    cb = np.cos(beta_rad)
    dot = -n_rad_s * cb * np.stack([-np.sin(th), np.cos(th), zero], axis=-1)
    ddot = -(n_rad_s**2) * cb * np.stack([np.cos(th), np.sin(th), zero], axis=-1)
    return dot, ddot


def wheel_rate(omega_rad_s: Array, psi_rad_s: Array, cfg: Config, model: str) -> Array:
    """The wheels' gyroscopic term of omega_dot (..., 3), rad/s^2: s D (omega x psi) / J for the
    `gyrostat` model (the wheels hold -s D psi), zeros for the paper's. The oracle has no rotating Hill
    frame nor gravity gradient: asking for them is an error, not a silent disagreement."""
    env = cfg.environment
    if env.rotating_hill or env.gravity_gradient:
        raise NotImplementedError("the numpy oracle models neither the rotating Hill frame nor gravity gradient")
    w, p = np.asarray(omega_rad_s, dtype=float), np.asarray(psi_rad_s, dtype=float)
    if model == "paper":
        return np.zeros(np.broadcast_shapes(w.shape, p.shape))
    sc = cfg.spacecraft
    return sc.torque_sign * sc.wheel_inertia_kgm2 * np.cross(w, p) / sc.J


def gyroscopic_rate(omega_rad_s: Array, J_kgm2: Array) -> Array:
    """Drift of Euler's equations (..., 3), rad/s^2: ((J2-J3) w2 w3 / J1, (J3-J1) w3 w1 / J2, ...)."""
    w1, w2, w3 = omega_rad_s[..., 0], omega_rad_s[..., 1], omega_rad_s[..., 2]
    J1, J2, J3 = J_kgm2
    return np.stack([(J2 - J3) * w2 * w3 / J1, (J3 - J1) * w3 * w1 / J2, (J1 - J2) * w1 * w2 / J3], axis=-1)


def face_cosine(A: Array, normal_body: Array, direction_hill: Array) -> Array:
    """cos of the angle between a body-fixed axis and a Hill-frame direction (...).

    Args:
        A: attitude matrices (..., 3, 3), Hill -> body.
        normal_body: the body axis (3,), unit.
        direction_hill: target directions (..., 3) or (3,), unit.
    """
    axis_hill = np.einsum("i,...ij->...j", normal_body, A)  # A^T e
    return np.sum(axis_hill * direction_hill, axis=-1)


def thermal_fluxes(cos_sun: Array, cos_earth: Array, T_K: Array, cfg: Config) -> Array:
    """Net heat flow into the -j_B face node (...), W, given its sun and Earth incidence cosines."""
    th, env = cfg.thermal, cfg.environment
    F_E = env.earth_view_factor * (np.maximum(0.0, cos_earth) if th.clamp_view_factor else cos_earth)
    sigma_eps_A = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2
    q_solar = th.absorptivity * th.area_m2 * env.solar_constant_W_m2 * np.maximum(0.0, cos_sun)
    q_albedo = th.absorptivity * th.area_m2 * env.solar_constant_W_m2 * env.albedo_factor * F_E
    q_ir = sigma_eps_A * F_E * env.earth_temperature_K**4
    q_rejected = sigma_eps_A * np.asarray(T_K, dtype=float) ** 4
    return q_solar + q_albedo + q_ir - q_rejected


def temperature_rate(x: Array, cfg: Config) -> Array:
    """T_dot (...), K/s."""
    A = quat.attitude_matrix(x[..., Q])
    cos_sun = face_cosine(A, face_normal(cfg), sun_direction(x[..., THETA_S], cfg.environment.sun_beta_rad))
    cos_earth = face_cosine(A, face_normal(cfg), EARTH_DIRECTION_HILL)
    heat_capacity = cfg.thermal.mass_kg * cfg.thermal.specific_heat_J_kgK
    return thermal_fluxes(cos_sun, cos_earth, x[..., TEMP], cfg) / heat_capacity


def net_power(cos_panel_sun: Array, cfg: Config) -> Array:
    """E_dot (...), W: panel power minus the load."""
    return cfg.power.peak_W * np.maximum(0.0, cos_panel_sun) - cfg.power.load_W


def drift(x: Array, cfg: Config) -> Array:
    """f(x) (..., 19): the state derivative with u = 0."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        return _drift_one(x, cfg)
    q, w = x[..., Q], x[..., OMEGA]
    q1, q2, q3, q4 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    f = np.zeros(x.shape)
    f[..., Q] = quat.kinematics(q, w)
    J1, J2, J3 = cfg.spacecraft.inertia_kgm2
    w1, w2, w3 = w[..., 0], w[..., 1], w[..., 2]
    f[..., OMEGA.start] = (J2 - J3) * w2 * w3 / J1
    f[..., OMEGA.start + 1] = (J3 - J1) * w3 * w1 / J2
    f[..., OMEGA.start + 2] = (J1 - J2) * w1 * w2 / J3
    f[..., OMEGA] += wheel_rate(w, x[..., PSI], cfg, cfg.spacecraft.model)
    cos_sun, cos_earth, cos_panel = _incidences(q1, q2, q3, q4, x[..., THETA_S], cfg)
    heat_capacity = cfg.thermal.mass_kg * cfg.thermal.specific_heat_J_kgK
    f[..., TEMP] = thermal_fluxes(cos_sun, cos_earth, x[..., TEMP], cfg) / heat_capacity
    f[..., ENERGY] = net_power(cos_panel, cfg)
    n = cfg.environment.mean_motion_rad_s
    f[..., THETA_S] = -n
    cw = x[..., CW]
    f[..., CW.start:CW.start + 3] = cw[..., 3:6]
    f[..., CW.start + 3] = 3 * n**2 * cw[..., 0] + 2 * n * cw[..., 4]
    f[..., CW.start + 4] = -2 * n * cw[..., 3]
    f[..., CW.start + 5] = -(n**2) * cw[..., 2]
    return f


def _incidences(q1: Any, q2: Any, q3: Any, q4: Any, theta_S: Any, cfg: Config) -> tuple[Any, Any, Any]:
    """(cos face-sun, cos face-Earth, cos panel-sun) from the quaternion's entries and theta_S (floats or
    arrays: the same operations either way). A body axis e in Hill is A^T e, A(q) of Markley & Crassidis."""
    a = ((q1 * q1 - q2 * q2 - q3 * q3 + q4 * q4, 2.0 * (q1 * q2 + q3 * q4), 2.0 * (q1 * q3 - q2 * q4)),
         (2.0 * (q1 * q2 - q3 * q4), -q1 * q1 + q2 * q2 - q3 * q3 + q4 * q4, 2.0 * (q2 * q3 + q1 * q4)),
         (2.0 * (q1 * q3 + q2 * q4), 2.0 * (q2 * q3 - q1 * q4), -q1 * q1 - q2 * q2 + q3 * q3 + q4 * q4))
    beta = cfg.environment.sun_beta_rad
    sun = (np.cos(beta) * np.cos(theta_S), np.cos(beta) * np.sin(theta_S), np.sin(beta))

    def along(e: tuple[float, ...], d: tuple[Any, ...]) -> Any:
        return sum(e[i] * a[i][j] * d[j] for i in range(3) for j in range(3) if e[i] != 0.0)

    face, panel = cfg.thermal.face_normal_body, cfg.power.panel_normal_body
    return along(face, sun), along(face, tuple(EARTH_DIRECTION_HILL)), along(panel, sun)


def _drift_one(x: Array, cfg: Config) -> Array:
    """`drift` of one state (19,) on Python floats: the same operations in the same order as the
    batch version (bit-identical results; `test_batch_equals_single`), ~6x faster for one state,
    which is what the plant integrates 40 times per step."""
    q1, q2, q3, q4, w1, w2, w3 = (float(v) for v in x[0:7])
    J1, J2, J3 = cfg.spacecraft.inertia_kgm2
    cos_sun, cos_earth, cos_panel = _incidences(q1, q2, q3, q4, float(x[THETA_S]), cfg)
    heat_capacity = cfg.thermal.mass_kg * cfg.thermal.specific_heat_J_kgK
    T_dot = float(thermal_fluxes(cos_sun, cos_earth, float(x[TEMP]), cfg)) / heat_capacity
    n = cfg.environment.mean_motion_rad_s
    px, _py, pz, vx, vy, vz = (float(v) for v in x[CW])
    wr = wheel_rate(x[OMEGA], x[PSI], cfg, cfg.spacecraft.model)
    return np.array([
        0.5 * (q4 * w1 - q3 * w2 + q2 * w3), 0.5 * (q3 * w1 + q4 * w2 - q1 * w3),
        0.5 * (-q2 * w1 + q1 * w2 + q4 * w3), -0.5 * (q1 * w1 + q2 * w2 + q3 * w3),
        (J2 - J3) * w2 * w3 / J1 + wr[0], (J3 - J1) * w3 * w1 / J2 + wr[1], (J1 - J2) * w1 * w2 / J3 + wr[2],
        0.0, 0.0, 0.0,
        T_dot, float(net_power(cos_panel, cfg)), -n,
        vx, vy, vz, 3 * n**2 * px + 2 * n * vy, -2 * n * vx, -(n**2) * pz,
    ])  # fmt: skip


def control_matrix(x: Array, cfg: Config) -> Array:
    """g(x) (..., 19, 3): constant; omega rows sign D / J_i, psi rows identity."""
    x = np.asarray(x, dtype=float)
    g = np.zeros((*x.shape[:-1], STATE_SIZE, CONTROL_SIZE))
    g[..., OMEGA, :] = np.diag(cfg.spacecraft.control_gain)
    g[..., PSI, :] = np.eye(3)
    return g


def state_derivative(x: Array, u: Array, cfg: Config) -> Array:
    """x_dot = f(x) + g u (..., 19), u (..., 3) in rad/s^2."""
    f = drift(x, cfg)
    u = np.asarray(u, dtype=float)
    f[..., OMEGA] += cfg.spacecraft.control_gain * u
    f[..., PSI] += u
    return f


def omega_dot(x: Array, u: Array, cfg: Config) -> Array:
    """Body angular acceleration (..., 3), rad/s^2, for wheel accelerations u."""
    return gyroscopic_rate(np.asarray(x)[..., OMEGA], cfg.spacecraft.J) + cfg.spacecraft.control_gain * u


def wheel_accel_to_torque(u_rad_s2: Array, cfg: Config) -> Array:
    """Body torque tau = sign D u (..., 3), N m: what crosses DDS as a command."""
    return cfg.spacecraft.torque_sign * cfg.spacecraft.wheel_inertia_kgm2 * np.asarray(u_rad_s2, dtype=float)


def torque_to_wheel_accel(tau_Nm: Array, cfg: Config) -> Array:
    """Wheel accelerations u = tau / (sign D) (..., 3), rad/s^2."""
    return np.asarray(tau_Nm, dtype=float) / (cfg.spacecraft.torque_sign * cfg.spacecraft.wheel_inertia_kgm2)


def through_torque_interface(u_rad_s2: Array, cfg: Config) -> Array:
    """u after the round trip u -> tau -> u that every DDS command makes (bit-exact with the nodes)."""
    return torque_to_wheel_accel(wheel_accel_to_torque(u_rad_s2, cfg), cfg)


__all__ = [
    "EARTH_DIRECTION_HILL", "control_matrix", "drift", "face_cosine", "face_normal", "gyroscopic_rate", "net_power",
    "omega_dot", "panel_normal", "state_derivative", "sun_direction", "sun_direction_rates", "temperature_rate",
    "thermal_fluxes", "through_torque_interface", "torque_to_wheel_accel", "wheel_accel_to_torque",
]  # fmt: skip
