"""Initial states of the Monte Carlo (SPEC sec. 5.2): Latin hypercube inside the safe set.

Latin hypercube (scipy.stats.qmc) over 12 dimensions: q uniform on the unit quaternions through
Shoemake's map (3), omega (3), psi (3), T, E, theta_S, in the ranges below; a state where any enabled
constraint has h, Psi_0 or Psi_1 < 0 (under either filter preset) is re-drawn (a fresh hypercube for
the rejected ones, from the same seeded stream) until none is, so one seed gives the same initial
states for `robust` and `paper`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config import CELSIUS_OFFSET_K
from rta_attitude.config.schema import PRESETS, Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.battery import eclipse_floors
from rta_attitude.dynamics.spacecraft import plant_record
from rta_attitude.dynamics.state import ENERGY, OMEGA, PSI, STATE_SIZE, TEMP, THETA_S, Q
from rta_attitude.errors import ConfigError, RtaError
from rta_attitude.kernel_cache import drop_stale_caches

Array = NDArray[np.float64]

# ----------------------------------------------------------------------------- SPEC sec. 5.2 ranges
# [resolved] in SPEC.md; proposed as a `montecarlo:` section of config/rta_attitude.yaml (see docs).
OMEGA_FRACTION = 0.95
"""omega_i uniform in +-OMEGA_FRACTION omega_max (5 % buffer)."""
PSI_FRACTION = 0.95
"""psi_i uniform in +-PSI_FRACTION psi_max (5 % buffer)."""
TEMPERATURE_RANGE_DEGC = (-10.0, 9.5)
"""T uniform in this range, degC (9.5 = T_max minus 5 %)."""
ENERGY_MIN_FACTOR = 1.05
"""E from ENERGY_MIN_FACTOR E_min ..."""
ENERGY_MAX_J = 10_000.0
"""... to this, J; with an eclipse, both above the eclipse's floor at the state's theta_S
(`constraints.battery.eclipse_floor`: what the load needs through the shadow ahead)."""
THETA_S_RANGE_RAD = (0.0, 2.0 * math.pi)
"""theta_S uniform in [0, 2 pi)."""
SAMPLE_DIMENSIONS = 12
"""Hypercube dimensions: 3 (Shoemake) + 3 omega + 3 psi + T + E + theta_S."""
MAX_REDRAW_ROUNDS = 10_000
"""Re-draw rounds before giving up (each re-draws every still-rejected state)."""

# ----------------------------------------------------------------------------- sampling
def _to_states(u: Array, cfg: Config) -> Array:
    """Unit-cube samples (n, 12) -> states (n, 19)."""
    L = cfg.limits
    n = u.shape[0]
    x = np.zeros((n, STATE_SIZE))
    u1, u2, u3 = u[:, 0], u[:, 1], u[:, 2]
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    # Shoemake (1992): uniform on S^3; order (vector, scalar) is immaterial for uniformity
    x[:, Q] = np.stack([a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                        b * np.sin(2 * np.pi * u3), b * np.cos(2 * np.pi * u3)], axis=1)
    x[:, Q] /= np.linalg.norm(x[:, Q], axis=1, keepdims=True)
    x[:, OMEGA] = (2.0 * u[:, 3:6] - 1.0) * OMEGA_FRACTION * L.omega_max_rad_s
    x[:, PSI] = (2.0 * u[:, 6:9] - 1.0) * PSI_FRACTION * L.psi_max_rad_s
    t_lo, t_hi = TEMPERATURE_RANGE_DEGC
    x[:, TEMP] = CELSIUS_OFFSET_K + t_lo + (t_hi - t_lo) * u[:, 9]
    e_lo = ENERGY_MIN_FACTOR * L.energy_min_J
    x[:, ENERGY] = e_lo + (ENERGY_MAX_J - e_lo) * u[:, 10]
    th_lo, th_hi = THETA_S_RANGE_RAD
    x[:, THETA_S] = th_lo + (th_hi - th_lo) * u[:, 11]
    if cfg.environment.eclipse_s > 0.0:  # E above what the eclipse ahead needs (`battery.eclipse_floor`)
        x[:, ENERGY] += eclipse_floors(x[:, THETA_S], plant_record(cfg)[0])
    return x


def rejected(x: Array, cfg: Config) -> NDArray[np.bool_]:
    """(n,) True where an enabled constraint has h, Psi_0 or Psi_1 < 0 at x (n, 19) under any filter
    preset (the robust preset may keep a sampled-data margin in Psi_0), with the paper model's margins and
    no sensor errors: one test for all presets, models and sensor settings, so a seed gives the same
    initial states whichever preset, model and sensors run them (a gyrostat filter, or the robust
    preset's measurement margins with sensor errors on, may start inside its margin, h >= 0)."""
    out = np.zeros(len(x), dtype=bool)
    exact = cfg.with_noise(False)
    for preset in PRESETS:
        cs = ConstraintSet.from_config(exact.with_preset(preset).with_models(filter="paper"))
        t = cs.evaluate(x)
        on = cs.enabled.astype(bool)
        out |= np.any(((t["h"] < 0) | (t["psi0"] < 0) | (t["psi1"] < 0)) & on, axis=1)
    return out


def sample_initial_states(runs: int, seed: int, cfg: Config) -> tuple[Array, NDArray[np.int64]]:
    """Latin-hypercube initial states inside the safe set (SPEC sec. 5.2).

    Args:
        runs: number of states.
        seed: seed of the one random stream (hypercube and re-draws).
        cfg: limits and barrier gains (the filter preset is not used).

    Returns:
        (states (runs, 19), re-draws per state (runs,)).

    Raises:
        RtaError: states still rejected after MAX_REDRAW_ROUNDS rounds.
    """
    drop_stale_caches()  # a library entry point (kernel_cache)
    from scipy.stats import qmc

    if runs < 1:
        raise ConfigError(f"runs must be >= 1, got {runs}")
    rng = np.random.default_rng(seed)
    x = _to_states(qmc.LatinHypercube(d=SAMPLE_DIMENSIONS, seed=rng).random(runs), cfg)
    redraws = np.zeros(runs, dtype=np.int64)
    bad = rejected(x, cfg)
    for _ in range(MAX_REDRAW_ROUNDS):
        k = int(bad.sum())
        if k == 0:
            return x, redraws
        idx = np.flatnonzero(bad)
        cube = qmc.LatinHypercube(d=SAMPLE_DIMENSIONS, seed=rng).random(k) if k > 1 else rng.random((1, 12))
        x[idx] = _to_states(cube, cfg)
        redraws[idx] += 1
        bad[idx] = rejected(x[idx], cfg)
    raise RtaError(f"{int(bad.sum())} initial states still outside the safe set after {MAX_REDRAW_ROUNDS} re-draws")



__all__ = ["ENERGY_MAX_J", "ENERGY_MIN_FACTOR", "OMEGA_FRACTION", "PSI_FRACTION", "SAMPLE_DIMENSIONS",
           "TEMPERATURE_RANGE_DEGC", "THETA_S_RANGE_RAD", "rejected", "sample_initial_states"]
