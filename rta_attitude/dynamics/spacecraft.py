"""The spacecraft plant, written once: compiled one-state code that simulate, the plant node, the
Monte Carlo and the filter's barriers all call.

State x (19,), `dynamics.state`: q (Hill -> body, scalar last), omega (body rate w.r.t. inertial space,
rad/s), psi (the wheels' momentum state, rad/s), T (K), E (J), theta_S (rad), Clohessy-Wiltshire (6).
Control u = psi_dot (3,), rad/s^2; the body feels the torque s D u (s = spacecraft.torque_sign, +1 the
paper's sign) and the wheels hold the momentum -s D psi, so without external torque the inertial
angular momentum A(q)^T (J omega - s D psi) is constant (test_gyrostat, docs/gyrostat.md).

    q_dot      = 1/2 Xi(q) (omega - A(q) [0, 0, n_f])            n_f: Hill frame rate (0: Hill inertial)
    J omega_dot = -omega x (J omega - s D psi) + s D u + tau_gg   gyrostat (`wheel_gyroscopic`)
    J omega_dot = -omega x  J omega            + s D u + tau_gg   the paper's model (no wheel momentum)
    tau_gg     = 3 n^2 r x (J r),  r = A(q) [1, 0, 0]             gravity gradient (optional)
    psi_dot    = u
    theta_S_dot = -n;  r_S, r_E: `dynamics.environment` (the sun with its beta angle; nadir)
    T_dot      = (alpha A S max(0, c_S) + (alpha A S A_f + sigma eps A T_E^4) F_E - sigma eps A T^4) / (m c_p)
                 F_E = F max(0, c_E) (clamped; c_E unclamped if not), c_S, c_E: the face (thermal.face_normal_body,
                 -j_B in the paper) to sun, Earth
    E_dot      = P_I I_d A_p max(0, c_panel) - P_out               c_panel: the panel (power.panel_normal_body, +k_B)
                                                                   to the sun
    CW         : unforced Clohessy-Wiltshire at mean motion n

psi is the paper's "wheel speed" with the paper's sign (psi = -Omega, Omega the wheel's spin rate
about its axis in inertial space) and J the inertia without the rotors' spin-axis part; with those
readings the gyrostat equation above is exact for torque-commanded wheels whose motor torque is -D u
(docs/gyrostat.md). The paper's model drops the wheel term (-omega x (-s D psi)).

Parameters reach the kernels by name, as one record of PLANT_DTYPE (`plant_record`): a structured
NumPy array whose fields the compiled code reads as attributes (docs/decisions.md says why). The
paper model's arithmetic is kept operation for operation from the first implementation, so the
`paper` preset reproduces its numbers.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config import inertia
from rta_attitude.config.schema import Config
from rta_attitude.dynamics.environment import EARTH_HILL, sun_hill, sunlit
from rta_attitude.dynamics.quaternion import attitude_matrix
from rta_attitude.dynamics.state import STATE_SIZE, state_size, wheel_column
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]


@functools.cache
def plant_dtype(n_wheels: int) -> np.dtype:
    """The PLANT_DTYPE of an array of n_wheels wheels (its wheel fields sized N; compiled code is specialised per
    dtype, so the three-wheel kernels are the paper's as they were)."""
    return np.dtype([
        ("inertia_kgm2", np.float64, (3,)),        # J1 J2 J3
        ("wheel_inertia_kgm2", np.float64),        # D
        ("torque_sign", np.float64),               # s: the wheels' body torque is s D u, their momentum -s D psi
        ("control_gain", np.float64, (3,)),        # d omega_dot / d u = D / J_i
        ("wheel_gyroscopic", np.uint8),            # 1: gyrostat term -omega x (-D psi); 0: the paper's model
        ("frame_rate_rad_s", np.float64),          # n_f, rate of the Hill frame in the kinematics (0: inertial)
        ("gravity_gradient", np.uint8),            # 1: tau_gg = 3 n^2 r x J r
        ("mean_motion_rad_s", np.float64),         # n: sun motion, CW, gravity gradient
        ("heat_capacity_J_K", np.float64),         # m c_p
        ("earth_view_factor", np.float64),         # F
        ("clamp_view_factor", np.uint8),           # F_E = F max(0, c_E) (1) or F c_E (0)
        ("sigma_eps_A_W_K4", np.float64),          # sigma eps A
        ("solar_W", np.float64),                   # alpha A S
        ("albedo_W", np.float64),                  # alpha A S A_f
        ("earth_T4_K4", np.float64),               # T_E^4
        ("panel_peak_W", np.float64),              # P_I I_d A_p
        ("load_W", np.float64),                    # P_out
        ("wheel_accel_max_rad_s2", np.float64),    # actuator saturation of u
        ("sun_cos_beta", np.float64),              # the sun's beta angle (`dynamics.environment.sun_hill`)
        ("sun_sin_beta", np.float64),
        ("shadow_sx", np.float64),                 # r_S . x_Hill below it: the Earth's shadow (-inf: no eclipse)
        ("eclipse_half_arc_rad", np.float64),      # half the theta_S arc in the shadow (0: none)
        ("eclipse_ramp_W", np.float64),            # the battery floor's rise over the sunlit arc (`battery`)
        ("face_normal", np.float64, (3,)),         # the thermal node's face, outward normal, body axes
        ("panel_normal", np.float64, (3,)),        # the solar panel's normal, body axes
        ("face_axis", np.int64),                   # `signed_axis` of face_normal: i if it is +-e_i, else -1
        ("panel_axis", np.int64),                  # the same of panel_normal
        ("delay_substeps", np.int64),              # substeps of a sample the previous command still holds
        ("inertia_matrix", np.float64, (3, 3)),    # J, body axes (diag(inertia_kgm2) where principal)
        ("inertia_inverse", np.float64, (3, 3)),   # J^-1
        ("control_matrix", np.float64, (3, n_wheels)),  # G = d omega_dot / d u = s D J^-1 A
        ("wheel_axes", np.float64, (3, n_wheels)),  # A: wheel i's spin axis in body axes is column i
        ("wheel_axes_inverse", np.float64, (n_wheels, 3)),  # A^-1, the right inverse of more than three
        ("diagonal", np.uint8),                    # 1: principal axes, wheel i on body axis i (the per-axis arithmetic)
        ("wheels_on_axes", np.uint8),              # 1: wheel i on body axis i (A = I; torques convert per axis)
        ("wheel_failed", np.uint8, (n_wheels,)),   # 1: the wheel's drive gives no torque (its acceleration held at 0)
    ])  # fmt: skip


PLANT_DTYPE = plant_dtype(3)
"""The plant's parameters, in model units, as the compiled code reads them."""


def plant_record(cfg: Config, model: str | None = None) -> NDArray[np.void]:
    """The PLANT_DTYPE record (shape (1,)) of a configuration; constants formed as the first
    implementation formed them (so its numbers are reproduced).

    Args:
        cfg: the configuration.
        model: PLANT_MODELS name; None: `spacecraft.model` (the simulated plant, with `plant.inertia_kgm2`
            where set). The filter's model of the plant is `plant_record(cfg, cfg.filter.model)`.
    """
    sc, th, env, pw = cfg.spacecraft, cfg.thermal, cfg.environment, cfg.power
    rec = np.zeros(1, plant_dtype(sc.n_wheels))
    p = rec[0]
    true_J = cfg.plant.inertia_kgm2 if model is None else None  # the simulated vehicle's, where it differs
    p["inertia_kgm2"] = sc.inertia_kgm2 if true_J is None else true_J
    p["wheel_inertia_kgm2"] = sc.wheel_inertia_kgm2
    p["torque_sign"] = sc.torque_sign
    p["control_gain"] = sc.control_gain if true_J is None else replace(sc, inertia_kgm2=true_J).control_gain
    p["wheel_gyroscopic"] = 1 if (sc.model if model is None else model) == "gyrostat" else 0
    p["frame_rate_rad_s"] = env.mean_motion_rad_s if env.rotating_hill else 0.0
    p["gravity_gradient"] = 1 if env.gravity_gradient else 0
    p["mean_motion_rad_s"] = env.mean_motion_rad_s
    p["heat_capacity_J_K"] = th.mass_kg * th.specific_heat_J_kgK
    p["earth_view_factor"] = env.earth_view_factor
    p["clamp_view_factor"] = 1 if th.clamp_view_factor else 0
    p["sigma_eps_A_W_K4"] = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2
    p["solar_W"] = th.absorptivity * th.area_m2 * env.solar_constant_W_m2
    p["albedo_W"] = th.absorptivity * th.area_m2 * env.solar_constant_W_m2 * env.albedo_factor
    p["earth_T4_K4"] = env.earth_temperature_K**4
    p["panel_peak_W"] = pw.peak_W
    p["load_W"] = pw.load_W
    p["wheel_accel_max_rad_s2"] = cfg.limits.wheel_accel_max_rad_s2
    p["sun_cos_beta"], p["sun_sin_beta"] = math.cos(env.sun_beta_rad), math.sin(env.sun_beta_rad)
    p["shadow_sx"] = env.shadow_sx
    p["eclipse_half_arc_rad"] = env.eclipse_half_arc_rad
    p["eclipse_ramp_W"] = cfg.eclipse_ramp_W
    p["face_normal"] = th.face_normal_body
    p["panel_normal"] = pw.panel_normal_body
    p["face_axis"] = signed_axis(th.face_normal_body)
    p["panel_axis"] = signed_axis(pw.panel_normal_body)
    p["delay_substeps"] = cfg.delay_substeps
    vehicle = sc if true_J is None else replace(sc, inertia_kgm2=true_J)
    p["diagonal"] = vehicle.diagonal
    p["wheels_on_axes"] = vehicle.wheels_on_body_axes
    p["inertia_matrix"] = vehicle.inertia_matrix
    p["inertia_inverse"] = vehicle.inertia_inverse
    p["control_matrix"] = vehicle.control_matrix
    p["wheel_axes"] = vehicle.wheel_axes
    p["wheel_axes_inverse"] = vehicle.wheel_axes_inverse
    p["wheel_failed"] = vehicle.wheel_failed
    return rec


def signed_axis(e: tuple[float, float, float]) -> int:
    """i if the unit vector e is +e_i or -e_i (a body axis), else -1 (`axis_along`'s fast path)."""
    nonzero = [i for i in range(3) if e[i] != 0.0]
    return nonzero[0] if len(nonzero) == 1 and abs(e[nonzero[0]]) == 1.0 else -1


# ----------------------------------------------------------------------------- geometry


@numba.njit(**LEAF, inline="always")
def axis_along(e: Array, axis: int, A: Array, r0: float, r1: float, r2: float) -> float:
    """e . (A r): the cosine between the body axis e (3,) and the Hill direction r = (r0, r1, r2) for the
    attitude matrix A (Hill -> body); axis: `signed_axis(e)`. Terms of a zero component of e or r are skipped
    (so an axis along a body axis and a target in the orbit plane cost what the paper's formulas do, to the
    last bit); a body axis (axis >= 0) takes one row of A without a loop (the plant calls this 120 times a
    sample)."""
    if axis >= 0:
        v = A[axis, 0] * r0 + A[axis, 1] * r1
        if r2 != 0.0:
            v += A[axis, 2] * r2
        return v if e[axis] > 0.0 else -v
    c = 0.0
    first = True
    for i in range(3):
        if e[i] != 0.0:
            v = A[i, 0] * r0 + A[i, 1] * r1
            if r2 != 0.0:
                v += A[i, 2] * r2
            term = v if e[i] == 1.0 else (-v if e[i] == -1.0 else e[i] * v)
            c = term if first else c + term
            first = False
    return c


@numba.njit(**LEAF)
def positive_part(c: float) -> float:
    """max(0, c) as numpy's maximum(0.0, c): 0.0 for c <= 0 (also -0.0), NaN stays NaN."""
    return c if (c > 0.0 or c != c) else 0.0


@numba.njit(**LEAF, inline="always")
def _principal_drift(x: Array, A: Array, p: np.void, out: Array) -> None:
    """`omega_drift` where diagonal (principal axes, a wheel on each)."""
    w1, w2, w3 = x[4], x[5], x[6]
    J1, J2, J3 = p.inertia_kgm2[0], p.inertia_kgm2[1], p.inertia_kgm2[2]
    t1 = (J2 - J3) * w2 * w3
    t2 = (J3 - J1) * w3 * w1
    t3 = (J1 - J2) * w1 * w2
    if p.wheel_gyroscopic or p.gravity_gradient:
        if p.wheel_gyroscopic:  # -omega x (-s D psi) = s D omega x psi
            D = p.torque_sign * p.wheel_inertia_kgm2
            p1, p2, p3 = x[7], x[8], x[9]
            t1 += D * (w2 * p3 - w3 * p2)
            t2 += D * (w3 * p1 - w1 * p3)
            t3 += D * (w1 * p2 - w2 * p1)
        if p.gravity_gradient:  # 3 n^2 r x (J r), r = zenith (+x_Hill) in body
            k = 3.0 * p.mean_motion_rad_s * p.mean_motion_rad_s
            r1, r2, r3 = A[0, 0], A[1, 0], A[2, 0]
            t1 += k * (J3 - J2) * r2 * r3
            t2 += k * (J1 - J3) * r3 * r1
            t3 += k * (J2 - J1) * r1 * r2
    out[0] = t1 / J1
    out[1] = t2 / J2
    out[2] = t3 / J3


@numba.njit(**LEAF, inline="always")
def omega_drift(x: Array, A: Array, p: np.void, out: Array) -> None:
    """omega_dot at u = 0 (3,), rad/s^2: Euler's equations, the wheels' gyroscopic term (gyrostat) and
    the gravity-gradient torque (if on). A = A(q) of x (used only with gravity gradient). On principal axes
    the arithmetic of the first implementation (`_principal_drift`); in general (products of inertia, wheels off
    the body axes)
    J^-1 (-w x (J w - s D psi) + 3 n^2 r x J r)."""
    if p.diagonal:
        _principal_drift(x, A, p, out)  # (inlined: the plant's hot path, 40 calls a step)
        return
    _general_drift(x, A, p, out)


@numba.njit(**LEAF)
def _general_drift(x: Array, A: Array, p: np.void, out: Array) -> None:
    """`omega_drift` in general."""
    J, Ji = p.inertia_matrix, p.inertia_inverse
    w1, w2, w3 = x[4], x[5], x[6]
    h1 = J[0, 0] * w1 + J[0, 1] * w2 + J[0, 2] * w3
    h2 = J[1, 0] * w1 + J[1, 1] * w2 + J[1, 2] * w3
    h3 = J[2, 0] * w1 + J[2, 1] * w2 + J[2, 2] * w3
    if p.wheel_gyroscopic:  # the body's momentum J w - s D A psi
        D = p.torque_sign * p.wheel_inertia_kgm2
        h1, h2, h3 = h1 - D * wheel_vector(p, x, 0), h2 - D * wheel_vector(p, x, 1), h3 - D * wheel_vector(p, x, 2)
    t1 = -(w2 * h3 - w3 * h2)
    t2 = -(w3 * h1 - w1 * h3)
    t3 = -(w1 * h2 - w2 * h1)
    if p.gravity_gradient:  # 3 n^2 r x (J r), r = zenith (+x_Hill) in body
        k = 3.0 * p.mean_motion_rad_s * p.mean_motion_rad_s
        r1, r2, r3 = A[0, 0], A[1, 0], A[2, 0]
        g1 = J[0, 0] * r1 + J[0, 1] * r2 + J[0, 2] * r3
        g2 = J[1, 0] * r1 + J[1, 1] * r2 + J[1, 2] * r3
        g3 = J[2, 0] * r1 + J[2, 1] * r2 + J[2, 2] * r3
        t1 += k * (r2 * g3 - r3 * g2)
        t2 += k * (r3 * g1 - r1 * g3)
        t3 += k * (r1 * g2 - r2 * g1)
    for a in range(3):
        out[a] = Ji[a, 0] * t1 + Ji[a, 1] * t2 + Ji[a, 2] * t3


@numba.njit(**LEAF, inline="always")
def control_accel(wd: Array, u: Array, p: np.void, a: int) -> float:
    """omega_dot_a = drift_a + (G u)_a (rad/s^2) of the drift wd (3,) and wheel accelerations u (3,): G_a u_a on
    principal axes with a wheel on each (the first implementation's arithmetic), the row G_a . u in general."""
    if p.diagonal:
        return wd[a] + p.control_gain[a] * u[a]
    return _general_accel(wd, u, p, a)


@numba.njit(**LEAF)
def _general_accels(wd: Array, u: Array, p: np.void, f: Array) -> None:
    """f[4:7] = omega_dot = wd + G u in general (`derivative`)."""
    for a in range(3):
        f[4 + a] = _general_accel(wd, u, p, a)


@numba.njit(**LEAF)
def _general_accel(wd: Array, u: Array, p: np.void, a: int) -> float:
    """`control_accel` in general (out of line: the per-axis path stays small where it is inlined)."""
    G = p.control_matrix
    v = G[a, 0] * u[0] + G[a, 1] * u[1] + G[a, 2] * u[2]
    for i in range(3, G.shape[1]):  # wheels past the third
        v += G[a, i] * u[i]
    return wd[a] + v


@numba.njit(**LEAF, inline="always")
def angular_momentum(p: np.void, x: Array, a: int) -> float:
    """(J w)_a - s D (A psi)_a of the state x (19,), N m s: the body's angular momentum on axis a."""
    if p.diagonal:
        return p.inertia_kgm2[a] * x[4 + a] - p.torque_sign * p.wheel_inertia_kgm2 * x[7 + a]
    return _general_momentum(p, x, a)


@numba.njit(**LEAF)
def _general_momentum(p: np.void, x: Array, a: int) -> float:
    """`angular_momentum` in general (products of inertia, wheels off the body axes)."""
    J = p.inertia_matrix
    Jw = J[a, 0] * x[4] + J[a, 1] * x[5] + J[a, 2] * x[6]
    return Jw - p.torque_sign * p.wheel_inertia_kgm2 * wheel_vector(p, x, a)


@numba.njit(**LEAF, inline="always")
def wheel_vector(p: np.void, x: Array, a: int) -> float:
    """(A psi)_a of the state x (19,), rad/s: the wheels' speeds summed along body axis a (their momentum on it is
    -s D (A psi)_a); psi_a where wheel a is on body axis a."""
    A = p.wheel_axes
    v = A[a, 0] * x[7] + A[a, 1] * x[8] + A[a, 2] * x[9]
    for i in range(3, A.shape[1]):  # wheels past the third, after z_dot
        v += A[a, i] * x[wheel_column(i)]
    return v


@numba.njit(**LEAF, inline="always")
def rate_momentum(p: np.void, a: int) -> float:
    """The most |(J w)_a| / |w|_inf can be, kg m^2: J_a on principal axes, sum_b |J_ab| with products."""
    if p.diagonal:
        return p.inertia_kgm2[a]
    return _general_rate_momentum(p, a)


@numba.njit(**LEAF)
def _general_rate_momentum(p: np.void, a: int) -> float:
    """`rate_momentum` in general."""
    J = p.inertia_matrix
    return abs(J[a, 0]) + abs(J[a, 1]) + abs(J[a, 2])


@numba.njit(**LEAF, inline="always")
def wheel_rate_momentum(p: np.void, i: int) -> float:
    """The most |(A^-1 J w)_i| / |w|_inf can be, kg m^2: the momentum wheel i takes over from the body's rates
    (`rate_momentum` where the wheels are on the body axes, sum_b |(A^-1 J)_ib| otherwise)."""
    if p.wheels_on_axes:
        return rate_momentum(p, i)
    return _general_wheel_rate_momentum(p, i)


@numba.njit(**LEAF)
def _general_wheel_rate_momentum(p: np.void, i: int) -> float:
    """`wheel_rate_momentum` with the wheels off the body axes."""
    Ai, J = p.wheel_axes_inverse, p.inertia_matrix
    rates = 0.0
    for c in range(3):
        rates += abs(Ai[i, 0] * J[0, c] + Ai[i, 1] * J[1, c] + Ai[i, 2] * J[2, c])
    return rates


@numba.njit(**LEAF, inline="always")
def control_error(p: np.void, e: Array, a: int) -> float:
    """The most |(G v)_a| can be for |v_b| <= e_b (3,), rad/s^2: |G_a| e_a where diagonal, sum_b |G_ab| e_b."""
    if p.diagonal:
        return abs(p.control_gain[a]) * e[a]
    return _general_control_error(p, e, a)


@numba.njit(**LEAF)
def _general_control_error(p: np.void, e: Array, a: int) -> float:
    """`control_error` in general."""
    G = p.control_matrix
    return abs(G[a, 0]) * e[0] + abs(G[a, 1]) * e[1] + abs(G[a, 2]) * e[2]


euler_bound = numba.njit(**LEAF)(inertia.euler_bound)
"""`config.inertia.euler_bound`, compiled (the one formula)."""
euler_rate_bound = numba.njit(**LEAF)(inertia.euler_rate_bound)
"""`config.inertia.euler_rate_bound`, compiled."""


@numba.njit(**LEAF)
def thermal_rate(cos_sun: float, cos_earth: float, T_K: float, lit: float, p: np.void) -> float:
    """T_dot (K/s) of the -j_B face node given its sun and Earth incidence cosines; lit: 1.0 in sunlight, 0.0
    in the Earth's shadow (`environment.sunlit`: no sun, and the Earth below is on its night side)."""
    F_E = p.earth_view_factor * (positive_part(cos_earth) if p.clamp_view_factor else cos_earth)
    q_solar = p.solar_W * lit * positive_part(cos_sun)
    q_albedo = p.albedo_W * lit * F_E
    q_ir = p.sigma_eps_A_W_K4 * F_E * p.earth_T4_K4
    T2 = T_K * T_K
    q_rejected = p.sigma_eps_A_W_K4 * (T2 * T2)
    return (q_solar + q_albedo + q_ir - q_rejected) / p.heat_capacity_J_K


@numba.njit(**LEAF)
def thermal_rates(cos_sun: Array, cos_earth: Array, T_K: Array, lit: Array, p: np.void, out: Array) -> None:
    """`thermal_rate` of arrays (n,) into out (n,): the one thermal law for callers that bound it over many
    states at once (the Monte Carlo's temperature rule)."""
    for k in range(T_K.shape[0]):
        out[k] = thermal_rate(cos_sun[k], cos_earth[k], T_K[k], lit[k], p)


@numba.njit(**LEAF)
def net_power(cos_panel_sun: float, lit: float, p: np.void) -> float:
    """E_dot (W): the panel's power minus the load; lit: 1.0 in sunlight, 0.0 in the Earth's shadow."""
    return p.panel_peak_W * lit * positive_part(cos_panel_sun) - p.load_W


# ----------------------------------------------------------------------------- the derivative and RK4


@numba.njit(**LEAF)
def derivative(x: Array, u: Array, p: np.void, A: Array, wd: Array, f: Array) -> None:
    """x_dot = f(x) + g u of one state (19,) into f; A (3, 3) and wd (3,) are scratch."""
    q1, q2, q3, q4, w1, w2, w3 = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    attitude_matrix(q1, q2, q3, q4, A)
    omega_drift(x, A, p, wd)
    if p.frame_rate_rad_s != 0.0:  # attitude relative to the rotating Hill frame
        nf = p.frame_rate_rad_s
        w1, w2, w3 = w1 - nf * A[0, 2], w2 - nf * A[1, 2], w3 - nf * A[2, 2]
    sx, sy, sz = sun_hill(x[12], p.sun_cos_beta, p.sun_sin_beta)
    cos_sun = axis_along(p.face_normal, p.face_axis, A, sx, sy, sz)
    cos_earth = axis_along(p.face_normal, p.face_axis, A, EARTH_HILL[0], EARTH_HILL[1], EARTH_HILL[2])
    c_panel = axis_along(p.panel_normal, p.panel_axis, A, sx, sy, sz)
    n = p.mean_motion_rad_s
    f[0] = 0.5 * (q4 * w1 - q3 * w2 + q2 * w3)
    f[1] = 0.5 * (q3 * w1 + q4 * w2 - q1 * w3)
    f[2] = 0.5 * (-q2 * w1 + q1 * w2 + q4 * w3)
    f[3] = -0.5 * (q1 * w1 + q2 * w2 + q3 * w3)
    if p.diagonal:  # (written out: the plant's and the rollouts' hot path)
        cg = p.control_gain
        f[4] = wd[0] + cg[0] * u[0]
        f[5] = wd[1] + cg[1] * u[1]
        f[6] = wd[2] + cg[2] * u[2]
    else:
        _general_accels(wd, u, p, f)
    f[7] = 0.0 + u[0]
    f[8] = 0.0 + u[1]
    f[9] = 0.0 + u[2]
    for i in range(3, p.wheel_failed.shape[0]):  # wheels past the third, after z_dot
        f[wheel_column(i)] = 0.0 + u[i]
    lit = sunlit(sx, p.shadow_sx)
    f[10] = thermal_rate(cos_sun, cos_earth, x[10], lit, p)
    f[11] = net_power(c_panel, lit, p)
    f[12] = -n
    f[13], f[14], f[15] = x[16], x[17], x[18]
    f[16] = 3 * n**2 * x[13] + 2 * n * x[17]
    f[17] = -2 * n * x[16]
    f[18] = -(n**2) * x[15]


@numba.njit(**LEAF)
def saturate(u: Array, p: np.void, out: Array) -> None:
    """The actuator: each wheel acceleration clipped to +-wheel_accel_max (NaN passes as in numpy.clip); a failed
    wheel's (`spacecraft.failed_wheels`) held at 0."""
    lim = p.wheel_accel_max_rad_s2
    for a in range(p.wheel_failed.shape[0]):
        v = u[a]
        out[a] = 0.0 if p.wheel_failed[a] else (-lim if v < -lim else (lim if v > lim else v))


RK4_WORK_ROWS = 8
"""Rows of `rk4_hold`'s scratch (RK4_WORK_ROWS, 19): x, k1..k4, the stage state, A(q) (9), omega drift (3)."""


def rk4_work(n_state: int = STATE_SIZE) -> Array:
    """A scratch array for `rk4_hold` of states of n_state entries (one per caller; its contents do not carry over
    between calls)."""
    return np.zeros((RK4_WORK_ROWS, n_state))


def record_wheels(p: NDArray[np.void]) -> int:
    """N, the wheels of a PLANT_DTYPE record (`plant_dtype`)."""
    return int(p.dtype["wheel_failed"].shape[0])


@numba.njit(**LEAF)
def rk4_hold(x0: Array, u: Array, dt_s: float, substeps: int, p: np.void, out: Array, work: Array) -> None:
    """Hold u (3,) (saturated already) over dt_s from x0 (19,): `substeps` classical RK4 steps, the
    quaternion renormalised after each. out (substeps, 19) receives the state after each substep;
    out[-1] is x(t + dt). work: scratch of `rk4_work()` (no allocation here: the Monte Carlo calls
    this 2,000 times a run)."""
    n = x0.shape[0]
    h = dt_s / substeps
    half = 0.5 * h
    sixth = h / 6.0
    x, k1, k2, k3, k4, y = work[0], work[1], work[2], work[3], work[4], work[5]
    A = work[6, :9].reshape((3, 3))
    wd = work[7, :3]
    for i in range(n):
        x[i] = x0[i]
    for j in range(substeps):
        derivative(x, u, p, A, wd, k1)
        for i in range(n):
            y[i] = x[i] + half * k1[i]
        derivative(y, u, p, A, wd, k2)
        for i in range(n):
            y[i] = x[i] + half * k2[i]
        derivative(y, u, p, A, wd, k3)
        for i in range(n):
            y[i] = x[i] + h * k3[i]
        derivative(y, u, p, A, wd, k4)
        for i in range(n):
            x[i] = x[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
        for i in range(4):
            x[i] = x[i] / norm
        for i in range(n):
            out[j, i] = x[i]


@numba.njit(**LEAF)
def rk4_delayed(x0: Array, u_prev: Array, u: Array, dt_s: float, substeps: int, p: np.void, out: Array,
                work: Array) -> None:
    """`rk4_hold` of a sample whose command reaches the wheels late (`spacecraft.transport_delay_s`): the
    previous command u_prev (3,) over the first p.delay_substeps substeps, then u (3,); both saturated
    already. out (substeps, 19): the state after each substep, on the same grid as without a delay. Exactly
    `rk4_hold` of u without one."""
    m = p.delay_substeps
    if m == 0:
        rk4_hold(x0, u, dt_s, substeps, p, out, work)
        return
    delay = delay_time(dt_s, substeps, m)
    rk4_hold(x0, u_prev, delay, m, p, out[:m], work)
    rk4_hold(out[m - 1], u, dt_s - delay, substeps - m, p, out[m:], work)


@numba.njit(**LEAF, inline="always")
def delay_time(dt_s: float, substeps: int, m: int) -> float:
    """The transport delay of m of a sample's substeps, s: the one formula the plant (`rk4_delayed`) and the
    filter's prediction (`filter.drive.delayed_state`) use, so they hold the same intervals to the bit."""
    return dt_s * m / substeps


@numba.vectorize(["float64(float64, float64)"], cache=True)
def wheel_accel_to_torque(u_rad_s2: float, D_kgm2: float) -> float:
    """D u (N m) per entry (a ufunc: scalars, arrays, compiled code): a primary controller's demand as the body
    torque it asks for (`demand_round_trip`), and a wheel command's torque where the wheels are on the body axes
    (`wheels_to_torque`)."""
    return D_kgm2 * u_rad_s2


@numba.vectorize(["float64(float64, float64)"], cache=True)
def torque_to_wheel_accel(tau_Nm: float, D_kgm2: float) -> float:
    """tau / D (rad/s^2) per entry (a ufunc): the wheel command of a body torque where the wheels are on the body
    axes (`torque_to_wheels`)."""
    return tau_Nm / D_kgm2


@numba.njit(**LEAF)
def _general_to_wheels(tau0: float, tau1: float, tau2: float, p: np.void, out: Array) -> None:
    """out := A^-1 tau / D (N,): the wheel accelerations whose torque D A u is tau (the smallest with N > 3)."""
    Ai, D = p.wheel_axes_inverse, p.wheel_inertia_kgm2
    for a in range(Ai.shape[0]):
        out[a] = torque_to_wheel_accel(Ai[a, 0] * tau0 + Ai[a, 1] * tau1 + Ai[a, 2] * tau2, D)


@numba.njit(**LEAF)
def _general_to_torque(u: Array, p: np.void, out: Array) -> None:
    """out := D A u (3,): the body torque of wheel accelerations u (N,)."""
    A, D = p.wheel_axes, p.wheel_inertia_kgm2
    for a in range(3):
        v = A[a, 0] * u[0] + A[a, 1] * u[1] + A[a, 2] * u[2]
        for i in range(3, A.shape[1]):
            v += A[a, i] * u[i]
        out[a] = wheel_accel_to_torque(v, D)


@numba.njit(**LEAF, inline="always")
def _per_axis_round_trip(v: Array, D: float, out: Array) -> None:
    """out := (v D) / D per axis: the round trip where the wheels are on the body axes."""
    for a in range(3):
        out[a] = torque_to_wheel_accel(wheel_accel_to_torque(v[a], D), D)


@numba.njit(**LEAF)
def torque_round_trip(u: Array, p: np.void, out: Array) -> None:
    """u -> tau = D A u -> u = A^-1 tau / D: the round trip every wheel command makes over DDS as a body torque
    (the nodes convert with `wheels_to_torque` and `torque_to_wheels`, which run these kernels, so a lockstep run
    over DDS equals the in-process one bit for bit); with the wheels on the body axes tau = D u per axis."""
    if p.wheels_on_axes:
        _per_axis_round_trip(u, p.wheel_inertia_kgm2, out)
        return
    _general_to_torque(u, p, out)
    _general_to_wheels(out[0], out[1], out[2], p, out)


@numba.njit(**LEAF)
def demand_round_trip(v: Array, p: np.void, out: Array) -> None:
    """A primary controller's demand v (3,; the body torque it asks for over D, `dynamics.controller`) -> tau = D v
    -> the wheel accelerations u = A^-1 tau / D that give it: the controller's torque_des reaching the filter as
    its u_des (the nodes: `wheel_accel_to_torque`, then `torque_to_wheels`)."""
    D = p.wheel_inertia_kgm2
    if p.wheels_on_axes:
        _per_axis_round_trip(v, D, out)
        return
    _general_to_wheels(wheel_accel_to_torque(v[0], D), wheel_accel_to_torque(v[1], D),
                       wheel_accel_to_torque(v[2], D), p, out)


def wheels_to_torque(u: Array, p: NDArray[np.void]) -> Array:
    """The body torque tau = D A u (..., 3), N m, of wheel accelerations u (..., N): what the filter sends as
    torque_cmd (`torque_round_trip`'s first half, the same kernel; p: a PLANT_DTYPE record)."""
    return _convert(u, p, wheel_accel_to_torque, _to_torque_all, record_wheels(p), 3)


def torque_to_wheels(tau: Array, p: NDArray[np.void]) -> Array:
    """The wheel accelerations u = A^-1 tau / D (..., N), rad/s^2, whose body torque is tau (..., 3), the smallest
    where N > 3: how torque_des reaches the filter and torque_cmd the plant (`torque_round_trip`'s second half, the
    same kernel)."""
    return _convert(tau, p, torque_to_wheel_accel, _to_wheels_all, 3, record_wheels(p))


def _convert(v: Array, p: NDArray[np.void], per_axis: Any, kernel: Any, n_in: int, n_out: int) -> Array:
    """v (..., n_in) through the torque interface into (..., n_out): per axis (a ufunc with D) where the wheels are
    on the body axes, else the compiled kernel row by row."""
    v = np.asarray(v, dtype=float)
    if p[0]["wheels_on_axes"]:
        return per_axis(v, float(p[0]["wheel_inertia_kgm2"]))
    V = np.ascontiguousarray(v.reshape(-1, n_in))
    out = np.empty((V.shape[0], n_out))
    kernel(V, p, out)
    return out.reshape((*v.shape[:-1], n_out))


@numba.njit(**LEAF)
def _to_torque_all(U: Array, pa: NDArray[np.void], out: Array) -> None:
    for k in range(U.shape[0]):
        _general_to_torque(U[k], pa[0], out[k])


@numba.njit(**LEAF)
def _to_wheels_all(T: Array, pa: NDArray[np.void], out: Array) -> None:
    for k in range(T.shape[0]):
        _general_to_wheels(T[k, 0], T[k, 1], T[k, 2], pa[0], out[k])


@numba.njit(**LEAF)
def _derivatives(X: Array, U: Array, pa: NDArray[np.void], F: Array, work: Array) -> None:
    A = work[0, :9].reshape((3, 3))
    wd = work[1, :3]
    for k in range(X.shape[0]):
        derivative(X[k], U[k], pa[0], A, wd, F[k])


@numba.njit(**LEAF)
def _omega_dots(X: Array, U: Array, pa: NDArray[np.void], W: Array, work: Array) -> None:
    p = pa[0]
    A = work[0, :9].reshape((3, 3))
    wd = work[1, :3]
    for k in range(X.shape[0]):
        attitude_matrix(X[k, 0], X[k, 1], X[k, 2], X[k, 3], A)
        omega_drift(X[k], A, p, wd)
        for a in range(3):
            W[k, a] = control_accel(wd, U[k], p, a)


@numba.njit(**LEAF)
def _integrate(x: Array, u: Array, u_prev: Array, dt_s: float, substeps: int, pa: NDArray[np.void], us: Array,
               out: Array, work: Array) -> None:
    saturate(u, pa[0], us)
    rk4_delayed(x, u_prev, us, dt_s, substeps, pa[0], out, work)


@numba.njit(**LEAF)
def _saturate_all(U: Array, pa: NDArray[np.void], out: Array) -> None:
    for k in range(U.shape[0]):
        saturate(U[k], pa[0], out[k])


def saturated(u: Array, p: NDArray[np.void]) -> Array:
    """What the actuator holds of wheel accelerations u (..., 3), rad/s^2: `saturate` for Python callers
    (the plant node, `simulate`'s record, the analysis of a bag, the Basilisk plant), a new array."""
    u = np.asarray(u, dtype=float)
    U = np.ascontiguousarray(u.reshape(-1, record_wheels(p)))
    out = np.empty_like(U)
    _saturate_all(U, p, out)
    return out.reshape(u.shape)


def omega_dot(x: Array, u: Array, p: NDArray[np.void]) -> Array:
    """Body angular accelerations (..., 3), rad/s^2, of states x (..., 16 + N) under wheel accelerations u (..., N)."""
    X, U = _batch(x, u, p)
    W = np.empty((X.shape[0], 3))
    _omega_dots(X, U, p, W, rk4_work(X.shape[1]))
    return W.reshape((*x.shape[:-1], 3))


def state_derivative(x: Array, u: Array, p: NDArray[np.void]) -> Array:
    """x_dot (..., 16 + N) of states x (..., 16 + N) with wheel accelerations u (..., N) held (no saturation)."""
    X, U = _batch(x, u, p)
    F = np.empty_like(X)
    _derivatives(X, U, p, F, rk4_work(X.shape[1]))
    return F.reshape(np.shape(x))


def _batch(x: Array, u: Array, p: NDArray[np.void]) -> tuple[Array, Array]:
    """States (k, 16 + N) and wheel accelerations (k, N) of x (..., 16 + N) and u (..., N) (broadcast)."""
    n = record_wheels(p)
    x = np.asarray(x, dtype=float)
    X = np.ascontiguousarray(x.reshape(-1, state_size(n)))
    U = np.ascontiguousarray(np.broadcast_to(np.asarray(u, dtype=float), (*x.shape[:-1], n)).reshape(-1, n))
    return X, U


def integrate(x: Array, u: Array, dt_s: float, p: NDArray[np.void], substeps: int,
              u_prev: Array | None = None) -> tuple[Array, Array]:
    """Saturate u and hold it over dt_s from one state (Python face of `saturate` + `rk4_delayed`).

    Args:
        x: state (16 + N,; 19 with three wheels).
        u: wheel accelerations (N,), rad/s^2 (saturated here at the actuator limit).
        dt_s: hold time, s.
        p: the PLANT_DTYPE record array (1,) of `plant_record`.
        substeps: RK4 substeps.
        u_prev: with a transport delay (p's delay_substeps > 0), the previous command as the wheels held it
            (saturated), which holds over the delay; None: zero.

    Returns:
        (x at t + dt (19,), the substep states (substeps, 19)).
    """
    x = np.ascontiguousarray(x, dtype=float)
    n = record_wheels(p)
    if x.shape != (state_size(n),):
        raise ValueError(f"integrate takes one state ({state_size(n)},), got {x.shape}")
    u = np.ascontiguousarray(u, dtype=float)
    if u.shape != (n,):
        raise ValueError(f"integrate takes {n} wheel accelerations, got {u.shape}")
    us = np.empty(n)
    out = np.empty((substeps, x.shape[0]))
    prev = np.zeros(n) if u_prev is None else np.ascontiguousarray(u_prev, dtype=float)
    # record arrays, not record scalars, cross into compiled code (numba types a scalar at every call)
    _integrate(x, u, prev, float(dt_s), substeps, p, us, out, rk4_work(x.shape[0]))
    return out[-1].copy(), out


__all__ = [
    "PLANT_DTYPE", "RK4_WORK_ROWS", "angular_momentum", "axis_along", "control_accel", "control_error", "euler_bound",
    "euler_rate_bound", "rate_momentum", "delay_time", "derivative", "integrate", "net_power", "omega_dot",
    "omega_drift", "plant_record", "positive_part", "rk4_delayed", "rk4_hold", "rk4_work", "saturate", "saturated",
    "state_derivative",
    "thermal_rate",
    "demand_round_trip", "torque_round_trip", "torque_to_wheel_accel", "torque_to_wheels", "wheel_accel_to_torque",
    "wheel_rate_momentum", "wheel_vector", "wheels_to_torque",
]  # fmt: skip
