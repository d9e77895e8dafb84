"""Sampled-data margins of the pointing constraints, derived from the vehicle where the configuration sets none.

The filter evaluates its HOCBF rows at the sample and holds u for dt; during the hold the angle's second
derivative drifts away from the value the row assumed (the gyroscopic torque and the kinematics change with
the state), by at most L tau after tau, where L bounds the angle's third derivative at fixed u. Integrated
twice over the hold, the angle departs from what the barrier planned by at most

    L dt^3 / 6,

so the robust preset keeps h >= that margin (`Psi_0 = h - margin`) and the overshoot of a hold stays on the
safe side of h = 0 (docs/constraints.md derives it). L, for a body axis at angle theta = alpha (the cone's edge)
from a target that turns at n_t (n, plus the Hill frame's rate), from the vehicle's limits:

    L = |B| + 3 W |A| (1 + |cot alpha|) + W^3 (1 + 3 cot^2 alpha),   W = sqrt(3) omega_max + n_t

A_i >= |omega_dot_i| and B_i >= |omega_ddot_i| (held u) with every rate at omega_max and every wheel at psi_max
(`angular_rate.zoh_rows` bounds the same terms per state): Euler's coupling, the wheels' gyroscopic torque (the
gyrostat model only), the actuator G_i U_i. The terms of L are those of d^3/dt^3 arccos(e . r) for a unit
vector turning at W with the acceleration |A| and jerk |B|.

On the paper's 6U this gives 2.8e-2 rad (gyrostat) and 2.8e-3 rad (the paper's model) for its 40 deg cone:
4.4 times the worst overshoot measured without a margin (6.3e-3 and 6.3e-4 rad), and above the margins the
default configuration keeps (1.9e-2, 2e-3, 3x those measurements), which it sets explicitly.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config, PointingConstraint
from rta_attitude.constraints.angular_rate import general_rate_bounds
from rta_attitude.constraints.base import general_inertia_error_bound, inertia_error_bound, inertia_shape


def axis_rate_bounds(cfg: Config, model: str, delta: float = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(A, B) (3,): bounds on |omega_dot_i| and |omega_ddot_i| (held u) with every rate at omega_max and every
    wheel at psi_max, for the plant model (PLANT_MODELS: the gyrostat has the wheels' gyroscopic torque), rad/s^2
    and rad/s^3; for every inertia within +-delta of the configured one (each bound grows with |J_j - J_k|, D /
    J_i and G_i, so the worst case takes |J_j - J_k| + delta (J_j + J_k), (1 - delta) J_i and G_i / (1 - delta))."""
    sc, L = cfg.spacecraft, cfg.limits
    if not sc.diagonal:
        return _general_axis_rate_bounds(cfg, model, delta)
    J = sc.J * (1.0 - delta)
    D = sc.wheel_inertia_kgm2
    G = np.abs(sc.control_gain) / (1.0 - delta)
    U = cfg.u_max_rad_s2
    W = np.full(3, L.omega_max_rad_s)
    P = np.full(3, L.psi_max_rad_s if model == "gyrostat" else 0.0)
    J0 = sc.J
    d = np.abs([J0[1] - J0[2], J0[2] - J0[0], J0[0] - J0[1]]) + delta * np.array([J0[1] + J0[2], J0[2] + J0[0],
                                                                                   J0[0] + J0[1]])
    A = np.empty(3)
    B = np.empty(3)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        A[i] = (d[i] * W[j] * W[k] + D * (W[j] * P[k] + W[k] * P[j])) / J[i] + G[i] * U[i]
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        B[i] = (d[i] * (A[j] * W[k] + W[j] * A[k]) + D * (A[j] * P[k] + W[j] * U[k] + A[k] * P[j] + W[k] * U[j])) / J[i]
    return A, B


def _general_axis_rate_bounds(cfg: Config, model: str, delta: float = 0.0
                              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:  # fmt: skip
    """`axis_rate_bounds` in general (products of inertia, wheels off the body axes): the torques' bounds (Euler's,
    `config.inertia.euler_bound` and its rate; the wheels' D |w x A psi|) through |J^-1|, as `angular_rate.zoh_rows`
    bounds them per state. For every inertia J + dJ with -delta J <= dJ <= delta J (k = delta / (1 - delta),
    s_i = sqrt((J^-1)_ii)): |dJ| <= delta lambda_max, |J'^-1 - J^-1|_ij <= k s_i s_j, so |G' - G|_ij <= k |s D| s_i
    sum_l s_l |A_lj|, and the QP's cap on (G u)_i leaves (G' u)_i up to that much more."""
    sc, L = cfg.spacecraft, cfg.limits
    gyrostat = model == "gyrostat"
    w = L.omega_max_rad_s
    reach = np.abs(sc.wheel_axes)
    P = reach @ np.full(3, L.psi_max_rad_s if gyrostat else 0.0)
    U = cfg.u_max_rad_s2
    Ji, G, cap, dJ = sc.inertia_inverse, sc.control_matrix, cfg.accel_limit_rad_s2, 0.0
    if delta > 0.0:
        k = delta / (1.0 - delta)
        s = np.sqrt(np.diag(Ji))
        Ji = np.abs(Ji) + k * np.outer(s, s)
        dG = k * abs(sc.torque_sign * sc.wheel_inertia_kgm2) * np.outer(s, s @ reach)
        G = np.abs(G) + dG
        cap = cap + dG @ U
        dJ = delta * float(np.max(sc.principal_moments))
    out = np.empty((3, 3))
    general_rate_bounds(sc.inertia_matrix, Ji, G, sc.wheel_inertia_kgm2 if gyrostat else 0.0, w, w, w,
                        P[0], P[1], P[2], U, reach @ U, cap, 0.0, 0.0, dJ, out)
    return out[0].copy(), out[1].copy()


def rate_bounds(cfg: Config, model: str) -> tuple[float, float]:
    """(|A|, |B|): the norms of `axis_rate_bounds`, for every inertia the robust preset allows
    (`spacecraft.inertia_uncertainty`), rad/s^2 and rad/s^3."""
    A, B = axis_rate_bounds(cfg, model, robust_inertia_uncertainty(cfg))
    return float(np.linalg.norm(A)), float(np.linalg.norm(B))


def robust_inertia_uncertainty(cfg: Config) -> float:
    """`spacecraft.inertia_uncertainty` where the filter keeps it (the robust preset), else 0."""
    return cfg.spacecraft.inertia_uncertainty if cfg.filter.preset == "robust" else 0.0


def inertia_accel_bound(cfg: Config, model: str) -> NDArray[np.float64]:
    """`constraints.base.inertia_error` at its worst over the states the rows allow (every rate at omega_max and
    wheel at psi_max: |omega_dot_a| <= A_a of `axis_rate_bounds` of the model, |w_b w_c| <= omega_max^2), per
    axis, rad/s^2: what the gatekeeper's rollouts allow for over a sample."""
    delta = robust_inertia_uncertainty(cfg)
    J, env = cfg.spacecraft.J, cfg.environment
    A, _ = axis_rate_bounds(cfg, model)
    w2 = cfg.limits.omega_max_rad_s**2
    k = delta / (1.0 - delta)
    if not cfg.spacecraft.principal:  # |omega| <= sqrt(3) omega_max, |R v| <= sqrt(lambda_max) |v|
        shape = inertia_shape(cfg)
        root = math.sqrt(float(np.max(cfg.spacecraft.principal_moments)))
        accel = root * float(np.linalg.norm(A))
        return np.array([general_inertia_error_bound(k, float(shape["inertia_scale"][a]), accel, 3.0 * w2 * root,
                                                     shape["inertia_spread"], shape["inertia_gg"]) for a in range(3)])
    return np.array([inertia_error_bound(k, float(A[a]), w2, env.mean_motion_rad_s,
                                         env.gravity_gradient, J, a) for a in range(3)])


def derived_margin(cfg: Config, cone: PointingConstraint, model: str) -> float:
    """L dt^3 / 6 (module docstring) for the cone's half-angle and the plant model, rad."""
    env = cfg.environment
    n_t = env.mean_motion_rad_s * (2.0 if env.rotating_hill else 1.0)
    W = math.sqrt(3.0) * cfg.limits.omega_max_rad_s + n_t
    A, B = rate_bounds(cfg, model)
    cot = abs(math.cos(cone.half_angle_rad) / math.sin(cone.half_angle_rad))
    L = B + 3.0 * W * A * (1.0 + cot) + W**3 * (1.0 + 3.0 * cot * cot)
    return L * cfg.filter.sample_time_s**3 / 6.0


def sampled_data_margin(cfg: Config, name: str) -> float:
    """The margin constraint `name` keeps in the robust preset for the filter's model (0 in `paper`): as
    configured, or for a pointing constraint that sets none, `derived_margin`."""
    if cfg.filter.preset != "robust":
        return 0.0
    configured = cfg.gains(name).sampled_data_margin(cfg.filter.model)
    if configured is not None:
        return configured
    return derived_margin(cfg, cfg.pointing_constraint(name), cfg.filter.model)


__all__ = ["axis_rate_bounds", "derived_margin", "inertia_accel_bound", "rate_bounds", "robust_inertia_uncertainty",
           "sampled_data_margin"]
