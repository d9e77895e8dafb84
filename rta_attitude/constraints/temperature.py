"""Temperature of the thermal node's face (`thermal.face_normal_body`, the paper's -j_B): T <= T_max.

    h_temp   = T_max - T                                                  (K; relative degree 3)
    Psi_0    = T_max - T - margin - delta0 max(0, pi/2 - theta_SI) - delta1 max(0, pi/2 - theta_EI)
    Psi_1    = Psi_0' + k1 Psi_0,   BC = Psi_0''(u) + k1 Psi_0' + k2 Psi_1 + bias >= 0   (HOCBF)

theta_SI / theta_EI: sun / Earth incidence angles of the face normal. Psi_0 <= h_temp and has
relative degree 2 (u enters theta_ddot); the clamps (SPEC sec. 4, [resolved]) give the zero gradient
the paper mentions when the face sees neither sun nor Earth. With c_S, c_E the incidence cosines:

    T_dot  = (alpha A S max(0, c_S) + (alpha A S A_f + sigma eps A T_E^4) F max(0, c_E)
              - sigma eps A T^4) / (m c_p)                          (`dynamics.spacecraft.thermal_rate`)
    T_ddot = (alpha A S [c_S > 0] c_S_dot + (alpha A S A_f + sigma eps A T_E^4) F [c_E > 0] c_E_dot
              - 4 sigma eps A T^3 T_dot) / (m c_p)                  (no u: T has relative degree 3)

([c_E > 0] is 1 when the view factor is not clamped.) With an eclipse (`environment.eclipse`) the rows keep
the sunlit law: in the shadow the face only cools (the plant drops the sun's and the albedo's heat), and where
the shadow ends the heat returns at once, a jump in T_dot that the sunlit law has held all along.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import angle_rate_error, nan_max, second_order
from rta_attitude.constraints.geometry import pointing
from rta_attitude.dynamics.spacecraft import thermal_rate
from rta_attitude.jit import LEAF


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void) -> float:
    """T_max - T (K); negative = too hot."""
    return c.temperature_max_K - x[10]


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, p: np.void, t: np.void) -> None:
    """h, HOCBF levels and the barrier row of the temperature into table t (p: the plant model)."""
    i = c.row_temperature
    g = c.gains[i]
    guard = c.sin_pole_guard
    f0, f1, f2 = p.face_normal[0], p.face_normal[1], p.face_normal[2]
    cs, cs_dot, th_s, th_s_dot, th_s_dd, gs0, gs1, gs2 = pointing(f0, f1, f2, ctx.sun, ctx.sun_rate, ctx.sun_acc,
                                                                  ctx, guard)
    ce, ce_dot, th_e, th_e_dot, th_e_dd, ge0, ge1, ge2 = pointing(f0, f1, f2, ctx.earth, ctx.earth_rate,
                                                                  ctx.earth_acc, ctx, guard)
    T = x[10]
    T_dot = thermal_rate(cs, ce, T, 1.0, p)  # the sun always (an eclipse only cools: module docstring)
    earth_coeff = p.albedo_W + p.sigma_eps_A_W_K4 * p.earth_T4_K4
    earth_on = (1.0 if ce > 0 else 0.0) if p.clamp_view_factor else 1.0
    sun_lit = 1.0 if cs > 0 else 0.0
    T_ddot = (p.solar_W * sun_lit * cs_dot + earth_coeff * p.earth_view_factor * earth_on * ce_dot
              - 4 * p.sigma_eps_A_W_K4 * T**3 * T_dot) / p.heat_capacity_J_K
    d0, d1 = c.delta0_K_rad, c.delta1_K_rad
    half_pi = math.pi / 2
    sun_on = 1.0 if th_s < half_pi else 0.0
    earth_in = 1.0 if th_e < half_pi else 0.0
    t.h[i] = c.temperature_max_K - T
    psi0 = t.h[i] - g.margin - d0 * nan_max(0.0, half_pi - th_s) - d1 * nan_max(0.0, half_pi - th_e)
    e = c.err_att_rad
    if e > 0.0 or c.err_T_K > 0.0:  # measurement-robust margin (docs/noise.md)
        T_hi = T + c.err_T_K
        T_dot_err = ((p.solar_W + earth_coeff * p.earth_view_factor) * e
                     + 4.0 * p.sigma_eps_A_W_K4 * T_hi * T_hi * T_hi * c.err_T_K) / p.heat_capacity_J_K
        s_near = 1.0 if th_s < half_pi + e else 0.0
        e_near = 1.0 if th_e < half_pi + e else 0.0
        rate_err = (T_dot_err + d0 * s_near * angle_rate_error(math.sin(th_s), x, c)
                    + d1 * e_near * angle_rate_error(math.sin(th_e), x, c))
        psi0 -= c.err_T_K + (d0 * s_near + d1 * e_near) * e + rate_err / g.k1
    psi0_dot = -T_dot + d0 * sun_on * th_s_dot + d1 * earth_in * th_e_dot
    psi0_dd = -T_ddot + d0 * sun_on * th_s_dd + d1 * earth_in * th_e_dd
    second_order(t, i, psi0, psi0_dot, psi0_dd, g)
    t.gain[i, 0] = d0 * sun_on * gs0 + d1 * earth_in * ge0
    t.gain[i, 1] = d0 * sun_on * gs1 + d1 * earth_in * ge1
    t.gain[i, 2] = d0 * sun_on * gs2 + d1 * earth_in * ge2
