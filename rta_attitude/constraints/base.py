"""What every safety constraint shares: its parameters by name, the barrier table, the HOCBF step.

A constraint's barrier condition is affine in u:  BC(x, u) = drift(x) + gain(x) . u  >= 0
(minus a slack delta when the constraint is soft). For relative degree 2 (HOCBF):

    Psi_0 = h (or its augmented form),   Psi_1 = dPsi_0/dt|_f + k1 Psi_0,
    BC    = dPsi_1/dt|_(f + g u) + k2 Psi_1 + bias,

and for relative degree 1:  BC = dh/dt|_(f + g u) + k1 h + bias. `bias` is the paper's sigma,
added to the final condition as the paper's equation writes it (AFRL's framework adds it to h).

Rows. A configuration's constraints are rows in one order (`Config.constraint_names`): its pointing
constraints (`constraints.cones`, the cone table), then temperature, battery, omega_x/y/z, psi_x/y/z. Every
table holds MAX_ROWS rows (the capacity: any configuration up to it runs the same compiled kernels) and the
record says how many are in use (n_rows) and where the fixed ones are (row_temperature, ...).

Records (structured NumPy arrays, read by name in compiled code):
- GAIN_DTYPE: one constraint's switches and gains (one per row);
- CONE_DTYPE: one pointing constraint (kind, boresight, target, half-angle, windows);
- CONSTRAINT_DTYPE: the limits, the augmentation weights, the sampled-data options, the cone table and the
  gains of every constraint (`constraint_record`);
- TABLE_DTYPE: one state's evaluation: h, Psi_0, Psi_1, drift and gain of every constraint, the
  box lo <= u <= hi (U, intersected with the one-step zero-order-hold bounds in the robust preset)
  and, in the robust preset with the gyrostat model, the coupled zero-order-hold rate rows
  (`angular_rate.zoh_rows`).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import FIXED_NAMES, MAX_POINTING, MAX_WINDOWS, Config
from rta_attitude.dynamics.environment import target_kind
from rta_attitude.dynamics.sensors import interface_energy_error
from rta_attitude.dynamics.spacecraft import control_error, plant_record
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

MAX_CONES = MAX_POINTING
MAX_ROWS = MAX_CONES + len(FIXED_NAMES)
"""Rows every table holds (the pointing constraints' capacity and the fixed rows); a configuration uses
`n_rows` of them."""

CONE_DTYPE = np.dtype([
    ("keep_in", np.uint8),                  # 1: h = half_angle - theta; 0: h = theta - half_angle
    ("axis", np.float64, (3,)),             # the boresight, body axes (unit)
    ("target", np.int64),                   # `dynamics.environment` kind: SUN, EARTH, HILL_FIXED, INERTIAL_FIXED
    ("vector", np.float64, (3,)),           # the target's fixed vector (Hill or inertial)
    ("angle_rad", np.float64),              # the half-angle
    ("n_windows", np.int64),                # 0: always; else only within the windows
    ("window_on_s", np.float64, (MAX_WINDOWS,)),     # the barrier starts to tighten (`windows.ramp_start`)
    ("window_start_s", np.float64, (MAX_WINDOWS,)),
    ("window_end_s", np.float64, (MAX_WINDOWS,)),
    ("ramp_rad_s", np.float64),             # how fast the barrier tightens ahead of a window
])  # fmt: skip
"""One pointing constraint of the cone table (`constraints.cones`)."""

GAIN_DTYPE = np.dtype([
    ("enabled", np.uint8),
    ("k1", np.float64),            # alpha_1(h) = k1 h, 1/s
    ("k2", np.float64),            # alpha_2 (relative degree 2), 1/s
    ("bias", np.float64),          # sigma, added to the final condition
    ("slack_weight", np.float64),  # p > 0: soft, cost p delta^2
    ("margin", np.float64),        # the HOCBF keeps h >= margin (robust preset; 0 in `paper`)
])  # fmt: skip

CONSTRAINT_DTYPE = np.dtype([
    ("gains", GAIN_DTYPE, (MAX_ROWS,)),
    ("n_rows", np.int64),                  # rows in use: n_cones + the fixed rows
    ("n_cones", np.int64),                 # the pointing constraints: rows 0 .. n_cones - 1
    ("row_temperature", np.int64),         # rows of the fixed constraints (after the cones)
    ("row_battery", np.int64),
    ("row_omega", np.int64),               # omega_x; omega_y, omega_z follow
    ("row_psi", np.int64),                 # psi_x; psi_y, psi_z follow
    ("cones", CONE_DTYPE, (MAX_CONES,)),
    ("temperature_max_K", np.float64),
    ("energy_min_J", np.float64),
    ("omega_max_rad_s", np.float64),
    ("psi_max_rad_s", np.float64),         # the wheel speed psi the rows keep within (`Config.psi_keep_rad_s`)
    ("psi_limit_rad_s", np.float64),       # the wheel-speed limit h judges (psi_max)
    ("wheel_speed_relative", np.uint8),    # 1: h judges |psi_i + a_i . omega|, the speed relative to the body
    ("delta0_K_rad", np.float64),          # temperature: sun-incidence augmentation
    ("delta1_K_rad", np.float64),          # temperature: Earth-incidence augmentation
    ("delta2_J_rad", np.float64),          # battery: panel-angle augmentation
    ("sin_pole_guard", np.float64),        # sin of the arccos pole guard
    ("robust", np.uint8),                  # 1: one-step zero-order-hold bounds on omega and psi
    ("dt_s", np.float64),                  # the hold the filter plans for
    ("zoh_margin", np.float64),            # ZOH bounds aim at (1 - zoh_margin) of the limit
    ("u_max_rad_s2", np.float64, (3,)),    # the box U
    ("wheel_axes", np.float64, (3, 3)),    # A: wheel i's spin axis in body axes is column i
    ("u_reach_rad_s2", np.float64, (3,)),  # the box a drive in any state reaches: (1 - 2c) U (`drive_lag`; U if c = 0)
    # measurement-robust margins (robust preset with sensors on; 0 otherwise): bounds on the errors of
    # what the filter reads (docs/noise.md, `measurement_errors`)
    ("err_att_rad", np.float64),           # attitude (angle of the error rotation, + the actuator's over a hold)
    ("err_omega_rad_s", np.float64),       # body rate (norm)
    ("err_omega_axis_rad_s", np.float64),  # body rate, one axis
    ("err_psi_rad_s", np.float64),         # one wheel speed
    ("err_u_rad_s2", np.float64, (3,)),    # the held wheel acceleration (lag and torque noise), per axis
    ("err_T_K", np.float64),
    ("err_E_J", np.float64),
    ("target_rate_rad_s", np.float64),     # sun and Earth directions turn at the mean motion
    # the vehicle's inertia within +-delta of the model's (robust preset; 0 otherwise, `constraint_record`,
    # `inertia_shape`)
    ("inertia_error_gain", np.float64),    # delta / (1 - delta)
    ("inertia_accel_rad_s2", np.float64, (3,)),  # its bound on |omega_dot(true) - omega_dot(model)|, any state
    ("inertia_principal", np.uint8),       # 1: principal axes, each moment within +-delta (the per-axis bound)
    ("inertia_root", np.float64, (3, 3)),  # in general: R = L^T, J = L L^T (|R v|^2 = v^T J v)
    ("inertia_scale", np.float64, (3,)),   # sqrt((J^-1)_aa)
    ("inertia_spread", np.float64),        # sqrt(lambda_max / lambda_min) of J
    ("inertia_gg", np.float64),            # 3 n^2 lambda_max / sqrt(lambda_min) with the gravity gradient, else 0
    ("control_root", np.float64, (3,)),    # |R G_j|: wheel j's acceleration's size in J's norm
    ("control_inverse", np.float64, (3, 3)),  # G^-1: a row's gain on omega_dot from its gain on u
    ("accel_limit_rad_s2", np.float64, (3,)),  # b: |(G u)_i| <= b_i (`Config.accel_limit_rad_s2`)
    ("accel_rows", np.uint8),              # 1: the QP keeps those three rows (G not diagonal); 0: the box is U
])  # fmt: skip

ZOH_CHECKS = 5
"""Check points of the coupled rate rows in one hold (`angular_rate.zoh_rows`)."""
ZOH_ROWS = 3 * ZOH_CHECKS

TABLE_DTYPE = np.dtype([
    ("h", np.float64, (MAX_ROWS,)),
    ("psi0", np.float64, (MAX_ROWS,)),
    ("psi1", np.float64, (MAX_ROWS,)),
    ("drift", np.float64, (MAX_ROWS,)),
    ("gain", np.float64, (MAX_ROWS, 3)),
    ("lo", np.float64, (3,)),
    ("hi", np.float64, (3,)),
    ("zoh_rows", np.int64),                      # coupled rate rows in use (0, or ZOH_ROWS)
    ("zoh_axis", np.int64, (ZOH_ROWS,)),         # the body axis of each
    ("zoh_gain", np.float64, (ZOH_ROWS, 3)),     # zoh_lo <= zoh_gain . u <= zoh_hi, rad/s
    ("zoh_lo", np.float64, (ZOH_ROWS,)),
    ("zoh_hi", np.float64, (ZOH_ROWS,)),
])  # fmt: skip


def constraint_record(cfg: Config) -> NDArray[np.void]:
    """The CONSTRAINT_DTYPE record (shape (1,)) of a configuration (margins only in the robust preset)."""
    from rta_attitude.constraints.margins import sampled_data_margin
    from rta_attitude.constraints.windows import ramp_rate, ramp_start

    cfg.spacecraft.require_three_wheels("the filter")
    robust = cfg.filter.preset == "robust"
    L, aug = cfg.limits, cfg.augmentation
    rec = np.zeros(1, CONSTRAINT_DTYPE)
    c = rec[0]
    names = cfg.constraint_names
    for i, name in enumerate(names):
        g = cfg.gains(name)
        gi = c["gains"][i]
        gi["enabled"], gi["k1"], gi["k2"], gi["bias"] = g.enabled, g.k1, g.k2, g.bias
        gi["slack_weight"] = g.slack_weight if g.enabled else 0.0
        gi["margin"] = sampled_data_margin(cfg, name)
    k = len(cfg.pointing)
    c["n_rows"], c["n_cones"] = len(names), k
    c["row_temperature"], c["row_battery"], c["row_omega"], c["row_psi"] = k, k + 1, k + 2, k + 5
    for j, cone in enumerate(cfg.pointing):
        e = c["cones"][j]
        kind, vector = target_kind(cone.target)
        e["keep_in"], e["axis"], e["target"] = cone.keep_in, cone.boresight_body, kind
        e["vector"] = cone.target_vector if cone.target_vector is not None else vector
        e["angle_rad"] = cone.half_angle_rad
        e["n_windows"] = len(cone.windows_s)
        e["ramp_rad_s"] = ramp_rate(cfg, cone)
        for w, (start, end) in enumerate(cone.windows_s):
            e["window_on_s"][w] = ramp_start(cfg, cone, start)
            e["window_start_s"][w], e["window_end_s"][w] = start, end
    c["temperature_max_K"], c["energy_min_J"] = L.temperature_max_K, L.energy_min_J
    c["omega_max_rad_s"], c["psi_max_rad_s"] = L.omega_max_rad_s, cfg.psi_keep_rad_s
    c["psi_limit_rad_s"] = L.psi_max_rad_s
    c["wheel_speed_relative"] = L.wheel_speed_relative_to_body
    c["delta0_K_rad"], c["delta1_K_rad"], c["delta2_J_rad"] = aug.delta0_K_rad, aug.delta1_K_rad, aug.delta2_J_rad
    c["sin_pole_guard"] = math.sin(cfg.filter.pole_guard_rad)
    c["robust"] = robust
    c["dt_s"], c["zoh_margin"] = cfg.filter.sample_time_s, cfg.filter.zoh_margin
    c["u_max_rad_s2"] = cfg.u_max_rad_s2
    c["wheel_axes"] = cfg.spacecraft.wheel_axes
    c["accel_rows"] = not cfg.spacecraft.diagonal
    c["accel_limit_rad_s2"] = cfg.accel_limit_rad_s2
    # with the drive's lag compensated, what a rollout plans keeps to the part of U every drive state can
    # deliver (the filter's answer now: the part its drive's state can, `filter.drive.drive_box`)
    c["u_reach_rad_s2"] = (1.0 - 2.0 * drive_lag(cfg)[0]) * cfg.u_max_rad_s2
    if robust and cfg.sensors.enabled:
        for key, value in measurement_errors(cfg).items():
            c[key] = value
    if robust and cfg.spacecraft.inertia_uncertainty > 0.0:
        from rta_attitude.constraints.margins import inertia_accel_bound

        delta = cfg.spacecraft.inertia_uncertainty
        c["inertia_error_gain"] = delta / (1.0 - delta)
        c["inertia_accel_rad_s2"] = inertia_accel_bound(cfg, cfg.filter.model)
        for key, value in inertia_shape(cfg).items():
            c[key] = value
    if robust:  # the battery's reading crosses the interface as a float32 (`dynamics.sensors.encode`)
        c["err_E_J"] += interface_energy_error(cfg)
    return rec


def lag_response(cfg: Config) -> tuple[float, float]:
    """(c, e) of the wheel drive's first-order lag (time constant tau = sensors.actuator_lag_s) over a hold dt,
    (0, 0) without a lag: the held mean of a command v_cmd from the drive's state v is (1 - c) v_cmd + c v,
    c = (tau/dt)(1 - e^(-dt/tau)), and the state after the hold v_cmd + (v - v_cmd) e, e = e^(-dt/tau)
    (`dynamics.sensors.actuate`)."""
    tau, dt = cfg.sensors.actuator_lag_s, cfg.filter.sample_time_s
    if not tau > 0:
        return 0.0, 0.0
    decay = math.exp(-dt / tau)
    return (tau / dt) * (1.0 - decay), decay


def drive_lag(cfg: Config) -> tuple[float, float]:
    """`lag_response` where the filter compensates the lag (robust preset, sensor errors on,
    `filter.actuator_lag: compensate`), else (0, 0). A held mean a with |a_i| <= (1 - 2c) U_i is reached from
    every drive state |v_i| <= U_i by a command within U: (a - c v) / (1 - c)."""
    if not (cfg.filter.preset == "robust" and cfg.sensors.enabled and cfg.filter.actuator_lag == "compensate"):
        return 0.0, 0.0
    return lag_response(cfg)


def measurement_errors(cfg: Config) -> dict[str, float | NDArray[np.float64]]:
    """Bounds on the errors of what the filter reads and of what the wheels do over one hold, from the
    `sensors:` standard deviations (b = bound_sigma of them; docs/noise.md derives each):

    - err_u,a = 2 U_a (tau/dt)(1 - e^(-dt/tau)) + b sigma_u: the lag's largest departure from a held
      command (a full reversal inside U) plus torque noise, per axis, rad/s^2; b sigma_u alone where the
      filter compensates the lag (`drive_lag`);
    - err_omega_axis = b sqrt(sigma_g^2 + sigma_b^2 + walk^2 horizon); err_omega = sqrt(3) of it (norm);
    - err_att = sqrt(3) b sigma_att + |G err_u| dt^2 / 2 (the actuator's drift of the attitude in a hold);
    - err_psi = b sigma_psi; err_T = b sigma_T; err_E = b sigma_E.
    """
    s, b, dt = cfg.sensors, cfg.sensors.bound_sigma, cfg.filter.sample_time_s
    # compensated: the filter sends the command whose held mean is its answer, so no lag departs from it
    lag = 0.0 if drive_lag(cfg)[0] > 0.0 else lag_response(cfg)[0]
    err_u = 2.0 * cfg.u_max_rad_s2 * lag + b * s.torque_noise_rad_s2
    gyro = b * math.sqrt(s.gyro_noise_rad_s**2 + s.gyro_bias_rad_s**2
                         + s.gyro_bias_walk_rad_s_sqrt_s**2 * s.bias_horizon_s)
    drift = float(np.linalg.norm(cfg.spacecraft.control_times(err_u))) * dt * dt / 2
    errors: dict[str, float | NDArray[np.float64]] = {
        "err_att_rad": math.sqrt(3.0) * b * s.attitude_noise_rad + drift,
        "err_omega_rad_s": math.sqrt(3.0) * gyro,
        "err_omega_axis_rad_s": gyro,
        "err_psi_rad_s": b * s.wheel_speed_noise_rad_s,
        "err_u_rad_s2": err_u,
        "err_T_K": b * s.temperature_noise_K,
        "err_E_J": b * s.energy_noise_J,
        "target_rate_rad_s": cfg.environment.mean_motion_rad_s,
    }
    if cfg.spacecraft.transport_delay_s > 0.0:
        errors.update(predicted_errors(cfg, errors))
    return errors


def predicted_errors(cfg: Config, e: dict[str, Any]) -> dict[str, float]:
    """The reading's errors (`measurement_errors`) carried over a transport delay d by the filter's prediction
    (`filter.drive.delayed_state`: the measured state held under the command in flight), docs/delay.md. The
    prediction's error grows as the dynamics' sensitivity to the state allows, plus the drive's error err_u
    on the command in flight; bounds with every rate at omega_max and wheel at psi_max:

    - omega: |d omega_dot / d omega| <= (2 J_max |omega| + D |psi|) / J_min, |d omega_dot / d psi| <= D |omega| /
      J_min (the gyrostat's wheel terms; the paper's model has neither D term), so e_omega grows to
      e_omega e^(K d) + (D |omega| / J_min) e_psi d + |G err_u| d, and each axis' error by the same amount;
    - the attitude: + (e_omega + |G err_u| d / 2) d;  psi: + err_u d;
    - E: + P_peak e_att d (the panel's cosine);  T: + ((alpha A S + alpha A S A_f F + sigma eps A T_E^4 F) e_att
      + 4 sigma eps A T_max^3 e_T) d / (m c_p) (the face's cosines and the radiation).

    Each with e_att and e_omega the larger, predicted values over the delay (the bound is first order in d,
    taken at the delay's end)."""
    sc, L = cfg.spacecraft, cfg.limits
    d = sc.transport_delay_s
    J, D = sc.principal_moments, sc.wheel_inertia_kgm2
    gyrostat = cfg.filter.model == "gyrostat"
    w = math.sqrt(3.0) * L.omega_max_rad_s
    psi = math.sqrt(3.0) * L.psi_max_rad_s if gyrostat else 0.0
    K = (2.0 * float(J.max()) * w + D * psi) / float(J.min())
    coupling = D * w / float(J.min()) if gyrostat else 0.0
    err_u = np.asarray(e["err_u_rad_s2"], dtype=float)
    accel = float(np.linalg.norm(sc.control_times(err_u)))
    e_psi = float(e["err_psi_rad_s"])
    grow = float(e["err_omega_rad_s"]) * math.expm1(K * d) + coupling * math.sqrt(3.0) * e_psi * d + accel * d
    e_omega = float(e["err_omega_rad_s"]) + grow
    e_att = float(e["err_att_rad"]) + (e_omega + accel * d / 2.0) * d
    p = plant_record(cfg, cfg.filter.model)[0]
    heat = (float(p["solar_W"]) + (float(p["albedo_W"]) + float(p["sigma_eps_A_W_K4"] * p["earth_T4_K4"]))
            * cfg.environment.earth_view_factor) * e_att
    radiation = 4.0 * float(p["sigma_eps_A_W_K4"]) * L.temperature_max_K**3 * float(e["err_T_K"])
    return {
        "err_att_rad": e_att,
        "err_omega_rad_s": e_omega,
        "err_omega_axis_rad_s": float(e["err_omega_axis_rad_s"]) + grow,
        "err_psi_rad_s": e_psi + float(err_u.max()) * d,
        "err_T_K": float(e["err_T_K"]) + (heat + radiation) * d / float(p["heat_capacity_J_K"]),
        "err_E_J": float(e["err_E_J"]) + float(p["panel_peak_W"]) * e_att * d,
    }


@numba.njit(**LEAF)
def inertia_error(c: np.void, p: np.void, w: Array, drift: Array, a: int) -> float:
    """Bound on |omega_dot_a(true) - omega_dot_a(model)| (rad/s^2) at body rate w (3,) and the model's
    omega_dot at u = 0, drift (3,), for any vehicle whose inertia is within +-delta of the model's J
    (k = c.inertia_error_gain = delta / (1 - delta); 0: none). The truth's J' omega_dot' = N - omega x (dJ omega)
    (+ the gravity gradient's dJ part), N the model's right-hand side (J omega_dot = N), J' = J + dJ.

    On principal axes (each principal moment within +-delta: |dJ_i| <= delta J_i, dJ diagonal)

        |omega_dot'_a - omega_dot_a| <= |N_a| |1/J'_a - 1/J_a| + |(omega x dJ omega)_a| / J'_a
                                     <= k (|omega_dot_a| + |w_b w_c| (J_b + J_c) / J_a + 3 n^2 (J_b + J_c) / (2 J_a))

    with |omega_dot_a| <= |drift_a| + sum_j |G_aj| U_j (any u in the box) and the gravity gradient's term only
    where it is modelled (|r_b r_c| <= 1/2). With products of inertia, `_general_inertia_error`. docs/conventions.md,
    "Inertia"."""
    k = c.inertia_error_gain
    if k == 0.0:
        return 0.0
    if not c.inertia_principal:
        return _general_inertia_error(c, w, drift, a)
    b, d = (a + 1) % 3, (a + 2) % 3
    return inertia_error_bound(k, abs(drift[a]) + control_error(p, c.u_max_rad_s2, a), abs(w[b] * w[d]),
                               p.mean_motion_rad_s, p.gravity_gradient != 0, p.inertia_kgm2, a)


@numba.njit(**LEAF)
def _general_inertia_error(c: np.void, w: Array, drift: Array, a: int) -> float:
    """`inertia_error` for a tensor known to within +-delta in every direction (-delta J <= dJ <= delta J: principal
    moments and axes both uncertain). With S = J^-1/2, M = S dJ S (|M| <= delta) and J' = S^-1 (I + M) S^-1, the
    error -J'^-1 (dJ omega_dot + omega x dJ omega - 3 n^2 r x dJ r) has, on axis a (|S e_a| = sqrt((J^-1)_aa)),

        |e_a| <= k sqrt((J^-1)_aa) (|R omega_dot| + sqrt(kappa) |omega| |R omega| + 3 n^2 lambda_max / sqrt(lambda_min))

    (R = L^T, J = L L^T; kappa = lambda_max / lambda_min of J; |(I + M)^-1 M| <= k), with |R omega_dot| <=
    |R drift| + sum_j |R G_j| U_j for any u in the box."""
    R = c.inertia_root
    rf = rw = nw = 0.0
    for i in range(3):
        vf = R[i, 0] * drift[0] + R[i, 1] * drift[1] + R[i, 2] * drift[2]
        vw = R[i, 0] * w[0] + R[i, 1] * w[1] + R[i, 2] * w[2]
        rf += vf * vf
        rw += vw * vw
        nw += w[i] * w[i]
    acc = math.sqrt(rf)
    for j in range(c.control_root.shape[0]):
        acc += c.control_root[j] * c.u_max_rad_s2[j]
    return general_inertia_error_bound(c.inertia_error_gain, c.inertia_scale[a], acc, math.sqrt(nw * rw),
                                       c.inertia_spread, c.inertia_gg)


@numba.njit(**LEAF)
def general_inertia_error_bound(k: float, scale: float, accel: float, rates: float, spread: float,
                                gg: float) -> float:
    """`_general_inertia_error`'s formula, k sqrt((J^-1)_aa) (|R omega_dot| + sqrt(kappa) |w| |R w| + gg), from
    scale = sqrt((J^-1)_aa), a bound accel on |R omega_dot| and one rates on |w| |R w|: at a state
    (`_general_inertia_error`) or at the worst the rows allow (`margins.inertia_accel_bound`)."""
    return k * scale * (accel + spread * rates + gg)


def inertia_shape(cfg: Config) -> dict[str, Any]:
    """The CONSTRAINT_DTYPE fields `inertia_error` reads of the filter's model J: principal or not, and for a
    tensor R = L^T (Cholesky), sqrt((J^-1)_aa), sqrt(kappa), the gravity gradient's term, |R G_j|, and G^-1 (the
    rows' gains on omega_dot, `rows.robust_to_inertia`)."""
    sc, env = cfg.spacecraft, cfg.environment
    lam_min, lam_max = float(np.min(sc.principal_moments)), float(np.max(sc.principal_moments))
    R = np.linalg.cholesky(sc.inertia_matrix).T
    return {
        "inertia_principal": sc.principal,
        "inertia_root": R,
        "inertia_scale": np.sqrt(np.diag(sc.inertia_inverse)),
        "inertia_spread": math.sqrt(lam_max / lam_min),
        "inertia_gg": 3.0 * env.mean_motion_rad_s**2 * lam_max / math.sqrt(lam_min) if env.gravity_gradient else 0.0,
        "control_root": np.linalg.norm(R @ sc.control_matrix, axis=0),
        "control_inverse": np.linalg.inv(sc.control_matrix),
    }


@numba.njit(**LEAF)
def inertia_error_bound(k: float, accel: float, w_bc: float, n: float, gravity_gradient: bool, J: Array,
                        a: int) -> float:
    """`inertia_error`'s formula, k (|omega_dot_a| + (|w_b w_c| + 3 n^2 / 2) (J_b + J_c) / J_a), from a bound
    accel on |omega_dot_a| and one w_bc on |w_b w_c| (the gravity gradient's term where it is modelled): at a
    state (`inertia_error`) or at the worst the rows allow (`margins.inertia_accel_bound`)."""
    b, d = (a + 1) % 3, (a + 2) % 3
    gg = 1.5 * 3.0 * n * n if gravity_gradient else 0.0
    return k * (accel + (w_bc + gg) * (J[b] + J[d]) / J[a])


@numba.njit(**LEAF, inline="always")
def hard(c: np.void, i: int) -> bool:
    """Row i of constraint record c binds hard: enabled and not slacked. A slacked row may be given up by the
    QP, so the gatekeeper's rollouts neither check it nor compute it (`rows.rollout_safety_values`)."""
    g = c.gains[i]
    return g.enabled != 0 and g.slack_weight == 0.0


@numba.njit(**LEAF)
def angle_rate_error(sin_theta: float, x: Array, c: np.void) -> float:
    """Bound on |theta_dot(true) - theta_dot(measured)| (rad/s) of a body axis' angle to a target, given
    the measured sin theta and state x (its |omega|) and the error bounds of c (0 when they are 0): with
    g = d/dt cos theta, |g' - g| <= err_omega + err_att (|omega| + n) and |g| <= |omega| + n,
    |g'/s' - g/s| <= |g' - g| / s' + |g| err_att / (s' (s' - err_att)); never more than both rates'
    bound (|omega'| + n) + (|omega| + n) (docs/noise.md)."""
    e, dw, n = c.err_att_rad, c.err_omega_rad_s, c.target_rate_rad_s
    if e == 0.0 and dw == 0.0:
        return 0.0
    omega_norm = math.sqrt(x[4] * x[4] + x[5] * x[5] + x[6] * x[6])
    w_true = omega_norm + dw
    g_true = w_true + n
    whole = (omega_norm + n) + g_true
    s_lo = sin_theta - e
    if s_lo <= 0.0:
        return whole
    local = (dw + e * g_true) / sin_theta + g_true * e / (sin_theta * s_lo)
    return local if local < whole else whole


@numba.njit(**LEAF)
def second_order(t: np.void, i: int, psi0: float, psi0_dot: float, psi0_ddot_drift: float, g: np.void) -> None:
    """HOCBF with linear class-K functions into row i of table t: Psi_0, Psi_1 = Psi_0' + k1 Psi_0 and
    the drift of BC = Psi_0'' + k1 Psi_0' + k2 Psi_1 + bias (the gain on u is the caller's)."""
    psi1 = psi0_dot + g.k1 * psi0
    t.psi0[i] = psi0
    t.psi1[i] = psi1
    t.drift[i] = psi0_ddot_drift + g.k1 * psi0_dot + g.k2 * psi1 + g.bias


@numba.njit(**LEAF)
def speed_limit_row(t: np.void, i: int, axis: int, v: float, v_max: float, err: float, v_gain: float,
                    v_drift: float, g: np.void) -> None:
    """The relative-degree-1 CBF h = v_max^2 - v^2 of a speed v (a body rate or a wheel speed) into row i
    of table t, with v_dot = v_drift + v_gain u_axis: h (the truth's formula), Psi = the measured speed
    kept err clear of the limit (measurement-robust; err = 0: h itself), gain -2 v v_gain on u_axis and
    drift -2 v v_drift + k1 Psi + bias."""
    hv = v_max**2 - v * v
    t.h[i] = hv
    if err > 0.0:
        lim = v_max - err
        hv = lim * lim - v * v
    t.psi0[i] = hv
    t.psi1[i] = hv
    for a in range(3):
        t.gain[i, a] = 0.0
    t.gain[i, axis] = -2.0 * v * v_gain
    t.drift[i] = -2.0 * v * v_drift + g.k1 * hv + g.bias


@numba.njit(**LEAF, inline="always")
def hold_interval(lo: float, hi: float, zlo: float, zhi: float) -> tuple[float, float]:
    """[lo, hi] (what the drive can hold) narrowed to a one-step zero-order-hold interval [zlo, zhi]; where that
    interval misses [lo, hi] entirely (a state already past a limit by more than one step can undo), the edge of
    [lo, hi] nearest to it."""
    new_lo, new_hi = nan_max(lo, zlo), nan_min(hi, zhi)
    if new_lo > new_hi:
        edge = lo if zhi < lo else hi
        return edge, edge
    return new_lo, new_hi


@numba.njit(**LEAF)
def nan_max(a: float, b: float) -> float:
    """numpy.maximum of two floats (NaN propagates)."""
    if a != a or b != b:
        return math.nan
    return a if a > b else b


@numba.njit(**LEAF)
def nan_min(a: float, b: float) -> float:
    """numpy.minimum of two floats (NaN propagates)."""
    if a != a or b != b:
        return math.nan
    return a if a < b else b


__all__ = [
    "CONE_DTYPE", "CONSTRAINT_DTYPE", "GAIN_DTYPE", "MAX_CONES", "MAX_ROWS", "TABLE_DTYPE", "ZOH_CHECKS", "ZOH_ROWS",
    "angle_rate_error", "constraint_record", "drive_lag", "hard", "lag_response", "measurement_errors", "nan_max",
    "general_inertia_error_bound", "inertia_error", "inertia_error_bound", "inertia_shape", "nan_min",
    "predicted_errors", "second_order", "speed_limit_row",
]  # fmt: skip
