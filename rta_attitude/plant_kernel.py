"""The plant's zero-order-hold step for ONE state, compiled (numba): `simulation.integrate`'s work.

`model` defines the plant (vectorised, readable); `simulation.rk4_step` the integrator. Integrating
one 1 s sample takes 10 RK4 substeps = 40 evaluations of x_dot, which cost ~1.5 ms in numpy on
one state and are the serial bottleneck of the DDS loop (the plant node) and of `simulate`.
`integrate_hold` performs the same floating-point operations in the same order as
`model.state_derivative` (through `model._drift_one`) and `simulation.rk4_step`, so its results
are bit-identical with them and with the Monte Carlo batch's plant (`batch._Plant`); the tests
check both (test_simulation.py, test_montecarlo.py). Transcendentals (cos, sin, pow) are the same
libm calls numpy makes on this platform; constants are formed in Python exactly as `model` forms
them (`plant_parameters`).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from .params import Config

Array = NDArray[np.float64]

(K_J1, K_J2, K_J3, K_CG1, K_CG2, K_CG3, K_N, K_HEAT_CAPACITY, K_VIEW_FACTOR, K_CLAMP_VIEW, K_SIGMA_EPS_A,
 K_SOLAR, K_ALBEDO, K_EARTH_T4, K_PEAK_W, K_LOAD_W, K_CW_3N2, K_CW_2N, K_CW_M2N, K_CW_MN2,
 N_PLANT_PARAMS) = range(21)  # fmt: skip


def plant_parameters(cfg: Config) -> Array:
    """The parameter vector of `integrate_hold`, each entry computed as `model` computes it."""
    th, env = cfg.thermal, cfg.environment
    K = np.zeros(N_PLANT_PARAMS)
    K[K_J1], K[K_J2], K[K_J3] = cfg.spacecraft.inertia_kgm2
    K[K_CG1], K[K_CG2], K[K_CG3] = cfg.spacecraft.control_gain
    n = cfg.environment.mean_motion_rad_s
    K[K_N] = n
    K[K_HEAT_CAPACITY] = cfg.thermal.mass_kg * cfg.thermal.specific_heat_J_kgK
    K[K_VIEW_FACTOR] = env.earth_view_factor
    K[K_CLAMP_VIEW] = 1.0 if th.clamp_view_factor else 0.0
    K[K_SIGMA_EPS_A] = env.stefan_boltzmann_W_m2K4 * th.emissivity * th.area_m2
    K[K_SOLAR] = th.absorptivity * th.area_m2 * env.solar_constant_W_m2
    K[K_ALBEDO] = th.absorptivity * th.area_m2 * env.solar_constant_W_m2 * env.albedo_factor
    K[K_EARTH_T4] = env.earth_temperature_K**4
    K[K_PEAK_W], K[K_LOAD_W] = cfg.power.peak_W, cfg.power.load_W
    K[K_CW_3N2], K[K_CW_2N], K[K_CW_M2N], K[K_CW_MN2] = 3 * n**2, 2 * n, -2 * n, -(n**2)
    return K


@numba.njit(cache=True, error_model="numpy")
def _positive_part(c: float) -> float:
    """np.maximum(0.0, c): 0.0 for c <= 0 (also -0.0), NaN stays NaN."""
    return c if (c > 0.0 or c != c) else 0.0


@numba.njit(cache=True, error_model="numpy")
def _derivative(x: Array, u: Array, K: Array, f: Array) -> None:
    """`model.state_derivative` of one state (19,) into f, operation for operation."""
    q1, q2, q3, q4, w1, w2, w3 = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    J1, J2, J3 = K[K_J1], K[K_J2], K[K_J3]
    th = x[12]
    cs, sn = math.cos(th), math.sin(th)
    a10, a11 = 2.0 * (q1 * q2 - q3 * q4), -q1 * q1 + q2 * q2 - q3 * q3 + q4 * q4
    a20, a21 = 2.0 * (q1 * q3 + q2 * q4), 2.0 * (q2 * q3 - q1 * q4)
    # model.thermal_fluxes(cos_sun, cos_earth, T)
    cos_sun = -(a10 * cs + a11 * sn)
    cos_earth = a10
    F_E = K[K_VIEW_FACTOR] * (_positive_part(cos_earth) if K[K_CLAMP_VIEW] > 0.5 else cos_earth)
    sigma_eps_A = K[K_SIGMA_EPS_A]
    q_solar = K[K_SOLAR] * _positive_part(cos_sun)
    q_albedo = K[K_ALBEDO] * F_E
    q_ir = sigma_eps_A * F_E * K[K_EARTH_T4]
    q_rejected = sigma_eps_A * math.pow(x[10], 4.0)
    T_dot = (q_solar + q_albedo + q_ir - q_rejected) / K[K_HEAT_CAPACITY]
    c_panel = a20 * cs + a21 * sn
    n = K[K_N]
    f[0] = 0.5 * (q4 * w1 - q3 * w2 + q2 * w3)
    f[1] = 0.5 * (q3 * w1 + q4 * w2 - q1 * w3)
    f[2] = 0.5 * (-q2 * w1 + q1 * w2 + q4 * w3)
    f[3] = -0.5 * (q1 * w1 + q2 * w2 + q3 * w3)
    f[4] = (J2 - J3) * w2 * w3 / J1 + K[K_CG1] * u[0]
    f[5] = (J3 - J1) * w3 * w1 / J2 + K[K_CG2] * u[1]
    f[6] = (J1 - J2) * w1 * w2 / J3 + K[K_CG3] * u[2]
    f[7] = 0.0 + u[0]
    f[8] = 0.0 + u[1]
    f[9] = 0.0 + u[2]
    f[10] = T_dot
    f[11] = K[K_PEAK_W] * _positive_part(c_panel) - K[K_LOAD_W]
    f[12] = -n
    f[13], f[14], f[15] = x[16], x[17], x[18]
    f[16] = K[K_CW_3N2] * x[13] + K[K_CW_2N] * x[17]
    f[17] = K[K_CW_M2N] * x[16]
    f[18] = K[K_CW_MN2] * x[15]


@numba.njit(cache=True, error_model="numpy")
def integrate_hold(x0: Array, u: Array, dt_s: float, substeps: int, K: Array, out: Array) -> None:
    """Hold u (3,) (already saturated) over dt_s from x0 (19,) with `substeps` classical RK4 steps,
    renormalising the quaternion after each (`simulation.rk4_step`). out (substeps, 19) receives the
    state after each substep; out[-1] is x(t + dt)."""
    n = x0.shape[0]
    h = dt_s / substeps
    half = 0.5 * h
    sixth = h / 6.0
    x = x0.copy()
    k1, k2, k3, k4, y = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for j in range(substeps):
        _derivative(x, u, K, k1)
        for i in range(n):
            y[i] = x[i] + half * k1[i]
        _derivative(y, u, K, k2)
        for i in range(n):
            y[i] = x[i] + half * k2[i]
        _derivative(y, u, K, k3)
        for i in range(n):
            y[i] = x[i] + h * k3[i]
        _derivative(y, u, K, k4)
        for i in range(n):
            x[i] = x[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
        for i in range(4):
            x[i] = x[i] / norm
        out[j, :] = x


def compile_kernel(cfg: Config) -> float:
    """Compile `integrate_hold` (or load it from numba's cache) by one step of a dummy state, so the
    first real step does not wait for it. Returns the seconds it took."""
    import time

    t0 = time.perf_counter()
    x = np.zeros(19)
    x[3], x[10], x[11] = 1.0, 273.15, 5000.0
    integrate_hold(x, np.zeros(3), 1.0, 1, plant_parameters(cfg), np.empty((1, 19)))
    return time.perf_counter() - t0


__all__ = ["compile_kernel", "integrate_hold", "plant_parameters"]
