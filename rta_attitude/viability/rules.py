"""Rules that PROVE a state unrecoverable over a horizon (no admissible command sequence keeps the
enforced constraints at every substep). IPOPT's failure never proves anything; only these do.

- `violated_at_x0`: an enforced h(x0) < 0 (the sample at t = 0 is already unsafe).
- `battery_drain` (`battery_rule`): E must fall below E_min at a substep time <= horizon.
- `temperature_heating` (`temperature_rule`): T must rise above T_max at a substep time <= horizon.

The two physical rules bound how fast the panel (or the hot face) can turn away from (towards)
the sun, which needs the rate constraint to be enforced (`rate_envelope`), and they are proved for
the exact ODE with any input in U: the constraints are only checked at the substep times, so the
rates between them are bounded from the dynamics. They apply to the model the proofs are written
for: Hill frame inertial, no gravity-gradient torque and, for the gyrostat, torque sign +1
(H = J w - D psi conserved in magnitude); otherwise they do not fire (`rules_apply`). Small
margins (RULE_DELTA_E, RULE_DELTA_T) cover the gap between RK4 and the exact ODE.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.viability.model import attitude_matrix, constraint_values, sun_hill
from rta_attitude.viability.params import OracleModel

Array = NDArray[np.float64]

RULES: tuple[str, ...] = ("violated_at_x0", "battery_drain", "temperature_heating")
RULE_DELTA_E_J = 0.1
"""Energy margin of the battery rule, J (RK4 vs exact ODE: measured < 1.4e-3 J over 2,000 s)."""
RULE_DELTA_T_K = 1e-3
"""Temperature margin of the temperature rule, K (RK4 vs exact ODE: measured < 1e-6 K)."""


def rules_apply(m: OracleModel) -> bool:
    """The physical rules' proofs hold for this model (module docstring)."""
    return m.frame_rate_rad_s == 0.0 and not m.gravity_gradient and (m.torque_sign == 1.0 or not m.gyrostat)


def rate_envelope(x0: Array, m: OracleModel) -> tuple[float, Array]:
    """(w_hi, a): |w_i(t)| <= w_hi and |w_dot_i(t)| <= a_i for all t on every trajectory of the exact
    ODE that keeps |w_i| <= w_max at t = 0 and at every substep time (spacing h) with u in U.

    Acceleration: J_i |w_dot_i| <= D U_i + |w x H|, |w| <= sqrt(3) |w|_inf. Gyrostat: H = J w - D psi
    has H_dot = -w x H for every input, so |H| = |H(x0)| and |w x H| <= sqrt(3) W |H| when
    |w|_inf <= W. Paper model: |w x J w| = |w x (J - J_min I) w| <= 3 W^2 (J_max - J_min). a_i(W) is
    the resulting bound.
    Stage 1 (one-sided): let W1 satisfy w_max + h max_i a_i(W1) < W1. If |w|_inf ever exceeded W1,
    at the first time S it reaches W1, a(W1) held on [0, S]; the last substep time t_j <= S has
    |w_i(t_j)| <= w_max and S - t_j < h, so |w_i(S)| < W1: a contradiction.
    Stage 2 (two-sided): with |w|_inf <= W_k everywhere, every t is within h/2 of a substep time (or
    of t = 0), so |w_i(t)| <= w_max + a_i(W_k) h/2 =: W_{k+1}, again valid everywhere; iterate.
    """
    h = m.dt_s / m.substeps
    J = m.J
    w_max = m.omega_max_rad_s
    base = m.wheel_inertia_kgm2 * m.u_max / J
    spread = float(np.max(J) - np.min(J))
    h_norm = float(np.linalg.norm(J * x0[4:7] - m.wheel_inertia_kgm2 * x0[7:10]))

    def accel(w_inf: float) -> Array:
        if m.gyrostat:
            return base + math.sqrt(3.0) * w_inf * h_norm / J
        return base + 3.0 * w_inf**2 * spread / J

    w1 = w_max
    for _ in range(1000):  # smallest fixed point of W = w_max + h max a(W), from below
        w_next = w_max + h * float(np.max(accel(w1)))
        if w_next - w1 < 1e-15:
            break
        w1 = w_next
    w1 *= 1.0 + 1e-6
    if not w_max + h * float(np.max(accel(w1))) < w1:
        raise ValueError("the rate envelope does not close (substeps too long for these limits)")
    w_hi = w1
    for _ in range(50):
        w_hi = w_max + 0.5 * h * float(np.max(accel(w_hi)))
    return w_hi, accel(w_hi)


def _turn_bound(w0: Array, a: Array, w_hi: float, axes: tuple[int, int], t: Array) -> Array:
    """Upper bound of the angle a body axis e can have turned by times t: |e_dot| = |w x e| =
    sqrt(sum over the two axes perpendicular to e of w_i^2), |w_i(t)| <= min(w_hi, |w_i(0)| + a_i t);
    the right Riemann sum bounds the integral of this non-decreasing integrand from above."""
    sq = np.zeros_like(t)
    for i in axes:
        sq += np.minimum(w_hi, abs(w0[i]) + a[i] * t) ** 2
    return np.cumsum(np.diff(np.concatenate([[0.0], t])) * np.sqrt(sq))


def _angle(u: Array, v: Array) -> float:
    return math.acos(max(-1.0, min(1.0, float(u @ v) / float(np.linalg.norm(u) * np.linalg.norm(v)))))


def _grid(horizon_s: float, m: OracleModel) -> Array:
    h = m.dt_s / m.substeps
    return h * np.arange(1, round(horizon_s / h) + 1, dtype=np.float64)


def battery_rule(x0: Array, horizon_s: float, m: OracleModel) -> str:
    """A non-empty explanation if E < E_min at some substep time <= horizon for every admissible input.

    Proof. phi(t), the angle between the panel normal k_B and r_S, is a distance on the sphere, so
    |phi_dot| <= |k_dot| + |r_S_dot| = sqrt(w1^2 + w2^2) + n. With `rate_envelope`,
    phi(t) >= phi_lb(t) = max(0, phi(0) - Phi(t) - n t) (`_turn_bound`). max(0, cos .) falls on [0, pi],
    so E_dot <= P_peak max(0, cos phi_lb(t)) - P_out, non-decreasing in t: its right Riemann sum on the
    substep grid bounds E(t_k) from above. If that bound is < E_min - delta_E at some t_k <= horizon,
    E(t_k) < E_min for every admissible input.
    """
    t = _grid(horizon_s, m)
    if len(t) == 0 or not rules_apply(m):
        return ""
    w_hi, a = rate_envelope(x0, m)
    k_hill = attitude_matrix(x0[0:4]).T @ np.array([0.0, 0.0, 1.0])
    phi0 = _angle(k_hill, sun_hill(float(x0[12])))
    phi_lb = np.maximum(0.0, phi0 - _turn_bound(x0[4:7], a, w_hi, (0, 1), t) - m.mean_motion_rad_s * t)
    h = m.dt_s / m.substeps
    e_ub = x0[11] + np.cumsum(h * (m.panel_peak_W * np.maximum(0.0, np.cos(phi_lb)) - m.load_W))
    k = int(np.argmin(e_ub))
    if e_ub[k] < m.energy_min_J - RULE_DELTA_E_J:
        return (f"panel {math.degrees(phi0):.1f} deg from the sun; even turning at the rate bound, "
                f"E <= {e_ub[k]:.1f} J < E_min at t = {t[k]:.1f} s")
    return ""


def temperature_rule(x0: Array, horizon_s: float, m: OracleModel) -> str:
    """A non-empty explanation if T > T_max at some substep time <= horizon for every admissible input.

    Proof. f = -j_B, phi_s and phi_e its angles to r_S and r_E. As in `battery_rule`,
    phi_s(t) <= min(pi, phi_s(0) + Phi(t) + n t) and phi_e(t) <= min(pi, phi_e(0) + Phi(t)), with
    |f_dot| <= sqrt(w1^2 + w3^2). The heat input Q(t) >= Q_lb(t) (the same with the angles at their
    bounds), non-increasing in t (so its right Riemann sum is a lower bound). Let T* = T_max + eta,
    eta = Tdot_max h/2 + delta_T, Tdot_max >= |T_dot| near T*. While T <= T*,
    T_dot >= (Q_lb - sigma eps A T*^4) / (m c_p); if the sum of that exceeds T* - T(0) by some
    t_k <= horizon, T reaches T* at some tau <= t_k, and the substep time within h/2 of tau has
    T >= T* - Tdot_max h/2 > T_max.
    """
    t = _grid(horizon_s, m)
    if len(t) == 0 or not rules_apply(m):
        return ""
    w_hi, a = rate_envelope(x0, m)
    f_hill = attitude_matrix(x0[0:4]).T @ np.array([0.0, -1.0, 0.0])
    phi_s0 = _angle(f_hill, sun_hill(float(x0[12])))
    phi_e0 = _angle(f_hill, np.array(m.earth_hill))
    turn = _turn_bound(x0[4:7], a, w_hi, (0, 2), t)
    phi_s = np.minimum(math.pi, phi_s0 + turn + m.mean_motion_rad_s * t)
    phi_e = np.minimum(math.pi, phi_e0 + turn)
    q_earth = m.albedo_W + m.sigma_eps_A_W_K4 * m.earth_T4_K4
    c_e = np.maximum(0.0, np.cos(phi_e)) if m.clamp_view_factor else np.cos(phi_e)
    q_lb = m.solar_W * np.maximum(0.0, np.cos(phi_s)) + q_earth * m.earth_view_factor * c_e
    h = m.dt_s / m.substeps
    tdot_max = max(m.solar_W + m.earth_view_factor * q_earth,
                   m.sigma_eps_A_W_K4 * (m.temperature_max_K + 1.0) ** 4) / m.heat_capacity_J_K
    t_star = m.temperature_max_K + tdot_max * 0.5 * h + RULE_DELTA_T_K
    t_lb = x0[10] + np.cumsum(h * (q_lb - m.sigma_eps_A_W_K4 * t_star**4) / m.heat_capacity_J_K)
    k = int(np.argmax(t_lb))
    if t_lb[k] > t_star:
        return (f"-j_B face {math.degrees(phi_s0):.1f} deg from the sun; even turning away at the rate "
                f"bound, T >= {t_lb[k]:.4f} K > T_max at t = {t[k]:.1f} s")
    return ""


def check_rules(x0: Array, horizon_s: float, m: OracleModel, enforce: tuple[str, ...]) -> tuple[str, str] | None:
    """(rule, explanation) of the first rule (RULES order) that proves x0 unrecoverable, or None."""
    h0 = constraint_values(x0, m)
    bad = [g for g in enforce if h0[g][0] < 0]
    if bad:
        return "violated_at_x0", "h(x0) < 0 for " + ", ".join(f"{g} ({h0[g][0]:.3g})" for g in bad)
    if "omega" in enforce and "battery" in enforce:
        why = battery_rule(x0, horizon_s, m)
        if why:
            return "battery_drain", why
    if "omega" in enforce and "temperature" in enforce:
        why = temperature_rule(x0, horizon_s, m)
        if why:
            return "temperature_heating", why
    return None


__all__ = ["RULES", "RULE_DELTA_E_J", "RULE_DELTA_T_K", "battery_rule", "check_rules", "rate_envelope",
           "rules_apply", "temperature_rule"]
