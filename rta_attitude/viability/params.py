"""The oracle's parameters, read once from the project's Config (the one parameter source).

`OracleModel` is a frozen, hashable record of plain floats and tuples: the casadi expressions are
built from it (so a different configuration is a different compiled block, keyed by the source's
hash) and `functools.lru_cache` can key on it. Nothing here imports casadi.

Constraint names are the config's groups (`BARRIER_GROUPS`): exclusion_zone, communication,
temperature, battery, omega (three axes, reported as the worst), psi (three wheels, the worst).
By default the oracle enforces the enabled constraints without a slack (slack_weight == 0): the
ones the Monte Carlo counts as failures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import BARRIER_GROUPS, Config
from rta_attitude.dynamics.spacecraft import EARTH_HILL, plant_record
from rta_attitude.errors import ConfigError

Array = NDArray[np.float64]

N_X = 13
"""Oracle state: the first 13 entries of the project's state (q, omega, psi, T, E, theta_S); the
Clohessy-Wiltshire entries do not couple into the attitude and are left out."""
GROUPS: tuple[str, ...] = BARRIER_GROUPS
"""Constraint names the oracle knows (the config's `constraints:` groups)."""
ENERGY_SCALE_J = 1000.0
"""Scale of the battery row inside the optimiser, J."""
TEMPERATURE_SCALE_K = 100.0
"""Scale of the temperature state inside the optimiser, K."""


@dataclass(frozen=True)
class OracleModel:
    """Everything the oracle's model, rules and laws need, in model units (from `from_config`)."""

    gyrostat: bool
    """True: the wheels' gyroscopic term -omega x (-D psi) (config `spacecraft.model: gyrostat`)."""
    inertia_kgm2: tuple[float, float, float]
    wheel_inertia_kgm2: float
    torque_sign: float
    control_gain: tuple[float, float, float]
    """d omega_dot / d u = sign D / J_i."""
    frame_rate_rad_s: float
    gravity_gradient: bool
    mean_motion_rad_s: float
    heat_capacity_J_K: float
    earth_view_factor: float
    clamp_view_factor: bool
    sigma_eps_A_W_K4: float
    solar_W: float
    albedo_W: float
    earth_T4_K4: float
    panel_peak_W: float
    load_W: float
    earth_hill: tuple[float, float, float]
    exclusion_angle_rad: float
    comm_angle_rad: float
    temperature_max_K: float
    energy_min_J: float
    omega_max_rad_s: float
    psi_max_rad_s: float
    u_max_rad_s2: tuple[float, float, float]
    """The box U (`Config.u_max_rad_s2`)."""
    dt_s: float
    substeps: int
    kp: float
    kd: float
    wheel_accel_max_rad_s2: float

    @property
    def name(self) -> str:
        return "gyrostat" if self.gyrostat else "paper"

    @property
    def J(self) -> Array:
        return np.array(self.inertia_kgm2)

    @property
    def u_max(self) -> Array:
        return np.array(self.u_max_rad_s2)

    @property
    def x_scale(self) -> Array:
        """Scale of each state entry inside the optimiser (13,)."""
        w, p = self.omega_max_rad_s, self.psi_max_rad_s
        return np.array([1.0, 1.0, 1.0, 1.0, w, w, w, p, p, p, TEMPERATURE_SCALE_K, ENERGY_SCALE_J, 1.0])

    def scale(self, group: str) -> float:
        """Scale of a constraint's row: the optimiser keeps h >= margin * scale (natural units of h)."""
        return {"exclusion_zone": 1.0, "communication": 1.0, "temperature": self.temperature_max_K,
                "battery": ENERGY_SCALE_J, "omega": self.omega_max_rad_s, "psi": self.psi_max_rad_s}[group]


def from_config(cfg: Config) -> OracleModel:
    """The oracle's parameters of a configuration (plant constants formed as the plant forms them)."""
    p = plant_record(cfg)[0]
    L = cfg.limits
    return OracleModel(
        gyrostat=bool(p["wheel_gyroscopic"]),
        inertia_kgm2=tuple(float(v) for v in p["inertia_kgm2"]),  # type: ignore[arg-type]
        wheel_inertia_kgm2=float(p["wheel_inertia_kgm2"]),
        torque_sign=float(cfg.spacecraft.torque_sign),
        control_gain=tuple(float(v) for v in p["control_gain"]),  # type: ignore[arg-type]
        frame_rate_rad_s=float(p["frame_rate_rad_s"]),
        gravity_gradient=bool(p["gravity_gradient"]),
        mean_motion_rad_s=float(p["mean_motion_rad_s"]),
        heat_capacity_J_K=float(p["heat_capacity_J_K"]),
        earth_view_factor=float(p["earth_view_factor"]),
        clamp_view_factor=bool(p["clamp_view_factor"]),
        sigma_eps_A_W_K4=float(p["sigma_eps_A_W_K4"]),
        solar_W=float(p["solar_W"]),
        albedo_W=float(p["albedo_W"]),
        earth_T4_K4=float(p["earth_T4_K4"]),
        panel_peak_W=float(p["panel_peak_W"]),
        load_W=float(p["load_W"]),
        earth_hill=tuple(float(v) for v in EARTH_HILL),  # type: ignore[arg-type]
        exclusion_angle_rad=L.exclusion_angle_rad,
        comm_angle_rad=L.comm_angle_rad,
        temperature_max_K=L.temperature_max_K,
        energy_min_J=L.energy_min_J,
        omega_max_rad_s=L.omega_max_rad_s,
        psi_max_rad_s=L.psi_max_rad_s,
        u_max_rad_s2=tuple(float(v) for v in cfg.u_max_rad_s2),  # type: ignore[arg-type]
        dt_s=cfg.filter.sample_time_s,
        substeps=cfg.substeps,
        kp=cfg.controller.kp,
        kd=cfg.controller.kd,
        wheel_accel_max_rad_s2=L.wheel_accel_max_rad_s2,
    )


def default_enforce(cfg: Config) -> tuple[str, ...]:
    """The constraints a witness must keep: enabled and without a slack (what the Monte Carlo counts)."""
    return tuple(g for g in GROUPS if cfg.barriers[g].enabled and cfg.barriers[g].slack_weight == 0)


def check_enforce(enforce: Sequence[str]) -> tuple[str, ...]:
    """`enforce` in GROUPS order; ConfigError on an unknown name."""
    unknown = sorted(set(enforce) - set(GROUPS))
    if unknown:
        raise ConfigError(f"unknown constraint(s) {', '.join(unknown)}; known: {', '.join(GROUPS)}")
    return tuple(g for g in GROUPS if g in set(enforce))


def as_oracle_state(x0: Array | Sequence[float]) -> Array:
    """A copy of x0 as the oracle's state (13,), quaternion normalised. Takes the project's state
    (19,) (the CW entries are dropped) or the 13 attitude entries.

    Raises:
        ValueError: wrong length, non-finite entries or a zero quaternion.
    """
    x = np.array(x0, dtype=float).ravel()
    if x.shape not in ((N_X,), (19,)):
        raise ValueError(f"a state must have 13 or 19 entries (q1..q4, omega, psi, T, E, theta_S[, CW]), "
                         f"got {x.shape[0]}")
    x = x[:N_X].copy()
    if not np.all(np.isfinite(x)):
        raise ValueError(f"a state must be finite, got {x.tolist()}")
    nq = math.sqrt(float(x[:4] @ x[:4]))
    if nq == 0.0:
        raise ValueError("the quaternion of a state must be nonzero")
    x[:4] /= nq
    return x


__all__ = ["ENERGY_SCALE_J", "GROUPS", "N_X", "OracleModel", "as_oracle_state", "check_enforce", "default_enforce",
           "from_config"]
