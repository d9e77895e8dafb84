"""The oracle's parameters, read once from the project's Config (the one parameter source).

`OracleModel` is a frozen, hashable record of plain floats and tuples: the casadi expressions are
built from it (so a different configuration is a different compiled block, keyed by the source's
hash) and `functools.lru_cache` can key on it. Nothing here imports casadi.

The oracle's constraint groups are the configuration's (`Config.groups`, in that order): every pointing
constraint by name (a cone of `constraints.pointing`, `OracleCone`), then the fixed groups of
`config.schema.FIXED_GROUPS` (the thermal node's temperature, the battery, the body rates and the wheel speeds,
the last two reported as the worst of their three axes). What each group is comes from the registry's kind
(`constraints.registry.KINDS`), never from its name. By default the oracle enforces the hard groups (enabled,
no slack): the ones the Monte Carlo counts as failures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config, unit_vector
from rta_attitude.constraints.registry import KINDS, registry
from rta_attitude.dynamics.environment import target_kind
from rta_attitude.dynamics.spacecraft import plant_record
from rta_attitude.errors import ConfigError

Array = NDArray[np.float64]

KEEP_OUT, KEEP_IN, TEMPERATURE, BATTERY, RATE, WHEEL_SPEED = KINDS
"""The registry's kinds of constraint, as the oracle names them."""
POINTING_KINDS = (KEEP_OUT, KEEP_IN)
N_X = 13
"""Oracle state: the first 13 entries of the project's state (q, omega, psi, T, E, theta_S); the
Clohessy-Wiltshire entries do not couple into the attitude and are left out."""
ENERGY_SCALE_J = 1000.0
"""Scale of the battery row inside the optimiser, J."""
TEMPERATURE_SCALE_K = 100.0
"""Scale of the temperature state inside the optimiser, K."""
UNITS: dict[str, str] = {KEEP_OUT: "rad", KEEP_IN: "rad", TEMPERATURE: "K", BATTERY: "J", RATE: "rad/s",
                         WHEEL_SPEED: "rad/s"}
"""Units of the oracle's h by kind (`model.constraint_values`): a cone's angle margin, T_max - T, E - E_min, and
limit - max_i |.| for the rates and the wheel speeds."""


@dataclass(frozen=True)
class OracleCone:
    """One pointing constraint (`constraints.pointing` entry) as the oracle reads it: the body axis `boresight_body`
    (unit) stays outside (keep_out) or inside (keep_in) the cone of half-angle `half_angle_rad` about a target."""

    name: str
    kind: str
    """KEEP_OUT or KEEP_IN."""
    boresight_body: tuple[float, float, float]
    """Unit vector, body axes (normalised here)."""
    target_kind: int
    """`dynamics.environment`'s code: SUN, EARTH, HILL_FIXED or INERTIAL_FIXED."""
    target_vector: tuple[float, float, float]
    """The target in Hill (EARTH, HILL_FIXED) or in the inertial frame (INERTIAL_FIXED); unused for SUN."""
    half_angle_rad: float
    windows_s: tuple[tuple[float, float], ...] = ()
    """(start, end) times, s from the run's t = 0, within which the cone applies; empty: always."""

    @property
    def keep_in(self) -> bool:
        return self.kind == KEEP_IN

    def applies(self, t_s: float | Array) -> NDArray[np.bool_]:
        """Whether the cone applies at times t_s (...): inside one of its windows (ends included), or always
        without windows (`constraints.windows.window_phase` == 'inside')."""
        t = np.asarray(t_s, dtype=float)
        if not self.windows_s:
            return np.ones(t.shape, dtype=bool)
        out = np.zeros(t.shape, dtype=bool)
        for start, end in self.windows_s:
            out |= (t >= start) & (t <= end)
        return out


@dataclass(frozen=True)
class OracleModel:
    """Everything the oracle's model, rules and laws need, in model units (from `from_config`)."""

    gyrostat: bool
    """True: the wheels' gyroscopic term -omega x (-D psi) (config `spacecraft.model: gyrostat`)."""
    inertia_kgm2: tuple[float, float, float]
    """The tensor's diagonal (the principal moments where `principal`)."""
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
    sun_beta_rad: float
    """The sun's angle out of the orbit plane (`environment.sun_beta_rad`)."""
    shadow_sx: float
    """The Earth's shadow: r_S . x_Hill below it (`environment.shadow_sx`; -inf without an eclipse)."""
    face_normal_body: tuple[float, float, float]
    """The thermal node's face, outward unit normal, body axes (`thermal.face_normal_body`)."""
    panel_normal_body: tuple[float, float, float]
    """The solar panel's unit normal, body axes (`power.panel_normal_body`)."""
    cones: tuple[OracleCone, ...]
    """The pointing constraints, in the configuration's order."""
    constraints: tuple[tuple[str, str, str], ...]
    """(name, group, kind) of every constraint, in the registry's row order."""
    temperature_max_K: float
    energy_min_J: float
    omega_max_rad_s: float
    psi_max_rad_s: float
    wheel_speed_relative: bool
    """psi_max bounds |psi_i + omega_i|, the rotor's speed relative to the body
    (`limits.wheel_speed_relative_to_body`)."""
    psi_keep_rad_s: float
    """The |psi_i| the transcription and the laws keep (`Config.psi_keep_rad_s`: psi_max, less omega_max if
    relative)."""
    u_max_rad_s2: tuple[float, float, float]
    """The box U (`Config.u_max_rad_s2`)."""
    dt_s: float
    substeps: int
    kp: float
    kd: float
    wheel_accel_max_rad_s2: float
    inertia_matrix: tuple[tuple[float, float, float], ...]
    """The inertia tensor (3 x 3, body axes)."""
    principal: bool
    """No products of inertia (the rules' proofs are per principal axis: `rules.rules_apply`)."""
    wheel_axes: tuple[tuple[float, float, float], ...]
    """A (3 x 3): wheel i's spin axis in body axes is column i (the identity: a wheel on each body axis)."""

    @property
    def A(self) -> NDArray[np.float64]:
        """`wheel_axes` as an array (3, 3)."""
        return np.array(self.wheel_axes, dtype=float)

    @property
    def wheels_on_body_axes(self) -> bool:
        """Wheel i spins about body axis i."""
        return bool(np.array_equal(self.A, np.eye(3)))

    @property
    def name(self) -> str:
        return "gyrostat" if self.gyrostat else "paper"

    @property
    def J(self) -> Array:
        """The tensor's diagonal (3,)."""
        return np.array(self.inertia_kgm2)

    @property
    def J_matrix(self) -> Array:
        """The tensor (3, 3)."""
        return np.array(self.inertia_matrix)

    @property
    def u_max(self) -> Array:
        return np.array(self.u_max_rad_s2)

    @property
    def sun_cos_beta(self) -> float:
        return math.cos(self.sun_beta_rad)

    @property
    def sun_sin_beta(self) -> float:
        return math.sin(self.sun_beta_rad)

    @property
    def x_scale(self) -> Array:
        """Scale of each state entry inside the optimiser (13,)."""
        w, p = self.omega_max_rad_s, self.psi_max_rad_s
        return np.array([1.0, 1.0, 1.0, 1.0, w, w, w, p, p, p, TEMPERATURE_SCALE_K, ENERGY_SCALE_J, 1.0])

    @property
    def groups(self) -> tuple[str, ...]:
        """The constraint groups (`Config.groups`): the cones by name, then the fixed groups."""
        return tuple(dict.fromkeys(group for _, group, _ in self.constraints))

    def kind(self, group: str) -> str:
        """The registry's kind of a group (KINDS).

        Raises:
            KeyError: not a group of this model.
        """
        for _, g, kind in self.constraints:
            if g == group:
                return kind
        raise KeyError(f"unknown constraint group {group!r}; known: {', '.join(self.groups)}")

    def kinds(self, groups: Sequence[str]) -> frozenset[str]:
        """The kinds of some groups."""
        return frozenset(self.kind(g) for g in groups)

    def cone(self, group: str) -> OracleCone:
        """The pointing constraint of a group."""
        for c in self.cones:
            if c.name == group:
                return c
        raise KeyError(f"no pointing constraint {group!r}; known: {', '.join(c.name for c in self.cones)}")

    def scale(self, group: str) -> float:
        """Scale of a constraint's row: the optimiser keeps h >= margin * scale (natural units of h)."""
        return {KEEP_OUT: 1.0, KEEP_IN: 1.0, TEMPERATURE: self.temperature_max_K, BATTERY: ENERGY_SCALE_J,
                RATE: self.omega_max_rad_s, WHEEL_SPEED: self.psi_max_rad_s}[self.kind(group)]

    def unit(self, group: str) -> str:
        """The unit of a group's h in `model.constraint_values` (UNITS)."""
        return UNITS[self.kind(group)]


def oracle_cones(cfg: Config) -> tuple[OracleCone, ...]:
    """The configuration's pointing constraints as OracleCone records (unit vectors normalised)."""
    out = []
    for c in cfg.pointing:
        code, vector = target_kind(c.target)
        if c.target_vector is not None:
            vector = unit_vector(f"constraints.pointing.{c.name}.target_vector", c.target_vector)
        out.append(OracleCone(c.name, c.kind, unit_vector(f"constraints.pointing.{c.name}.boresight_body",
                                                          c.boresight_body),
                              code, tuple(float(v) for v in vector), c.half_angle_rad,  # type: ignore[arg-type]
                              tuple((float(a), float(b)) for a, b in c.windows_s)))
    return tuple(out)


def from_config(cfg: Config) -> OracleModel:
    """The oracle's parameters of a configuration (plant constants formed as the plant forms them)."""
    cfg.spacecraft.require_three_wheels("the viability oracle")
    p = plant_record(cfg)[0]
    L = cfg.limits
    return OracleModel(
        gyrostat=bool(p["wheel_gyroscopic"]),
        inertia_kgm2=tuple(float(v) for v in p["inertia_kgm2"]),  # type: ignore[arg-type]
        wheel_inertia_kgm2=float(p["wheel_inertia_kgm2"]),
        inertia_matrix=tuple(tuple(float(v) for v in row) for row in p["inertia_matrix"]),
        principal=bool(cfg.spacecraft.principal),
        wheel_axes=tuple(tuple(float(v) for v in row) for row in p["wheel_axes"]),
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
        sun_beta_rad=float(cfg.environment.sun_beta_rad),
        shadow_sx=float(p["shadow_sx"]),
        face_normal_body=unit_vector("thermal.face_normal_body", cfg.thermal.face_normal_body),
        panel_normal_body=unit_vector("power.panel_normal_body", cfg.power.panel_normal_body),
        cones=oracle_cones(cfg),
        constraints=tuple((c.name, c.group, c.kind) for c in registry(cfg)),
        temperature_max_K=L.temperature_max_K,
        energy_min_J=L.energy_min_J,
        omega_max_rad_s=L.omega_max_rad_s,
        psi_max_rad_s=L.psi_max_rad_s,
        wheel_speed_relative=L.wheel_speed_relative_to_body,
        psi_keep_rad_s=cfg.psi_keep_rad_s,
        u_max_rad_s2=tuple(float(v) for v in cfg.u_max_rad_s2),  # type: ignore[arg-type]
        dt_s=cfg.filter.sample_time_s,
        substeps=cfg.substeps,
        kp=cfg.controller.kp,
        kd=cfg.controller.kd,
        wheel_accel_max_rad_s2=L.wheel_accel_max_rad_s2,
    )


def default_enforce(cfg: Config) -> tuple[str, ...]:
    """The groups a witness must keep: the hard ones (enabled, no slack; what the Monte Carlo counts), in
    `Config.groups` order."""
    hard = {c.group for c in registry(cfg) if c.hard}
    return tuple(g for g in cfg.groups if g in hard)


def check_enforce(enforce: Sequence[str], cfg: Config) -> tuple[str, ...]:
    """`enforce` in `Config.groups` order.

    Raises:
        ConfigError: a name that is not one of the configuration's groups.
    """
    for name in enforce:
        if name not in cfg.groups:
            raise ConfigError(f"enforce: unknown constraint group {name!r}; known: {', '.join(cfg.groups)}")
    return tuple(g for g in cfg.groups if g in set(enforce))


def substep_times(t0_s: float, n: int, m: OracleModel) -> Array:
    """Times (n,) of the states x0, then n - 1 substeps after it, s: t0 + dt i / substeps, i = 0 .. n - 1
    (a node k is i = k substeps; the one formula every part of the oracle uses)."""
    return t0_s + m.dt_s * (np.arange(n, dtype=np.float64) / m.substeps)


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


__all__ = ["BATTERY", "ENERGY_SCALE_J", "KEEP_IN", "KEEP_OUT", "N_X", "POINTING_KINDS", "RATE", "TEMPERATURE",
           "UNITS", "WHEEL_SPEED", "OracleCone", "OracleModel", "as_oracle_state", "check_enforce",
           "default_enforce", "from_config", "oracle_cones", "substep_times"]
