"""Rules that PROVE a state unrecoverable over a horizon (no admissible command sequence keeps the
enforced constraints at every substep). IPOPT's failure never proves anything; only these do.

- `violated_at_x0`: an enforced h(x0) < 0 (the sample at t = 0 is already unsafe).
- `battery_drain` (`battery_rule`): E must fall below E_min at a substep time <= horizon.
- `temperature_heating` (`temperature_rule`): T must rise above T_max at a substep time <= horizon.
- `momentum_battery` (`battery_rule` with `momentum=True`, gyrostat only): the same as
  `battery_drain`, with the panel's angle to the sun also bounded below by where the wheels can hold
  the spacecraft's total angular momentum (`momentum_band`): E must fall below E_min.

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

RULES: tuple[str, ...] = ("violated_at_x0", "battery_drain", "temperature_heating", "momentum_battery")
RULE_DELTA_E_J = 0.1
"""Energy margin of the battery rule, J (RK4 vs exact ODE: measured < 1.4e-3 J over 2,000 s)."""
RULE_DELTA_T_K = 1e-3
"""Temperature margin of the temperature rule, K (RK4 vs exact ODE: measured < 1e-6 K)."""


def rules_apply(m: OracleModel) -> bool:
    """The physical rules' proofs hold for this model (module docstring)."""
    return m.frame_rate_rad_s == 0.0 and not m.gravity_gradient and (m.torque_sign == 1.0 or not m.gyrostat)


def body_momentum(x0: Array, m: OracleModel) -> Array:
    """H = J w - D psi (3,), body frame, N m s (torque sign +1, as `rules_apply` requires of the gyrostat)."""
    return m.J * x0[4:7] - m.wheel_inertia_kgm2 * x0[7:10]


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
    h_norm = float(np.linalg.norm(body_momentum(x0, m)))

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


def momentum_bands(h_body: Array, m: OracleModel) -> list[tuple[float, float]]:
    """The angles beta = angle(k_B, H) at which the wheels can hold the body momentum H (body frame,
    N m s; only |H| matters) with the rates inside their limit, as intervals in [0, pi].

    H = J w - D psi, so |w_i| <= w_max and |psi_i| <= psi_max give |H_i| <= c_i = J_i w_max + D psi_max:
    |cos beta| = |H_3|/|H| <= c_3/|H| and sin beta = |(H_1, H_2)|/|H| <= sqrt(c_1^2 + c_2^2)/|H|, i.e.
    beta in [a, pi - a] intersected with ([0, b] union [pi - b, pi]), a = acos(min(1, c_3/|H|)),
    b = asin(min(1, sqrt(c_1^2 + c_2^2)/|H|)). Each value is reached (turn about k_B to share
    (H_1, H_2) between the wheels)."""
    h_norm = float(np.linalg.norm(h_body))
    if h_norm == 0.0:
        return [(0.0, math.pi)]
    c = m.J * m.omega_max_rad_s + m.wheel_inertia_kgm2 * m.psi_max_rad_s
    a = math.acos(min(1.0, float(c[2]) / h_norm))
    b = math.asin(min(1.0, math.hypot(float(c[0]), float(c[1])) / h_norm))
    if b >= math.pi / 2:
        return [(a, math.pi - a)]
    if a <= b:
        return [(a, b), (math.pi - b, math.pi - a)]
    return []  # no attitude holds this momentum (never at a state that meets the constraints)


def momentum_band(x0: Array, m: OracleModel, delta: float) -> tuple[Array, list[tuple[float, float]]]:
    """(H_hat, F): the unit total angular momentum in Hill, and the angles beta(t) = angle(k_B, H_hat)
    the panel normal can have at any time on an admissible trajectory from x0, as intervals.

    Gyrostat with the rules' assumptions (`rules_apply`): H = J w - D psi (body) has H_dot = -w x H
    for every input, so H_I = A(q)^T H is fixed in Hill and |H| is constant. At x0 and at every
    substep time beta is in `momentum_bands`; between substep times it moves by at most delta
    (|k_B_dot| bounds |beta_dot|), so the bands widened by delta hold at every time. Where the
    widened bands are disjoint (|H| past sqrt(c_1^2 + c_2^2): the wheels hold H only near a body
    diagonal), beta(t), continuous, stays in the band it starts in, and only that one is returned.
    """
    hb = body_momentum(x0, m)
    h_norm = float(np.linalg.norm(hb))
    h_hat = attitude_matrix(x0[0:4]).T @ hb / max(h_norm, 1e-300)
    bands = [(max(0.0, lo - delta), min(math.pi, hi + delta)) for lo, hi in momentum_bands(hb, m)]
    if len(bands) == 2 and bands[0][1] < bands[1][0]:
        beta0 = math.acos(max(-1.0, min(1.0, float(hb[2]) / h_norm)))
        bands = [band for band in bands if band[0] <= beta0 <= band[1]]
    return h_hat, bands


def _distance_to_bands(alpha: Array, bands: list[tuple[float, float]]) -> Array:
    """Distance of each angle in `alpha` to the union of `bands` (pi where there are none)."""
    if not bands:
        return np.full_like(alpha, math.pi)
    return np.min([np.maximum(0.0, np.maximum(lo - alpha, alpha - hi)) for lo, hi in bands], axis=0)


def battery_rule(x0: Array, horizon_s: float, m: OracleModel, momentum: bool = False) -> str:
    """A non-empty explanation if E < E_min at some substep time <= horizon for every admissible input.

    Proof. phi(t), the angle between the panel normal k_B and r_S, is a distance on the sphere, so
    |phi_dot| <= |k_dot| + |r_S_dot| = sqrt(w1^2 + w2^2) + n. With `rate_envelope`,
    phi(t) >= phi_lb(t) = max(0, phi(0) - Phi(t) - n t) (`_turn_bound`), non-increasing in t.
    With `momentum` (gyrostat; the wheel-speed constraint enforced): beta(t) = angle(k_B, H_hat) lies in
    the band F_delta of `momentum_band` (delta = sqrt(2) w_hi h) and alpha(t) = angle(H_hat, r_S(t)), so
    by the triangle inequality on the sphere phi(t) >= |beta(t) - alpha(t)| >= dist(alpha(t), F_delta);
    alpha moves by at most n h within a substep interval. On the interval (t_{k-1}, t_k],
    phi >= g_k = max(phi_lb(t_k), dist(alpha(t_k), F_delta) - n h) and max(0, cos .) falls on [0, pi], so
    E_dot <= P_peak max(0, cos g_k) - P_out there, and the sum of h times that over the intervals up to
    t_k bounds E(t_k) from above. If that bound is < E_min - delta_E at some t_k <= horizon,
    E(t_k) < E_min for every admissible input.
    """
    t = _grid(horizon_s, m)
    if len(t) == 0 or not rules_apply(m) or (momentum and not m.gyrostat):
        return ""
    w_hi, a = rate_envelope(x0, m)
    k_hill = attitude_matrix(x0[0:4]).T @ np.array([0.0, 0.0, 1.0])
    phi0 = _angle(k_hill, sun_hill(float(x0[12])))
    phi_lb = np.maximum(0.0, phi0 - _turn_bound(x0[4:7], a, w_hi, (0, 1), t) - m.mean_motion_rad_s * t)
    h = m.dt_s / m.substeps
    if momentum:
        h_hat, bands = momentum_band(x0, m, math.sqrt(2.0) * w_hi * h)
        theta = float(x0[12]) - m.mean_motion_rad_s * t  # theta_S_dot = -n
        alpha = np.arccos(np.clip(h_hat[0] * np.cos(theta) + h_hat[1] * np.sin(theta), -1.0, 1.0))
        phi_lb = np.maximum(phi_lb, _distance_to_bands(alpha, bands) - m.mean_motion_rad_s * h)
    e_ub = x0[11] + np.cumsum(h * (m.panel_peak_W * np.maximum(0.0, np.cos(np.minimum(phi_lb, math.pi)))
                                   - m.load_W))
    k = int(np.argmin(e_ub))
    if e_ub[k] < m.energy_min_J - RULE_DELTA_E_J:
        if momentum:
            h_over_d = float(np.linalg.norm(body_momentum(x0, m))) / m.wheel_inertia_kgm2
            held = " or ".join(f"{math.degrees(lo):.1f}-{math.degrees(hi):.1f}" for lo, hi in bands) or "no"
            return (f"the wheels hold |H|/D = {h_over_d:.0f} rad/s only with the panel {held} deg from H; "
                    f"E <= {e_ub[k]:.1f} J < E_min at t = {t[k]:.1f} s")
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
    if "omega" in enforce and "battery" in enforce and "psi" in enforce:
        why = battery_rule(x0, horizon_s, m, momentum=True)
        if why:
            return "momentum_battery", why
    return None


__all__ = ["RULES", "RULE_DELTA_E_J", "RULE_DELTA_T_K", "battery_rule", "body_momentum", "check_rules",
           "momentum_band", "momentum_bands", "rate_envelope", "rules_apply", "temperature_rule"]
