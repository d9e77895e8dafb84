"""Battery charge: E >= E_min.

    h_batt = E - E_min                                         (J; relative degree 3)
    Psi_0  = E - E_min - margin - delta2 theta_SI              theta_SI: sun incidence on the panel, [0, pi]
                                                               (`power.panel_normal_body`, the paper's +k_B)
    Psi_1  = Psi_0' + k1 Psi_0,   BC = Psi_0''(u) + k1 Psi_0' + k2 Psi_1 + bias >= 0   (HOCBF)

    E_dot  = P_peak max(0, cos theta_SI) - P_out                  (`dynamics.spacecraft.net_power`)
    E_ddot = P_peak [cos theta_SI > 0] d/dt cos theta_SI

Psi_0 has relative degree 2. Singular (arccos) at theta_SI = 0 (panel on the sun, the safest
attitude) and pi.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import angle_rate_error, second_order
from rta_attitude.constraints.geometry import pointing
from rta_attitude.dynamics.spacecraft import net_power
from rta_attitude.jit import LEAF


@numba.njit(**LEAF)
def h(ctx: np.void, x: NDArray[np.float64], c: np.void) -> float:
    """E - E_min (J); negative = the battery is below its minimum."""
    return x[11] - c.energy_min_J


@numba.njit(**LEAF)
def row(ctx: np.void, x: NDArray[np.float64], c: np.void, p: np.void, t: np.void) -> None:
    """h, HOCBF levels and the barrier row of the battery into table t (p: the plant model)."""
    i = c.row_battery
    g = c.gains[i]
    cp, cp_dot, th, th_dot, th_dd, g0, g1, g2 = pointing(p.panel_normal[0], p.panel_normal[1], p.panel_normal[2],
                                                         ctx.sun, ctx.sun_rate, ctx.sun_acc, ctx, c.sin_pole_guard)
    t.h[i] = x[11] - c.energy_min_J
    E_dot = net_power(cp, p)
    E_ddot = p.panel_peak_W * (1.0 if cp > 0 else 0.0) * cp_dot
    d2 = c.delta2_J_rad
    psi0 = t.h[i] - g.margin - d2 * th
    e = c.err_att_rad
    if e > 0.0 or c.err_E_J > 0.0:  # measurement-robust margin (docs/noise.md)
        psi0 -= c.err_E_J + d2 * e + (p.panel_peak_W * e + d2 * angle_rate_error(math.sin(th), x, c)) / g.k1
    second_order(t, i, psi0, E_dot - d2 * th_dot, E_ddot - d2 * th_dd, g)
    t.gain[i, 0], t.gain[i, 1], t.gain[i, 2] = -d2 * g0, -d2 * g1, -d2 * g2
