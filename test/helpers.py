"""Shared test utilities: seeded random states inside and around the safe set."""

from __future__ import annotations

import numpy as np

from rta_attitude.params import Config
from rta_attitude.state import STATE_SIZE


def random_states(rng: np.random.Generator, n: int, cfg: Config) -> np.ndarray:
    """n random states (n, 19): uniform attitudes, rates up to 1.5 w_max, any wheel speed and sun angle."""
    x = np.zeros((n, STATE_SIZE))
    q = rng.normal(size=(n, 4))
    x[:, 0:4] = q / np.linalg.norm(q, axis=1, keepdims=True)
    x[:, 4:7] = rng.uniform(-1.5, 1.5, (n, 3)) * cfg.limits.omega_max_rad_s
    x[:, 7:10] = rng.uniform(-1.0, 1.0, (n, 3)) * cfg.limits.psi_max_rad_s
    x[:, 10] = rng.uniform(250.0, 300.0, n)
    x[:, 11] = rng.uniform(500.0, 10000.0, n)
    x[:, 12] = rng.uniform(0, 2 * np.pi, n)
    x[:, 13:19] = rng.normal(size=(n, 6)) * [100, 100, 100, 0.1, 0.1, 0.1]
    return x
