"""Battery charge: E >= E_min.

    h_batt = E - E_min                                         (J; relative degree 3)
    Psi_0  = E - E_min - margin - delta2 theta_SI              theta_SI: sun incidence on the panel, [0, pi]
                                                               (`power.panel_normal_body`, the paper's +k_B)
    Psi_1  = Psi_0' + k1 Psi_0,   BC = Psi_0''(u) + k1 Psi_0' + k2 Psi_1 + bias >= 0   (HOCBF)

    E_dot  = P_peak L max(0, cos theta_SI) - P_out                (`dynamics.spacecraft.net_power`)
    E_ddot = P_peak L [cos theta_SI > 0] d/dt cos theta_SI

L: 1 in sunlight, 0 in the Earth's shadow (`environment.eclipse`). With an eclipse, Psi_0 also keeps the
eclipse's floor F(theta_S) (`eclipse_floor`: the energy the load needs to the shadow's end, reached at a rate
the panel can give ahead of it): Psi_0 = E - E_min - F - margin - delta2 theta_SI (docs/eclipse.md).

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
from rta_attitude.dynamics.environment import sunlit
from rta_attitude.dynamics.spacecraft import net_power
from rta_attitude.jit import LEAF


@numba.njit(**LEAF)
def eclipse_floor(theta_S: float, p: np.void) -> tuple[float, float]:
    """The eclipse's floor above E_min at theta_S (J) and its time derivative (W) (docs/eclipse.md): in the
    shadow, what the load draws until it ends, L tau_out (falling at L, as E does there); in sunlight,
    L T_ecl less eclipse_ramp_W times the time until the shadow begins (rising at that rate from 0 where the
    shadow ends). Continuous; (0, 0) without an eclipse. theta_S falls at n: the shadow is
    theta_S in (pi - a, pi + a), a = p.eclipse_half_arc_rad, entered at pi + a."""
    a = p.eclipse_half_arc_rad
    if not a > 0.0:
        return 0.0, 0.0
    n = p.mean_motion_rad_s
    past = (theta_S - (math.pi - a)) % (2.0 * math.pi)  # theta_S's way to the shadow's end, rad
    if past < 2.0 * a:  # in the shadow for past / n s more
        return p.load_W * past / n, -p.load_W
    to_shadow_s = (past - 2.0 * a) / n
    return max(0.0, p.load_W * (2.0 * a / n) - p.eclipse_ramp_W * to_shadow_s), p.eclipse_ramp_W


@numba.njit(**LEAF)
def _eclipse_floors(theta_S: NDArray[np.float64], p: np.void, out: NDArray[np.float64]) -> None:
    for k in range(theta_S.shape[0]):
        out[k] = eclipse_floor(theta_S[k], p)[0]


def eclipse_floors(theta_S: NDArray[np.float64], p: np.void) -> NDArray[np.float64]:
    """`eclipse_floor`'s floor (J) at each theta_S (n,) (p: a PLANT_DTYPE record): the numpy face."""
    th = np.ascontiguousarray(theta_S, dtype=np.float64)
    out = np.empty_like(th)
    _eclipse_floors(th, p, out)
    return out


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
    lit, floor, floor_dot = 1.0, 0.0, 0.0
    if p.eclipse_half_arc_rad > 0.0:
        lit = sunlit(p.sun_cos_beta * math.cos(x[12]), p.shadow_sx)
        floor, floor_dot = eclipse_floor(x[12], p)
    E_dot = net_power(cp, lit, p)
    E_ddot = p.panel_peak_W * lit * (1.0 if cp > 0 else 0.0) * cp_dot
    d2 = c.delta2_J_rad
    psi0 = t.h[i] - floor - g.margin - d2 * th
    e = c.err_att_rad
    if e > 0.0 or c.err_E_J > 0.0:  # measurement-robust margin (docs/noise.md)
        psi0 -= c.err_E_J + d2 * e + (p.panel_peak_W * e + d2 * angle_rate_error(math.sin(th), x, c)) / g.k1
    second_order(t, i, psi0, E_dot - floor_dot - d2 * th_dot, E_ddot - d2 * th_dd, g)
    t.gain[i, 0], t.gain[i, 1], t.gain[i, 2] = -d2 * g0, -d2 * g1, -d2 * g2
