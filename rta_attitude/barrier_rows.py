"""The barrier rows and the box of ONE state, compiled (numba): what the filter evaluates each call.

`constraints/` is the readable definition of every barrier (one module per constraint, vectorised
over state batches, checked against finite differences). This module is its port to scalar code
for one state, compiled by numba, because a filter call must take microseconds: the numpy version
costs ~1 us per array operation and a call needs several hundred (measured: ~1.5 ms per call).
`rows_one` gives, for each constraint in CONSTRAINT_NAMES order, h, Psi_0, Psi_1 and the affine
barrier condition BC_i(u) = drift_i + gain_i . u, plus the box lo <= u <= hi (U, intersected with
the one-step zero-order-hold bounds on omega and psi in the `robust` preset) exactly as
`constraints.ConstraintSet.evaluate` and `asif.AsifFilter.box` define them; the tests compare the
two at random states and at the arccos poles (test/test_barrier_rows.py).

Body axes and the Earth direction are those of `model` (+i_B sensor, +j_B antenna, -j_B thermal
face, +k_B panel; Earth -x_Hill), fixed here as the spacecraft's geometry; `row_parameters` checks
that they still agree with `model`.

Parameters travel as one float vector (`row_parameters(cfg)`, indices P_*), so the compiled code
depends on no Python object.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from . import model
from .params import Config

Array = NDArray[np.float64]

N_CONSTRAINTS = 10
"""Rows in CONSTRAINT_NAMES order: exclusion_zone, communication, temperature, battery,
omega_x/y/z (4..6), psi_x/y/z (7..9)."""
EZ, COMM, TEMP_ROW, BATT = 0, 1, 2, 3

# indices into the parameter vector
(P_J1, P_J2, P_J3, P_CG1, P_CG2, P_CG3, P_N, P_SIN_GUARD,
 P_EZ_LIMIT, P_COMM_LIMIT, P_T_MAX, P_E_MIN, P_W_MAX, P_PSI_MAX,
 P_EZ_MARGIN, P_COMM_MARGIN, P_T_MARGIN, P_E_MARGIN,
 P_EZ_K1, P_EZ_K2, P_EZ_BIAS, P_COMM_K1, P_COMM_K2, P_COMM_BIAS,
 P_T_K1, P_T_K2, P_T_BIAS, P_E_K1, P_E_K2, P_E_BIAS,
 P_W_K1, P_W_BIAS, P_PSI_K1, P_PSI_BIAS,
 P_HEAT_CAPACITY, P_SOLAR, P_ALBEDO, P_SIGMA_EPS_A, P_IR, P_EARTH_COEFF, P_VIEW_FACTOR, P_CLAMP_VIEW,
 P_D0, P_D1, P_D2, P_PEAK_W, P_LOAD_W,
 P_UMAX1, P_UMAX2, P_UMAX3, P_ROBUST, P_DT, P_ZOH_MARGIN, P_W_ENABLED, P_PSI_ENABLED,
 N_PARAMS) = range(56)  # fmt: skip


def row_parameters(cfg: Config) -> Array:
    """The parameter vector of `rows_one` for a configuration (units of `params`)."""
    geometry = {"SENSOR_AXIS_BODY": (1, 0, 0), "ANTENNA_AXIS_BODY": (0, 1, 0),
                "THERMAL_FACE_NORMAL_BODY": (0, -1, 0), "PANEL_NORMAL_BODY": (0, 0, 1),
                "EARTH_DIRECTION_HILL": (-1, 0, 0)}
    for name, v in geometry.items():
        if tuple(getattr(model, name)) != v:  # a programming error: the kernel hard-codes them
            raise AssertionError(f"barrier_rows assumes model.{name} = {v}")
    robust = cfg.filter.preset == "robust"
    th, env, L, b = cfg.thermal, cfg.environment, cfg.limits, cfg.barriers
    P = np.zeros(N_PARAMS)

    def margin(group: str) -> float:
        return float(b[group].margin) if robust else 0.0

    J, cg = cfg.spacecraft.inertia_kgm2, cfg.spacecraft.control_gain
    P[P_J1], P[P_J2], P[P_J3] = J
    P[P_CG1], P[P_CG2], P[P_CG3] = cg
    P[P_N] = env.mean_motion_rad_s
    P[P_SIN_GUARD] = math.sin(cfg.filter.pole_guard_rad)
    P[P_EZ_LIMIT], P[P_COMM_LIMIT] = L.exclusion_angle_rad, L.comm_angle_rad
    P[P_T_MAX], P[P_E_MIN] = L.temperature_max_K, L.energy_min_J
    P[P_W_MAX], P[P_PSI_MAX] = L.omega_max_rad_s, L.psi_max_rad_s
    P[P_EZ_MARGIN], P[P_COMM_MARGIN] = margin("exclusion_zone"), margin("communication")
    P[P_T_MARGIN], P[P_E_MARGIN] = margin("temperature"), margin("battery")
    for base, group in ((P_EZ_K1, "exclusion_zone"), (P_COMM_K1, "communication"), (P_T_K1, "temperature"),
                        (P_E_K1, "battery")):
        P[base], P[base + 1], P[base + 2] = b[group].k1, b[group].k2, b[group].bias
    P[P_W_K1], P[P_W_BIAS] = b["omega"].k1, b["omega"].bias
    P[P_PSI_K1], P[P_PSI_BIAS] = b["psi"].k1, b["psi"].bias
    P[P_HEAT_CAPACITY] = th.mass_kg * th.specific_heat_J_kgK
    solar = th.absorptivity * th.area_m2 * env.solar_constant_W_m2
    sigma_eps_A = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2
    P[P_SOLAR] = solar
    P[P_ALBEDO] = solar * env.albedo_factor
    P[P_SIGMA_EPS_A] = sigma_eps_A
    P[P_IR] = env.earth_temperature_K**4
    P[P_EARTH_COEFF] = (solar * env.albedo_factor
                        + env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2 * env.earth_temperature_K**4)
    P[P_VIEW_FACTOR] = env.earth_view_factor
    P[P_CLAMP_VIEW] = 1.0 if th.clamp_view_factor else 0.0
    P[P_D0], P[P_D1] = cfg.augmentation.delta0_K_rad, cfg.augmentation.delta1_K_rad
    P[P_D2] = cfg.augmentation.delta2_J_rad
    P[P_PEAK_W], P[P_LOAD_W] = cfg.power.peak_W, cfg.power.load_W
    P[P_UMAX1], P[P_UMAX2], P[P_UMAX3] = cfg.u_max_rad_s2
    P[P_ROBUST] = 1.0 if robust else 0.0
    P[P_DT] = cfg.filter.sample_time_s
    P[P_ZOH_MARGIN] = cfg.filter.zoh_margin
    P[P_W_ENABLED] = 1.0 if b["omega"].enabled else 0.0
    P[P_PSI_ENABLED] = 1.0 if b["psi"].enabled else 0.0
    return P


@numba.njit(cache=True, error_model="numpy")
def _max(a: float, b: float) -> float:
    """np.maximum for two floats (NaN propagates)."""
    if a != a or b != b:
        return math.nan
    return a if a > b else b


@numba.njit(cache=True, error_model="numpy")
def _min(a: float, b: float) -> float:
    """np.minimum for two floats (NaN propagates)."""
    if a != a or b != b:
        return math.nan
    return a if a < b else b


@numba.njit(cache=True, error_model="numpy")
def _pointing(ex: float, ey: float, ez: float, r: Array, rd: Array, rdd: Array, w: Array, wd: Array,
              cg: Array, sin_guard: float, out: Array, gout: Array) -> None:
    """`constraints.pointing.pointing` for one unit body axis e and a body-frame target r (with its
    rates rd, rdd in body axes). out = [cos, cos_dot, theta, theta_dot, theta_ddot_drift];
    gout = theta_ddot_gain (3,)."""
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
    out[0] = c
    out[1] = c_dot
    out[2] = math.atan2(sin_raw, c)
    if sin_raw > sin_guard:
        s = sin_raw
        out[3] = -c_dot / s
        out[4] = -c_dd_drift / s - c * c_dot**2 / s**3
        gout[0] = -(m0 * cg[0]) / s
        gout[1] = -(m1 * cg[1]) / s
        gout[2] = -(m2 * cg[2]) / s
    else:  # within the pole guard: the angle is held stationary (see constraints/pointing.py)
        out[3] = 0.0
        out[4] = 0.0
        gout[0] = 0.0
        gout[1] = 0.0
        gout[2] = 0.0


@numba.njit(cache=True, error_model="numpy")
def _second_order(i: int, psi0: float, d1: float, dd: float, k1: float, k2: float, bias: float,
                  psi0_out: Array, psi1_out: Array, drift: Array) -> None:
    """`constraints.base.second_order_condition` into row i."""
    psi1 = d1 + k1 * psi0
    psi0_out[i] = psi0
    psi1_out[i] = psi1
    drift[i] = dd + k1 * d1 + k2 * psi1 + bias


@numba.njit(cache=True, error_model="numpy")
def rows_one(x: Array, P: Array, h: Array, psi0: Array, psi1: Array, drift: Array, gain: Array,
             lo: Array, hi: Array) -> None:
    """Barrier rows and box of one state.

    Args:
        x: state (19,) with a unit quaternion, model units.
        P: `row_parameters(cfg)`.
        h, psi0, psi1, drift: outputs (10,), CONSTRAINT_NAMES order (units of each constraint).
        gain: output (10, 3), dBC/du.
        lo, hi: outputs (3,), rad/s^2: U, intersected with the ZOH bounds in the robust preset
            (where a ZOH interval misses U, both shrink to U's edge nearest to it).
    """
    q1, q2, q3, q4 = x[0], x[1], x[2], x[3]
    w = x[4:7]
    s11, s22, s33, s44 = q1 * q1, q2 * q2, q3 * q3, q4 * q4
    A = np.empty((3, 3))
    A[0, 0] = s11 - s22 - s33 + s44
    A[0, 1] = 2.0 * (q1 * q2 + q3 * q4)
    A[0, 2] = 2.0 * (q1 * q3 - q2 * q4)
    A[1, 0] = 2.0 * (q1 * q2 - q3 * q4)
    A[1, 1] = -s11 + s22 - s33 + s44
    A[1, 2] = 2.0 * (q2 * q3 + q1 * q4)
    A[2, 0] = 2.0 * (q1 * q3 + q2 * q4)
    A[2, 1] = 2.0 * (q2 * q3 - q1 * q4)
    A[2, 2] = -s11 - s22 + s33 + s44
    J1, J2, J3 = P[P_J1], P[P_J2], P[P_J3]
    wd = np.empty(3)
    wd[0] = (J2 - J3) * w[1] * w[2] / J1
    wd[1] = (J3 - J1) * w[2] * w[0] / J2
    wd[2] = (J1 - J2) * w[0] * w[1] / J3
    cg = P[P_CG1:P_CG3 + 1]
    n = P[P_N]
    cs, sn = math.cos(x[12]), math.sin(x[12])
    # sun r_S = (cos, sin, 0) in Hill, theta_S_dot = -n; rotated into body axes: A r
    rs, rsd, rsdd = np.empty(3), np.empty(3), np.empty(3)
    for i in range(3):
        rs[i] = A[i, 0] * cs + A[i, 1] * sn
        rsd[i] = A[i, 0] * (n * sn) + A[i, 1] * (-n * cs)
        rsdd[i] = A[i, 0] * (-(n * n) * cs) + A[i, 1] * (-(n * n) * sn)
    # Earth r_E = -x_Hill: A r_E = -A[:, 0], fixed in Hill
    re = np.empty(3)
    for i in range(3):
        re[i] = -A[i, 0]
    zero = np.zeros(3)
    guard = P[P_SIN_GUARD]
    pt = np.empty(5)
    gt = np.empty(3)
    gain[:, :] = 0.0

    # exclusion zone: +i_B to the sun
    _pointing(1.0, 0.0, 0.0, rs, rsd, rsdd, w, wd, cg, guard, pt, gt)
    h[EZ] = pt[2] - P[P_EZ_LIMIT]
    _second_order(EZ, h[EZ] - P[P_EZ_MARGIN], pt[3], pt[4], P[P_EZ_K1], P[P_EZ_K2], P[P_EZ_BIAS], psi0, psi1, drift)
    gain[EZ, :] = gt

    # communication: +j_B to the Earth, h = FOV/2 - theta
    _pointing(0.0, 1.0, 0.0, re, zero, zero, w, wd, cg, guard, pt, gt)
    h[COMM] = P[P_COMM_LIMIT] - pt[2]
    _second_order(COMM, h[COMM] - P[P_COMM_MARGIN], -pt[3], -pt[4], P[P_COMM_K1], P[P_COMM_K2], P[P_COMM_BIAS],
                  psi0, psi1, drift)
    gain[COMM, :] = -gt

    # temperature: -j_B face, sun and Earth incidence; Psi_temp augmented by the two angles
    ps, gs = np.empty(5), np.empty(3)
    pe, ge = np.empty(5), np.empty(3)
    _pointing(0.0, -1.0, 0.0, rs, rsd, rsdd, w, wd, cg, guard, ps, gs)
    _pointing(0.0, -1.0, 0.0, re, zero, zero, w, wd, cg, guard, pe, ge)
    T = x[10]
    clamp = P[P_CLAMP_VIEW] > 0.5
    F_E = P[P_VIEW_FACTOR] * (_max(0.0, pe[0]) if clamp else pe[0])
    flux = (P[P_SOLAR] * _max(0.0, ps[0]) + P[P_ALBEDO] * F_E + P[P_SIGMA_EPS_A] * F_E * P[P_IR]
            - P[P_SIGMA_EPS_A] * T**4)
    T_dot = flux / P[P_HEAT_CAPACITY]
    earth_on = (1.0 if pe[0] > 0 else 0.0) if clamp else 1.0
    sun_lit = 1.0 if ps[0] > 0 else 0.0
    T_ddot = (P[P_SOLAR] * sun_lit * ps[1] + P[P_EARTH_COEFF] * P[P_VIEW_FACTOR] * earth_on * pe[1]
              - 4 * P[P_SIGMA_EPS_A] * T**3 * T_dot) / P[P_HEAT_CAPACITY]
    d0, d1 = P[P_D0], P[P_D1]
    half_pi = math.pi / 2
    sun_on = 1.0 if ps[2] < half_pi else 0.0
    earth_in = 1.0 if pe[2] < half_pi else 0.0
    h[TEMP_ROW] = P[P_T_MAX] - T
    p0 = h[TEMP_ROW] - P[P_T_MARGIN] - d0 * _max(0.0, half_pi - ps[2]) - d1 * _max(0.0, half_pi - pe[2])
    p0_dot = -T_dot + d0 * sun_on * ps[3] + d1 * earth_in * pe[3]
    p0_dd = -T_ddot + d0 * sun_on * ps[4] + d1 * earth_in * pe[4]
    _second_order(TEMP_ROW, p0, p0_dot, p0_dd, P[P_T_K1], P[P_T_K2], P[P_T_BIAS], psi0, psi1, drift)
    for a in range(3):
        gain[TEMP_ROW, a] = d0 * sun_on * gs[a] + d1 * earth_in * ge[a]

    # battery: +k_B panel to the sun; Psi_batt = E - E_min - delta2 theta_SI
    _pointing(0.0, 0.0, 1.0, rs, rsd, rsdd, w, wd, cg, guard, pt, gt)
    h[BATT] = x[11] - P[P_E_MIN]
    E_dot = P[P_PEAK_W] * _max(0.0, pt[0]) - P[P_LOAD_W]
    E_ddot = P[P_PEAK_W] * (1.0 if pt[0] > 0 else 0.0) * pt[1]
    d2 = P[P_D2]
    _second_order(BATT, h[BATT] - P[P_E_MARGIN] - d2 * pt[2], E_dot - d2 * pt[3], E_ddot - d2 * pt[4],
                  P[P_E_K1], P[P_E_K2], P[P_E_BIAS], psi0, psi1, drift)
    for a in range(3):
        gain[BATT, a] = -d2 * gt[a]

    # angular rate and wheel speed (relative degree 1)
    w_max2 = P[P_W_MAX] ** 2
    p_max2 = P[P_PSI_MAX] ** 2
    for a in range(3):
        wa = w[a]
        hw = w_max2 - wa * wa
        h[4 + a] = hw
        psi0[4 + a] = hw
        psi1[4 + a] = hw
        gain[4 + a, a] = -2.0 * wa * cg[a]
        drift[4 + a] = -2.0 * wa * wd[a] + P[P_W_K1] * hw + P[P_W_BIAS]
        pa = x[7 + a]
        hp = p_max2 - pa * pa
        h[7 + a] = hp
        psi0[7 + a] = hp
        psi1[7 + a] = hp
        gain[7 + a, a] = -2.0 * pa
        drift[7 + a] = P[P_PSI_K1] * hp + P[P_PSI_BIAS]

    # the box: U, and in the robust preset the one-step ZOH bounds on omega and psi
    dt = P[P_DT]
    for a in range(3):
        u_max = P[P_UMAX1 + a]
        lo_a, hi_a = -u_max, u_max
        if P[P_ROBUST] > 0.5:
            zlo, zhi = -math.inf, math.inf
            if P[P_W_ENABLED] > 0.5:
                limit = (1.0 - P[P_ZOH_MARGIN]) * P[P_W_MAX]
                w_free = w[a] + wd[a] * dt
                ua = (limit - w_free) / (cg[a] * dt)
                ub = (-limit - w_free) / (cg[a] * dt)
                zlo = _max(zlo, _min(ua, ub))
                zhi = _min(zhi, _max(ua, ub))
            if P[P_PSI_ENABLED] > 0.5:
                limit = (1.0 - P[P_ZOH_MARGIN]) * P[P_PSI_MAX]
                zlo = _max(zlo, (-limit - x[7 + a]) / dt)
                zhi = _min(zhi, (limit - x[7 + a]) / dt)
            new_lo, new_hi = _max(lo_a, zlo), _min(hi_a, zhi)
            if new_lo > new_hi:  # the ZOH interval misses U: the edge of U nearest to it
                edge = lo_a if zhi < lo_a else hi_a
                lo_a, hi_a = edge, edge
            else:
                lo_a, hi_a = new_lo, new_hi
        lo[a] = lo_a
        hi[a] = hi_a


@numba.njit(cache=True, error_model="numpy")
def rows_many(X: Array, P: Array, h: Array, psi0: Array, psi1: Array, drift: Array, gain: Array,
              lo: Array, hi: Array) -> None:
    """`rows_one` for states X (N, 19) into outputs with a leading N axis."""
    for k in range(X.shape[0]):
        rows_one(X[k], P, h[k], psi0[k], psi1[k], drift[k], gain[k], lo[k], hi[k])


def evaluate(x: Array, cfg: Config | None = None, P: Array | None = None) -> dict[str, Array]:
    """Rows and box of states x (19,) or (N, 19) (unit quaternions), as arrays keyed h, psi0, psi1,
    drift, gain, lo, hi. A convenience for tests and tools; the filter calls the kernels directly."""
    if P is None:
        if cfg is None:
            raise ValueError("evaluate needs cfg or P")
        P = row_parameters(cfg)
    X = np.atleast_2d(np.asarray(x, dtype=float))
    N = X.shape[0]
    out = {k: np.empty((N, N_CONSTRAINTS)) for k in ("h", "psi0", "psi1", "drift")}
    out["gain"] = np.empty((N, N_CONSTRAINTS, 3))
    out["lo"], out["hi"] = np.empty((N, 3)), np.empty((N, 3))
    rows_many(np.ascontiguousarray(X), P, out["h"], out["psi0"], out["psi1"], out["drift"], out["gain"],
              out["lo"], out["hi"])
    if np.ndim(x) == 1:
        return {k: v[0] for k, v in out.items()}
    return out


__all__ = ["N_CONSTRAINTS", "evaluate", "row_parameters", "rows_many", "rows_one"]
