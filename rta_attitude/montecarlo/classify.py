"""Which Monte Carlo failures were physically unavoidable: rules that bound what any admissible command
sequence could do from an initial state (docs/montecarlo.md), and for the failed runs the viability
oracle's `momentum_battery` rule (`viability.rules`: the panel cannot face the sun where the wheels cannot
hold the total angular momentum)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.environment import sunlit_fraction
from rta_attitude.dynamics.spacecraft import thermal_rates
from rta_attitude.dynamics.state import ENERGY, OMEGA, PSI, TEMP, THETA_S

Array = NDArray[np.float64]

UNRECOVERABLE_RULES: tuple[str, ...] = ("battery_energy", "temperature_heating", "pointing_escape",
                                        "wheel_momentum", "momentum_battery")
"""The rules of `unavoidable`, and the viability oracle's `momentum_battery` (`viability.rules`), applied by
`classify` to the failed runs only."""
KEPT_BY_MOMENTUM_BATTERY: tuple[str, ...] = ("battery", "rate", "wheel_speed")
"""The kinds (`constraints.registry.KINDS`) of which `momentum_battery` proves that no admissible command keeps
all (the battery, with the rates and wheel speeds the bound on the panel's angle assumes)."""


CLASSIFY_STEP_S = 0.05
"""Time step of the temperature lower-bound integration, s."""
CLASSIFY_MARGIN_K = 1e-3
"""The temperature bound must exceed T_max by this before a failure counts as unavoidable, K."""


def unavoidable(x0: Array, cfg: Config, duration_s: float = math.inf) -> dict[str, NDArray[np.bool_]]:
    """Constraints that no admissible command sequence can keep from x0, by rule (n, m) each.

    Every rule bounds what the best possible trajectory could do, generously (it ignores the
    other constraints, the acceleration limits where stated, and the filter): if even that bound
    breaks a limit, the failure is physically unrecoverable. Any trajectory that keeps every
    constraint has |omega_i| <= omega_max, so a body axis turns relative to a direction at most at
    Omega = sqrt(3) omega_max (+ n for the moving sun).

    - battery_energy: the panel (power.panel_normal_body) turns towards the sun at Omega from t = 0; E_dot <=
      P_peak max(0, cos theta_SI(t)) - P_out with theta_SI(t) >= theta_SI(0) - Omega t. E falls until
      cos theta_SI = P_out / P_peak; if the bound on E drops below E_min first, so does E.
    - temperature_heating: the thermal face turns away from the sun and the Earth at Omega; the heat
      input is at least that of the bounding angles, so T >= the solution of
      T' = (Q_min(t) - sigma eps A T^4) / (m c_p) (comparison principle); a peak above T_max counts.
    - pointing_escape, for every pointing constraint without windows: h = s (theta - alpha) (s = +1
      keep_out, -1 keep_in) and its rate at t = 0; |theta_ddot| <= a_max = sqrt(3) omega_dot_max
      + 2 Omega^2 / sin(alpha) + n^2 near the cone's edge, so h >= 0 is lost if h(0) - h_dot(0)^2 /
      (2 a_max) < 0 while approaching it.
    - wheel_momentum: about body axis i, J_i omega_i - sign D psi_i changes only through the
      gyroscopic torque, so stopping the body about i moves the wheel to psi_i(0) - sign J_i omega_i(0)
      / D; where that lies beyond psi_max, and keeping omega_i inside its limit needs the rate
      stopped (|omega_i(0)| > omega_max: not in the sampled set), psi_i is lost.

    Args:
        x0: initial states (n, 19).
        cfg: configuration.
        duration_s: run length; a bound that needs longer is not used.

    Returns:
        rule name -> (n, m) bool, columns in the configuration's row order (`Config.constraint_names`).
    """
    n = len(x0)
    constraints = ConstraintSet(cfg)
    reg = constraints.registry
    angles = constraints.angles(x0)
    m = len(reg)
    L, env, pw = cfg.limits, cfg.environment, cfg.power
    Omega = math.sqrt(3.0) * L.omega_max_rad_s
    n_orb = env.mean_motion_rad_s
    out = {r: np.zeros((n, m), dtype=bool) for r in UNRECOVERABLE_RULES}
    col = {c.kind: c.row for c in reg if c.kind in ("temperature", "battery")}

    # battery: energy lost before the panel can face the sun
    rate = Omega + n_orb
    theta0 = angles["panel_sun"]
    P, P_out = pw.peak_W, pw.load_W
    if P <= P_out:
        loss = np.full(n, P_out - P) * duration_s if math.isfinite(duration_s) else np.full(n, np.inf)
    else:
        th_star = math.acos(P_out / P)
        th_b = np.minimum(theta0, np.pi / 2)
        dark = np.maximum(theta0 - np.pi / 2, 0.0)
        lit = np.where(th_b > th_star, P_out * (th_b - th_star) - P * (np.sin(th_b) - math.sin(th_star)), 0.0)
        loss = (P_out * dark + lit) / rate
        t_star = np.maximum(theta0 - th_star, 0.0) / rate
        loss = np.where(t_star <= duration_s, loss, 0.0)
    out["battery_energy"][:, col["battery"]] = x0[:, ENERGY] - loss < L.energy_min_J

    # temperature: lower bound of T while the face turns away at the largest rate (the heat input falls as
    # the incidence angles grow, so the plant's own thermal law at the bounding angles bounds T from below)
    th_s0, th_e0 = angles["face_sun"], angles["face_earth"]
    plant = constraints.plant[0]
    T = x0[:, TEMP].copy()
    T_peak = T.copy()
    T_dot = np.empty_like(T)
    horizon = min(math.pi / min(rate, Omega), duration_s)
    for k in range(math.ceil(horizon / CLASSIFY_STEP_S)):
        t = k * CLASSIFY_STEP_S
        thermal_rates(np.cos(np.minimum(th_s0 + rate * t, np.pi)), np.cos(np.minimum(th_e0 + Omega * t, np.pi)),
                      T, sunlit_fraction(x0[:, THETA_S] - n_orb * t, env.sun_beta_rad, env.shadow_sx), plant, T_dot)
        T = T + CLASSIFY_STEP_S * T_dot
        np.maximum(T_peak, T, out=T_peak)
    out["temperature_heating"][:, col["temperature"]] = T_peak > L.temperature_max_K + CLASSIFY_MARGIN_K

    # pointing constraints: stopping distance of the approach to the cone's edge
    table = constraints.evaluate(x0)
    for c in reg.pointing:
        if c.windowed or not c.enabled:
            continue
        i = c.row
        h = table["h"][:, i]
        h_dot = table["psi1"][:, i] - cfg.gains(c.name).k1 * table["psi0"][:, i]  # Psi_1 - k1 Psi_0
        a_max = math.sqrt(3.0) * L.omega_dot_max_rad_s2 + 2.0 * rate**2 / math.sin(c.limit) + n_orb**2
        reach = h - np.where(h_dot < 0, h_dot**2 / (2.0 * a_max), 0.0)
        out["pointing_escape"][:, i] = reach < 0

    # wheels: momentum exchanged in stopping the body about each axis
    sc = cfg.spacecraft
    D = sc.wheel_inertia_kgm2
    sign = sc.torque_sign
    w0 = x0[:, OMEGA]
    Jw = sc.J * w0 if sc.principal else w0 @ sc.inertia_matrix.T
    psi_stop = x0[:, PSI] - sign * (Jw @ sc.wheel_axes_inverse.T) / D  # A^-1 (J w): per wheel
    must_stop = np.abs(w0) > L.omega_max_rad_s
    wheels = [c.row for c in reg if c.kind == "wheel_speed"]
    for a, i in enumerate(wheels):
        out["wheel_momentum"][:, i] = must_stop[:, a] & (np.abs(psi_stop[:, a]) > L.psi_max_rad_s)
    return out


def classify(x0: Array, violated: NDArray[np.bool_], cfg: Config,
             duration_s: float = math.inf) -> tuple[NDArray[np.bool_], list[str]]:
    """Which failures no admissible command could have avoided (see docs/montecarlo.md).

    Args:
        x0: initial states (n, 19).
        violated: (n, m) constraints violated in each run (the configuration's row order).
        cfg: configuration.

    Returns:
        (unrecoverable (n,) bool, the rules that proved it per run ('' if none, ';'-joined)).
    """
    from rta_attitude.viability.params import as_oracle_state, default_enforce, from_config
    from rta_attitude.viability.rules import battery_rule, rules_apply

    proofs = unavoidable(x0, cfg, duration_s)  # name -> (n, m) bool
    model = from_config(cfg)
    enforced = default_enforce(cfg)
    momentum = (rules_apply(model) and all(g in enforced for g in ("omega", "psi", "battery"))
                and math.isfinite(duration_s))
    kept = np.array([c.kind in KEPT_BY_MOMENTUM_BATTERY for c in ConstraintSet(cfg).registry])
    rules: list[str] = []
    out = np.zeros(len(x0), dtype=bool)
    for k in range(len(x0)):
        hit = [name for name, mask in proofs.items() if np.any(mask[k] & violated[k])]
        if (momentum and np.any(violated[k] & kept)
                and battery_rule(as_oracle_state(x0[k]), duration_s, model, momentum=True)):
            hit.append("momentum_battery")
        rules.append(";".join(hit))
        out[k] = bool(hit)
    return out, rules



__all__ = ["UNRECOVERABLE_RULES", "classify", "unavoidable"]
