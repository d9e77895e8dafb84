"""Rules that PROVE a state unrecoverable over a horizon (no admissible command sequence keeps the
enforced constraints at every substep). IPOPT's failure never proves anything; only these do.

- `violated_at_x0`: an enforced h(x0) < 0 at the start state's time (the first sample is already unsafe);
  every group of the configuration, any pointing constraint included (a windowed one only inside a window).
- `battery_drain` (`battery_rule`): E must fall below E_min at a substep time <= horizon.
- `temperature_heating` (`temperature_rule`): T must rise above T_max at a substep time <= horizon.
- `momentum_battery` (`battery_rule` with `momentum=True`, gyrostat only): the same as
  `battery_drain`, with the panel's angle to the sun also bounded below by where the wheels can hold
  the spacecraft's total angular momentum (`momentum_band`): E must fall below E_min.

The physical rules are about the panel (`power.panel_normal_body`, the paper's +k_B) and the thermal node's
face (`thermal.face_normal_body`, the paper's -j_B), wherever the configuration puts them, and the sun with its
beta angle (its direction turns at n cos beta <= n); they need the rate, battery (temperature) and, for the
momentum rule, wheel-speed groups enforced, found by the registry's kind. No rule reasons about a pointing
constraint's cone (no escape rule for a keep_out cone): the cones enter through `violated_at_x0` only.
The momentum bands are exact for a panel along a body axis and a sound over-approximation otherwise.

The rules bound how fast the panel (or the hot face) can turn away from (towards)
the sun, which needs the rate constraint to be enforced (`rate_envelope`), and they are proved for
the exact ODE with any input in U: the constraints are only checked at the substep times, so the
rates between them are bounded from the dynamics. They apply to the model the proofs are written
for: Hill frame inertial, no gravity-gradient torque, a wheel on each principal body axis (no products of
inertia, no skewed wheel: the bounds
are per axis) and, for the gyrostat, torque sign +1 (H = J w - D psi conserved in magnitude); otherwise they do
not fire (`rules_apply`). Small
margins (RULE_DELTA_E, RULE_DELTA_T) cover the gap between RK4 and the exact ODE.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.dynamics.environment import EARTH_HILL, sun_direction
from rta_attitude.viability.model import along, attitude_matrix, constraint_values, sun_hill
from rta_attitude.viability.params import BATTERY, RATE, TEMPERATURE, WHEEL_SPEED, OracleModel

Array = NDArray[np.float64]

RULES: tuple[str, ...] = ("violated_at_x0", "battery_drain", "temperature_heating", "momentum_battery")
RULE_DELTA_E_J = 0.1
"""Energy margin of the battery rule, J (RK4 vs exact ODE: measured < 1.4e-3 J over 2,000 s)."""
RULE_DELTA_T_K = 1e-3
"""Temperature margin of the temperature rule, K (RK4 vs exact ODE: measured < 1e-6 K)."""


def rules_apply(m: OracleModel) -> bool:
    """The physical rules' proofs hold for this model (module docstring)."""
    return (m.frame_rate_rad_s == 0.0 and not m.gravity_gradient and (m.torque_sign == 1.0 or not m.gyrostat)
            and m.principal and m.wheels_on_body_axes)


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


def cross_bound(W: Array, e: Array) -> Array:
    """Upper bound of |w x e| for a unit body vector e (3,) over |w_i| <= W_i (W (3,) or (3, n)): each component
    (w x e)_i = w_j e_k - w_k e_j is at most W_j |e_k| + W_k |e_j| (i, j, k cyclic). For e along a body axis it is
    the norm of the bounds of the two rates perpendicular to it (exact); otherwise an upper bound."""
    a = np.abs(np.asarray(e, dtype=float))
    c0 = W[1] * a[2] + W[2] * a[1]
    c1 = W[2] * a[0] + W[0] * a[2]
    c2 = W[0] * a[1] + W[1] * a[0]
    return np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)


def _turn_bound(w0: Array, a: Array, w_hi: float, e: Array, t: Array) -> Array:
    """Upper bound of the angle a unit body vector e (3,) can have turned by times t: |e_dot| = |w x e| <=
    `cross_bound` of |w_i(t)| <= min(w_hi, |w_i(0)| + a_i t); the right Riemann sum bounds the integral of this
    non-decreasing integrand from above."""
    W = np.stack([np.minimum(w_hi, abs(w0[i]) + a[i] * t) for i in range(3)])
    return np.cumsum(np.diff(np.concatenate([[0.0], t])) * cross_bound(W, e))


def axis_label(e: tuple[float, float, float] | Array) -> str:
    """A body vector as text: '+k_B', '-j_B' for a body axis, else its components."""
    nonzero = [i for i in range(3) if e[i] != 0.0]
    if len(nonzero) == 1 and abs(e[nonzero[0]]) == 1.0:
        return f"{'+' if e[nonzero[0]] > 0 else '-'}{'ijk'[nonzero[0]]}_B"
    return "[" + ", ".join(f"{float(v):.3g}" for v in e) + "]_B"


def _angle(u: Array, v: Array) -> float:
    return math.acos(max(-1.0, min(1.0, float(u @ v) / float(np.linalg.norm(u) * np.linalg.norm(v)))))


def _grid(horizon_s: float, m: OracleModel) -> Array:
    h = m.dt_s / m.substeps
    return h * np.arange(1, round(horizon_s / h) + 1, dtype=np.float64)


def momentum_bands(h_body: Array, m: OracleModel) -> list[tuple[float, float]]:
    """The angles beta = angle(p, H) at which the wheels can hold the body momentum H (body frame,
    N m s; only |H| matters) with the rates inside their limit, as intervals in [0, pi]; p the panel's
    normal (`power.panel_normal_body`, the paper's k_B).

    H = J w - D psi, so |w_i| <= w_max and |psi_i| <= psi_max give |H_i| <= c_i = J_i w_max + D psi_max:
    |cos beta| = |H . p|/|H| <= sum_i c_i |p_i| / |H| and sin beta = |H x p|/|H| <= `cross_bound`(c, p)/|H|
    (for p = k_B: c_3/|H| and sqrt(c_1^2 + c_2^2)/|H|), i.e. beta in [a, pi - a] intersected with
    ([0, b] union [pi - b, pi]), a = acos(min(1, .)) and b = asin(min(1, .)) of the two. For a panel along a body
    axis each value is reached (turn about p to share H's other components between the wheels); for any other
    panel the bands contain every reachable value (sound, not tight)."""
    h_norm = float(np.linalg.norm(h_body))
    if h_norm == 0.0:
        return [(0.0, math.pi)]
    psi_top = m.psi_max_rad_s + (m.omega_max_rad_s if m.wheel_speed_relative else 0.0)  # |psi| <= |psi + w| + |w|
    c = m.J * m.omega_max_rad_s + m.wheel_inertia_kgm2 * psi_top
    p = np.abs(np.array(m.panel_normal_body))
    c_along = float(along(p, c))
    c_perp = math.hypot(float(c[1] * p[2] + c[2] * p[1]), float(c[2] * p[0] + c[0] * p[2]),
                        float(c[0] * p[1] + c[1] * p[0]))  # cross_bound(c, p), as one rounding
    a = math.acos(min(1.0, c_along / h_norm))
    b = math.asin(min(1.0, c_perp / h_norm))
    if b >= math.pi / 2:
        return [(a, math.pi - a)]
    if a <= b:
        return [(a, b), (math.pi - b, math.pi - a)]
    return []  # no attitude holds this momentum (never at a state that meets the constraints)


def momentum_band(x0: Array, m: OracleModel, delta: float) -> tuple[Array, list[tuple[float, float]]]:
    """(H_hat, F): the unit total angular momentum in Hill, and the angles beta(t) = angle(p, H_hat)
    the panel normal p can have at any time on an admissible trajectory from x0, as intervals.

    Gyrostat with the rules' assumptions (`rules_apply`): H = J w - D psi (body) has H_dot = -w x H
    for every input, so H_I = A(q)^T H is fixed in Hill and |H| is constant. At x0 and at every
    substep time beta is in `momentum_bands`; between substep times it moves by at most delta
    (|p_dot| bounds |beta_dot|), so the bands widened by delta hold at every time. Where the
    widened bands are disjoint (for p = k_B, |H| past sqrt(c_1^2 + c_2^2): the wheels hold H only near a body
    diagonal), beta(t), continuous, stays in the band it starts in, and only that one is returned.
    """
    hb = body_momentum(x0, m)
    h_norm = float(np.linalg.norm(hb))
    h_hat = attitude_matrix(x0[0:4]).T @ hb / max(h_norm, 1e-300)
    bands = [(max(0.0, lo - delta), min(math.pi, hi + delta)) for lo, hi in momentum_bands(hb, m)]
    if len(bands) == 2 and bands[0][1] < bands[1][0]:
        beta0 = math.acos(max(-1.0, min(1.0, float(along(m.panel_normal_body, hb)) / h_norm)))
        bands = [band for band in bands if band[0] <= beta0 <= band[1]]
    return h_hat, bands


def _distance_to_bands(alpha: Array, bands: list[tuple[float, float]]) -> Array:
    """Distance of each angle in `alpha` to the union of `bands` (pi where there are none)."""
    if not bands:
        return np.full_like(alpha, math.pi)
    return np.min([np.maximum(0.0, np.maximum(lo - alpha, alpha - hi)) for lo, hi in bands], axis=0)


def battery_rule(x0: Array, horizon_s: float, m: OracleModel, momentum: bool = False) -> str:
    """A non-empty explanation if E < E_min at some substep time <= horizon for every admissible input.

    Proof. phi(t), the angle between the panel normal p and r_S, is a distance on the sphere, so
    |phi_dot| <= |p_dot| + |r_S_dot| <= |w x p| + n (sqrt(w1^2 + w2^2) + n for the paper's p = k_B). With
    `rate_envelope`, phi(t) >= phi_lb(t) = max(0, phi(0) - Phi(t) - n t) (`_turn_bound`), non-increasing in t.
    With `momentum` (gyrostat; the wheel-speed constraint enforced): beta(t) = angle(p, H_hat) lies in
    the band F_delta of `momentum_band` (delta = `cross_bound`(w_hi, p) h, sqrt(2) w_hi h for p = k_B) and
    alpha(t) = angle(H_hat, r_S(t)), so
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
    panel = np.array(m.panel_normal_body)
    k_hill = attitude_matrix(x0[0:4]).T @ panel
    phi0 = _angle(k_hill, sun_hill(float(x0[12]), m))
    phi_lb = np.maximum(0.0, phi0 - _turn_bound(x0[4:7], a, w_hi, panel, t) - m.mean_motion_rad_s * t)
    h = m.dt_s / m.substeps
    if momentum:
        h_hat, bands = momentum_band(x0, m, float(cross_bound(np.ones(3), panel)) * w_hi * h)
        theta = float(x0[12]) - m.mean_motion_rad_s * t  # theta_S_dot = -n
        alpha = np.arccos(np.clip(along(h_hat, sun_direction(theta, m.sun_beta_rad)), -1.0, 1.0))
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

    Proof. f the face's normal (`thermal.face_normal_body`, the paper's -j_B), phi_s and phi_e its angles to r_S
    and r_E. As in `battery_rule`, phi_s(t) <= min(pi, phi_s(0) + Phi(t) + n t) and
    phi_e(t) <= min(pi, phi_e(0) + Phi(t)), with |f_dot| <= `cross_bound` (sqrt(w1^2 + w3^2) for -j_B). The heat
    input Q(t) >= Q_lb(t) (the same with the angles at their
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
    face = np.array(m.face_normal_body)
    f_hill = attitude_matrix(x0[0:4]).T @ face
    phi_s0 = _angle(f_hill, sun_hill(float(x0[12]), m))
    phi_e0 = _angle(f_hill, np.array(EARTH_HILL))
    turn = _turn_bound(x0[4:7], a, w_hi, face, t)
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
        return (f"{axis_label(m.face_normal_body)} face {math.degrees(phi_s0):.1f} deg from the sun; even turning "
                f"away at the rate bound, T >= {t_lb[k]:.4f} K > T_max at t = {t[k]:.1f} s")
    return ""


def check_rules(x0: Array, horizon_s: float, m: OracleModel, enforce: tuple[str, ...],
                t0_s: float = 0.0) -> tuple[str, str] | None:
    """(rule, explanation) of the first rule (RULES order) that proves x0 (at time t0_s, s) unrecoverable, or
    None. The physical rules run where the groups they need are enforced (by kind: module docstring)."""
    h0 = constraint_values(x0, m, t0_s)
    bad = [g for g in enforce if h0[g][0] < 0]
    if bad:
        return "violated_at_x0", "h(x0) < 0 for " + ", ".join(f"{g} ({h0[g][0]:.3g})" for g in bad)
    kinds = m.kinds(enforce)
    if RATE in kinds and BATTERY in kinds:
        why = battery_rule(x0, horizon_s, m)
        if why:
            return "battery_drain", why
    if RATE in kinds and TEMPERATURE in kinds:
        why = temperature_rule(x0, horizon_s, m)
        if why:
            return "temperature_heating", why
    if RATE in kinds and BATTERY in kinds and WHEEL_SPEED in kinds:
        why = battery_rule(x0, horizon_s, m, momentum=True)
        if why:
            return "momentum_battery", why
    return None


__all__ = ["RULES", "RULE_DELTA_E_J", "RULE_DELTA_T_K", "axis_label", "battery_rule", "body_momentum", "check_rules",
           "cross_bound", "momentum_band", "momentum_bands", "rate_envelope", "rules_apply", "temperature_rule"]
