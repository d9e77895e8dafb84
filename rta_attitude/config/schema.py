"""Typed, frozen parameter sets, in model units (SI, rad, K), each checked on construction.

Built by `rta_attitude.config.load` from the YAML file; nothing else converts units.
"""

from __future__ import annotations

import datetime as _dt
import importlib.util
import math
import re
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.inertia import check_inertia, euler_bound, inertia_matrix, is_principal, principal_moments
from rta_attitude.errors import ConfigError
from rta_attitude.topics import WHEEL_JOINTS

FIXED_GROUPS: tuple[str, ...] = ("temperature", "battery", "omega", "psi")
"""The constraints that are not pointing cones, as sections of `constraints:` (after `pointing`): the thermal
node's temperature, the battery's charge, and the body rate and wheel speed, each per axis."""
AXIS_NAMES: tuple[str, ...] = ("x", "y", "z")
FIXED_NAMES: tuple[str, ...] = (
    "temperature", "battery", *(f"omega_{a}" for a in AXIS_NAMES), *(f"psi_{a}" for a in AXIS_NAMES),
)  # fmt: skip
"""The rows of FIXED_GROUPS, in report order (after the pointing cones)."""
PER_AXIS_GROUPS: tuple[str, ...] = ("omega", "psi")
"""Groups with one constraint per body axis (`omega_x` ...), always hard."""
MAX_POINTING = 16
"""Pointing constraints (`constraints.pointing`) a configuration may hold: the compiled table's capacity, so
that any number up to it runs without recompiling the kernels."""
MAX_WINDOWS = 8
"""Time windows one pointing constraint may hold."""
POINTING_KINDS: tuple[str, ...] = ("keep_out", "keep_in")
"""keep_out: the boresight stays outside the cone about the target; keep_in: inside it."""
TARGET_NAMES: tuple[str, ...] = ("sun", "earth", "orbit_normal", "velocity", "hill", "inertial")
"""What a pointing constraint's cone is about (`dynamics.environment`): the sun; nadir; the orbit normal; the
along-track velocity; a fixed vector in Hill; a fixed vector in the inertial frame (x toward the sun's
direction in the orbit plane at theta_S = 0, z the orbit normal)."""
NAME_CHARACTERS = frozenset("abcdefghijklmnopqrstuvwxyz0123456789_")

PRESETS: tuple[str, ...] = ("robust", "paper")
FALLBACKS: tuple[str, ...] = ("pass_through", "hold", "soften", "raise", "prioritize")
BACKUP_SOLVERS: tuple[str, ...] = ("quadprog", "none")
SOLVERS: tuple[str, ...] = ("active_set", "proxsuite")
CONTROLLERS: tuple[str, ...] = ("pd", "none")
ACTUATOR_LAGS: tuple[str, ...] = ("compensate", "bound")
"""How the robust filter treats the wheel drive's first-order lag (`filter.actuator_lag`, with sensor errors on):
compensate (the filter tracks the drive's state from its own commands and sends the command whose held mean
is its answer: `filter.drive.drive_command`); bound (the answer is sent as it is and every row keeps the
lag's largest departure from it, a full reversal inside U, as a margin: docs/noise.md)."""
BACKUP_LAWS: tuple[str, ...] = ("none", "sun_safe")
"""Backup laws of the gatekeeper (`filter.backup_law`): none (no gatekeeper: the ASIF's answer is
applied); sun_safe (the filter applies its answer only if the answer then the sun-safe law are safe
over `filter.backup_horizon_s`, else the sun-safe law of its committed plan: `filter.gatekeeper`)."""
MAX_BACKUP_SUBSTEPS = 64
"""integrator.substeps at most this with a backup law (the gatekeeper's scratch rows)."""
MAX_NOMINAL_STEPS = 120
"""filter.backup_nominal_s / filter.sample_time_s at most this (the gatekeeper's plan rows)."""
PLANT_MODELS: tuple[str, ...] = ("gyrostat", "paper")
"""Models of the spacecraft, for the simulated plant (`spacecraft.model`) and for the filter's barriers
(`filter.model`): gyrostat: the wheels' momentum in Euler's equations (-omega x (J omega - s D psi));
paper: without it (the paper's model)."""
SIMULATORS: tuple[str, ...] = ("compiled", "basilisk")
"""What integrates the simulated spacecraft: `compiled`, the package's own RK4 of `spacecraft.model`
(`dynamics.spacecraft`); `basilisk`, Basilisk (the optional `bsk` package) as an independent truth plant
(`dynamics.basilisk`: rigid hub and three wheels, always with the wheels' gyroscopic torque)."""
BASILISK_MISSING = "plant.simulator basilisk needs the optional extra: pip install rta_attitude[basilisk]"


def group_of(name: str) -> str:
    """The group (a section of `constraints:`) of a constraint: omega_y -> omega, psi_x or psi_<wheel> -> psi, else
    itself."""
    head, _, axis = name.partition("_")
    if head == "psi" and WHEEL_NAME.fullmatch(axis):
        return head
    head, _, axis = name.rpartition("_")
    return head if head in PER_AXIS_GROUPS and axis in AXIS_NAMES else name


def wheel_constraint_name(wheel: str) -> str:
    """The speed constraint of the wheel with joint name `wheel`: psi_<name> less a leading 'wheel_' (the paper's
    wheel_x: psi_x)."""
    return "psi_" + wheel.removeprefix("wheel_")


def _positive(where: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{where} must be > 0, got {value!r}")


def _nonneg(where: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0):
        raise ConfigError(f"{where} must be >= 0, got {value!r}")


DEFAULT_EPOCH_UTC = "2024-03-02T00:00:00Z"
"""The scenarios' default epoch: t = 0 of a run is this UTC date in its ROS time stamps (/clock, headers, bag
times); a fixed date (the first day of the IEEE Aerospace Conference 2024, where the paper appeared) so that
runs are reproducible bit for bit."""
_UNIX_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.UTC)


def epoch_ns(where: str, text: str) -> int:
    """Nanoseconds since 1970-01-01T00:00:00Z of an ISO 8601 UTC time ('2024-03-02T00:00:00Z'), exact to the
    microsecond.

    Raises:
        ConfigError: not an ISO 8601 date-time, not UTC, or before 1970.
    """
    try:
        when = _dt.datetime.fromisoformat(text)
    except (TypeError, ValueError):
        raise ConfigError(f"{where} must be an ISO 8601 UTC date-time such as {DEFAULT_EPOCH_UTC}, "
                          f"got {text!r}") from None
    if when.utcoffset() != _dt.timedelta(0):
        raise ConfigError(f"{where} must be in UTC (end it with Z or +00:00), got {text!r}")
    if when < _UNIX_EPOCH:
        raise ConfigError(f"{where} must not be before 1970-01-01 (ROS time starts there), got {text!r}")
    return (when - _UNIX_EPOCH) // _dt.timedelta(microseconds=1) * 1000


def _choice(where: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ConfigError(f"{where} must be one of {', '.join(allowed)}, got {value!r}")


BODY_AXES: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
"""The paper's wheels' spin axes: one wheel on each body axis."""
WHEEL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
"""A wheel's name: a ROS joint name that is also a parameter name's part."""


def spanning(axes: NDArray[np.float64]) -> float:
    """The smallest singular value of the (3, k) matrix of spin axes as columns: 0 where they do not span the body's
    three axes (fewer than three, or all in a plane)."""
    if axes.shape[1] < 3:
        return 0.0
    return float(np.linalg.svd(axes, compute_uv=False)[2])


WHEEL_CONDITION_MIN = 1e-3
"""The wheels' spin axes must span the body's three axes: the matrix of their axes' smallest singular value at
least this (below it one axis is all but out of their reach)."""


@dataclass(frozen=True)
class Spacecraft:
    """Rigid body with N >= 3 reaction wheels (`wheel_axes_body`: three on its body axes unless configured)."""

    inertia_kgm2: tuple[float, float, float]
    """The inertia tensor's diagonal J_xx, J_yy, J_zz in body axes (the principal moments where the products are
    zero), kg m^2."""
    wheel_inertia_kgm2: float
    """D, wheel spin-axis inertia, kg m^2."""
    torque_sign: float = 1.0
    """+1: tau = +D psi_dot (the paper); -1: a physical reaction torque."""
    model: str = "gyrostat"
    """The simulated plant (PLANT_MODELS): `gyrostat` (the wheels' gyroscopic torque included) or `paper`
    (dropped). The filter's own model is `filter.model`."""
    inertia_uncertainty: float = 0.0
    """How far the vehicle's inertia may be from the configured, a fraction (0.01: +-1 %): on principal axes each
    principal moment; with products of inertia the tensor in every direction (-delta J <= J' - J <= delta J, its
    axes uncertain too). The robust preset's rows stay safe for any inertia within it (docs/conventions.md,
    "Inertia")."""
    transport_delay_s: float = 0.0
    """From a command to the wheels (the flight computer's compute and bus), s: the wheels hold sample k's
    command over [t_k + delay, t_k+1 + delay), the previous command before. Part of the plant and of the
    filter's model (docs/delay.md); 0 to less than one sample, a whole number of RK4 substeps
    (`Config.delay_substeps`)."""
    products_of_inertia_kgm2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The tensor's off-diagonal entries J_xy, J_xz, J_yz (J_xy = -int x y dm), kg m^2 (`config.inertia`); zero:
    the body axes are principal."""
    wheel_axes_body: tuple[tuple[float, float, float], ...] = BODY_AXES
    """Each wheel's spin axis, a unit vector in body axes, in the order of `wheel_names` (wheel i's speed is
    psi_i, its acceleration u_i): the body's angular acceleration is G u with G = s D J^-1 A, A (3, N) with these
    axes as columns, and the wheels' momentum -s D A psi (docs/conventions.md, "Wheels")."""
    failed_wheels: tuple[str, ...] = ()
    """Wheels (by joint name) whose drive gives no torque: the plant holds their acceleration at 0 (each coasts at
    its speed, its momentum still in Euler's equations) and the filter's box is 0 on them. 3-axis control is lost
    when the wheels left no longer span the body's axes (with three wheels, at the first failure; "Wheels",
    docs/conventions.md)."""
    wheel_names: tuple[str, ...] = WHEEL_JOINTS
    """The wheels' joint names, in wheel order (the keys of `spacecraft.wheel_spin_axes_body`)."""

    def __post_init__(self) -> None:
        _choice("spacecraft.model", self.model, PLANT_MODELS)
        if not (math.isfinite(self.inertia_uncertainty) and 0.0 <= self.inertia_uncertainty < 0.5):
            raise ConfigError(f"spacecraft.inertia_uncertainty must be a fraction in [0, 0.5), got "
                              f"{self.inertia_uncertainty!r}")
        if not (math.isfinite(self.transport_delay_s) and self.transport_delay_s >= 0.0):
            raise ConfigError(f"spacecraft.transport_delay_s must be >= 0 s, got {self.transport_delay_s!r}")
        for i, j in enumerate(self.inertia_kgm2):
            _positive(f"spacecraft.inertia_kgm2[{i}]", j)
        _positive("spacecraft.wheel_inertia_kgm2", self.wheel_inertia_kgm2)
        if self.torque_sign not in (1.0, -1.0):
            raise ConfigError(f"spacecraft.torque_sign must be 1.0 or -1.0, got {self.torque_sign!r}")
        check_inertia(self.inertia_matrix, "spacecraft.inertia_kgm2 with spacecraft.products_of_inertia_kgm2")
        n = len(self.wheel_axes_body)
        if n < 3:
            raise ConfigError(f"spacecraft.wheel_spin_axes_body must give at least 3 wheels, got {n}")
        if len(self.wheel_names) != n:
            raise ConfigError(f"spacecraft: {len(self.wheel_names)} wheel names for {n} spin axes")
        for name in self.wheel_names:
            if not WHEEL_NAME.fullmatch(name):
                raise ConfigError(f"spacecraft.wheel_spin_axes_body: a wheel's name must be a letter then letters, "
                                  f"digits or '_' (a ROS joint and parameter name), got {name!r}")
        if len(set(self.wheel_names)) != n:
            raise ConfigError(f"spacecraft.wheel_spin_axes_body names a wheel twice: {list(self.wheel_names)!r}")
        for name, a in zip(self.wheel_names, self.wheel_axes_body):
            unit_vector(f"spacecraft.wheel_spin_axes_body.{name}", a)
        smallest = spanning(self.wheel_axes)
        if not smallest >= WHEEL_CONDITION_MIN:
            raise ConfigError(f"spacecraft.wheel_spin_axes_body: the wheels' axes must span the three body axes "
                              f"(3-axis control); their smallest singular value is {smallest:.3g}, below "
                              f"{WHEEL_CONDITION_MIN}")
        for name in self.failed_wheels:
            if name not in self.wheel_names:
                raise ConfigError(f"spacecraft.failed_wheels: unknown wheel {name!r}; the wheels are "
                                  f"{', '.join(self.wheel_names)}")
        if len(set(self.failed_wheels)) != len(self.failed_wheels):
            raise ConfigError(f"spacecraft.failed_wheels names a wheel twice: {list(self.failed_wheels)!r}")

    def require_three_wheels(self, what: str) -> None:
        """Raise ConfigError (one line naming `what`) for an array of more than three wheels: the plant model and
        Basilisk take any array, the filter, the controller's closed loop, the nodes' messages and the Monte Carlo
        take three so far."""
        if self.n_wheels != 3:
            raise ConfigError(f"{what} takes three reaction wheels; spacecraft.wheel_spin_axes_body gives "
                              f"{self.n_wheels} ({', '.join(self.wheel_names)}), which the plant model "
                              f"(rta_attitude.dynamics.plant) and Basilisk take (docs/conventions.md, \"Wheels\")")

    @property
    def J(self) -> NDArray[np.float64]:
        """The tensor's diagonal as an array (3,), kg m^2: the principal moments where `principal`."""
        return np.array(self.inertia_kgm2, dtype=float)

    @property
    def principal(self) -> bool:
        """The body axes are principal (no products of inertia): the kernels' principal-axis arithmetic."""
        return is_principal(self.products_of_inertia_kgm2)

    @property
    def n_wheels(self) -> int:
        """N, the number of wheels."""
        return len(self.wheel_axes_body)

    @property
    def wheel_axes(self) -> NDArray[np.float64]:
        """A (3, N): wheel i's spin axis in body axes is column i."""
        return np.array(self.wheel_axes_body, dtype=float).reshape(-1, 3).T

    @property
    def wheel_axes_inverse(self) -> NDArray[np.float64]:
        """A^-1 (3, 3) of three wheels, the right inverse A^T (A A^T)^-1 (N, 3) of more: the wheel accelerations of a
        body-axis vector, the smallest (2-norm) where there are many (A^-1 tau / D: the wheels whose torque is tau;
        A^-1 H / D: the speeds that hold the momentum H at rest)."""
        A = self.wheel_axes
        if self.n_wheels == 3:
            return np.linalg.inv(A)
        return A.T @ np.linalg.inv(A @ A.T)

    @property
    def wheel_rate_reach(self) -> float:
        """max_i |a_i|_1: the most |a_i . omega| can be for |omega_j| <= 1 (1 with the wheels on the body axes)."""
        return max(sum(abs(v) for v in a) for a in self.wheel_axes_body)

    @property
    def wheel_failed(self) -> NDArray[np.bool_]:
        """Each wheel's drive failed (`failed_wheels`), in wheel order (N,)."""
        return np.array([name in self.failed_wheels for name in self.wheel_names])

    @property
    def control_lost(self) -> str:
        """'' while the working wheels span the body's axes; else one line saying what the failed wheels take away."""
        if not self.failed_wheels or spanning(self.wheel_axes[:, ~self.wheel_failed]) >= WHEEL_CONDITION_MIN:
            return ""
        left = self.n_wheels - len(self.failed_wheels)
        return (f"lost 3-axis control: {', '.join(self.failed_wheels)} failed, {left} wheel{'s' if left != 1 else ''} "
                "left")

    @property
    def wheels_on_body_axes(self) -> bool:
        """Wheel i spins about body axis i (A = I, the paper's)."""
        return self.wheel_axes_body == BODY_AXES

    @property
    def diagonal(self) -> bool:
        """Principal axes and the wheels on them: G is diagonal, and every kernel runs the paper's per-axis
        arithmetic (else the general one)."""
        return self.principal and self.wheels_on_body_axes

    @property
    def inertia_matrix(self) -> NDArray[np.float64]:
        """The inertia tensor (3, 3) in body axes, kg m^2."""
        return inertia_matrix(self.inertia_kgm2, self.products_of_inertia_kgm2)

    @property
    def inertia_inverse(self) -> NDArray[np.float64]:
        """J^-1 (3, 3), 1/(kg m^2)."""
        return np.linalg.inv(self.inertia_matrix)

    @property
    def principal_moments(self) -> NDArray[np.float64]:
        """The tensor's eigenvalues (3,), kg m^2: the diagonal itself where `principal`."""
        return self.J if self.principal else principal_moments(self.inertia_matrix)

    @property
    def control_gain(self) -> NDArray[np.float64]:
        """d omega_dot_i / d u_i = sign D / J_i (3,), 1/s^2 per rad/s^2, where `diagonal`."""
        return self.torque_sign * self.wheel_inertia_kgm2 / self.J

    @property
    def control_matrix(self) -> NDArray[np.float64]:
        """G = d omega_dot / d u = sign D J^-1 A (3, 3), 1/s^2 per rad/s^2 (diag(control_gain) where `diagonal`)."""
        if self.diagonal:
            return np.diag(self.control_gain)
        return self.torque_sign * self.wheel_inertia_kgm2 * (self.inertia_inverse @ self.wheel_axes)

    def control_times(self, v: NDArray[np.float64]) -> NDArray[np.float64]:
        """G v (3,): the body's angular acceleration of wheel accelerations v, rad/s^2."""
        return self.control_gain * v if self.diagonal else self.control_matrix @ v


@dataclass(frozen=True)
class PlantOptions:
    """Which simulator integrates the spacecraft (simulate, the Monte Carlo, the plant node); the
    filter's own model is `spacecraft.model` whatever this says."""

    simulator: str = "compiled"
    """SIMULATORS: `compiled` or `basilisk` (needs `pip install rta_attitude[basilisk]`)."""
    inertia_kgm2: tuple[float, float, float] | None = None
    """The simulated vehicle's principal moments where they differ from the filter's model
    (`spacecraft.inertia_kgm2`, in the same reading: docs/conventions.md), kg m^2; None: the model's. To test
    the filter against a vehicle it does not know exactly (`spacecraft.inertia_uncertainty`)."""

    def __post_init__(self) -> None:
        _choice("plant.simulator", self.simulator, SIMULATORS)
        for i, j in enumerate(self.inertia_kgm2 or ()):
            _positive(f"plant.inertia_kgm2[{i}]", j)
        if self.simulator == "basilisk" and importlib.util.find_spec("Basilisk") is None:
            raise ConfigError(BASILISK_MISSING)


@dataclass(frozen=True)
class Sensors:
    """Noise and bias on what the plant publishes, torque noise and lag on what it applies
    (`dynamics.sensors`, docs/noise.md); all 1 sigma, model units. Off: the exact state and command."""

    enabled: bool = False
    seed: int = 1
    attitude_noise_rad: float = 0.0
    """Per axis, a small body-frame rotation (star tracker)."""
    gyro_noise_rad_s: float = 0.0
    """White noise on each rate sample."""
    gyro_bias_rad_s: float = 0.0
    """Initial gyro bias per axis."""
    gyro_bias_walk_rad_s_sqrt_s: float = 0.0
    """Random walk of the gyro bias."""
    wheel_speed_noise_rad_s: float = 0.0
    temperature_noise_K: float = 0.0
    energy_noise_J: float = 0.0
    torque_noise_rad_s2: float = 0.0
    """On each held wheel acceleration (torque / D)."""
    actuator_lag_s: float = 0.0
    """Time constant of the wheels' first-order lag; 0: none."""
    bound_sigma: float = 4.0
    """The filter's error bounds (measurement-robust margins) are bound_sigma standard deviations."""
    bias_horizon_s: float = 2000.0
    """The gyro bias bound covers its random walk over this long."""

    def __post_init__(self) -> None:
        if not (isinstance(self.seed, int) and 0 <= self.seed < 2**63):
            raise ConfigError(f"sensors.seed must be an integer in [0, 2^63), got {self.seed!r}")
        for name in ("attitude_noise_rad", "gyro_noise_rad_s", "gyro_bias_rad_s", "gyro_bias_walk_rad_s_sqrt_s",
                     "wheel_speed_noise_rad_s", "temperature_noise_K", "energy_noise_J", "torque_noise_rad_s2",
                     "actuator_lag_s", "bound_sigma", "bias_horizon_s"):
            _nonneg(f"sensors.{name}", getattr(self, name))


EARTH_RADIUS_M = 6_378_137.0
"""The Earth's equatorial radius (WGS-84), m: the shadow cylinder's radius."""
EARTH_MU_M3_S2 = 3.986004418e14
"""The Earth's gravitational parameter, m^3/s^2: the orbit's radius from its mean motion."""


@dataclass(frozen=True)
class Environment:
    """Orbit, sun and Earth radiation constants."""

    mean_motion_rad_s: float
    solar_constant_W_m2: float
    albedo_factor: float
    earth_temperature_K: float
    stefan_boltzmann_W_m2K4: float
    earth_view_factor: float
    rotating_hill: bool = False
    """The Hill frame turns at the mean motion (in the attitude kinematics); False: inertial, as the paper."""
    gravity_gradient: bool = False
    """Gravity-gradient torque of a circular orbit at the mean motion."""
    sun_beta_rad: float = 0.0
    """The sun's angle out of the orbit plane (the orbit's beta angle), rad: r_S = [cos beta cos theta_S,
    cos beta sin theta_S, sin beta] in Hill (`dynamics.environment`; 0 in the paper)."""
    eclipse: bool = False
    """The Earth's cylindrical shadow on the orbit (its radius from the mean motion, the sun from the beta angle):
    the panel charges nothing and the sun heats nothing there (`dynamics.environment.sunlit`); False: sunlight
    all orbit, as the paper."""

    @property
    def orbit_radius_m(self) -> float:
        """The circular orbit's radius from its mean motion, a = (mu / n^2)^(1/3), m."""
        return float((EARTH_MU_M3_S2 / (self.mean_motion_rad_s * self.mean_motion_rad_s)) ** (1.0 / 3.0))

    @property
    def shadow_sx(self) -> float:
        """The sun's radial component r_S . x_Hill below which the spacecraft is in the shadow
        (`dynamics.environment.sunlit`): -cos rho, sin rho = R_E / a; -inf with the eclipse off.

        The spacecraft sits at a x_Hill; it is in the cylinder behind the Earth where r_S . x_Hill < 0 and its
        distance from the Earth-sun line, a sqrt(1 - (r_S . x_Hill)^2), is below R_E: r_S . x_Hill < -cos rho."""
        if not self.eclipse:
            return -math.inf
        sin_rho = min(1.0, EARTH_RADIUS_M / self.orbit_radius_m)
        return -math.sqrt(1.0 - sin_rho * sin_rho)

    @property
    def eclipse_half_arc_rad(self) -> float:
        """Half the theta_S arc in the shadow, rad: r_S . x_Hill = cos beta cos theta_S < -cos rho within
        arccos(cos rho / cos beta) of theta_S = pi; 0 with the eclipse off or none at this beta (|beta| >= rho)."""
        if not self.eclipse:
            return 0.0
        c = -self.shadow_sx / math.cos(self.sun_beta_rad)
        return math.acos(c) if c < 1.0 else 0.0

    @property
    def eclipse_s(self) -> float:
        """The eclipse's length, s (0: none)."""
        return 2.0 * self.eclipse_half_arc_rad / self.mean_motion_rad_s

    @property
    def orbit_period_s(self) -> float:
        """2 pi / n, s."""
        return 2.0 * math.pi / self.mean_motion_rad_s

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sun_beta_rad) and abs(self.sun_beta_rad) <= math.pi / 2):
            raise ConfigError(f"environment.sun_beta_deg must be in [-90, 90], got {math.degrees(self.sun_beta_rad)!r}")
        for name in ("mean_motion_rad_s", "solar_constant_W_m2", "earth_temperature_K",
                     "stefan_boltzmann_W_m2K4"):
            _positive(f"environment.{name}", getattr(self, name))
        for name in ("albedo_factor", "earth_view_factor"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ConfigError(f"environment.{name} must be in [0, 1], got {v!r}")


@dataclass(frozen=True)
class Thermal:
    """Lumped thermal node of the -j_B face (no conduction)."""

    mass_kg: float
    area_m2: float
    specific_heat_J_kgK: float
    absorptivity: float
    emissivity: float
    clamp_view_factor: bool = True
    face_normal_body: tuple[float, float, float] = (0.0, -1.0, 0.0)
    """The node's face, its outward normal in body axes (the paper's -j_B)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "face_normal_body", unit_vector("thermal.face_normal_body", self.face_normal_body))
        for name in ("mass_kg", "area_m2", "specific_heat_J_kgK"):
            _positive(f"thermal.{name}", getattr(self, name))
        for name in ("absorptivity", "emissivity"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ConfigError(f"thermal.{name} must be in [0, 1], got {v!r}")


@dataclass(frozen=True)
class Power:
    """Solar panel on +k_B and a constant load."""

    ideal_W_m2: float
    degradation: float
    panel_area_m2: float
    load_W: float
    bus_voltage_V: float = 8.0
    """Nominal bus voltage: the battery's energy E crosses the flight software's interface as
    sensor_msgs/BatteryState.charge = E / (V 3600) Ah, a float32 (`dynamics.sensors.encode`)."""
    panel_normal_body: tuple[float, float, float] = (0.0, 0.0, 1.0)
    """The solar panel's normal in body axes (the paper's +k_B)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "panel_normal_body", unit_vector("power.panel_normal_body", self.panel_normal_body))
        for name in ("ideal_W_m2", "panel_area_m2", "bus_voltage_V"):
            _positive(f"power.{name}", getattr(self, name))
        _nonneg("power.load_W", self.load_W)
        if not 0 < self.degradation <= 1:
            raise ConfigError(f"power.degradation must be in (0, 1], got {self.degradation!r}")

    @property
    def peak_W(self) -> float:
        """Panel power with the sun on its normal, W."""
        return self.ideal_W_m2 * self.degradation * self.panel_area_m2


@dataclass(frozen=True)
class Limits:
    """Safety limits, model units."""

    wheel_accel_max_rad_s2: float
    omega_dot_max_rad_s2: float
    omega_max_rad_s: float
    psi_max_rad_s: float
    temperature_max_K: float
    energy_min_J: float
    wheel_speed_relative_to_body: bool = False
    """True: psi_max bounds each rotor's speed relative to the body, |psi_i + omega_i| (a drive's limit: back-EMF,
    bearings); False: psi_i itself, the rotor's inertial rate about its axis (the paper's reading)."""

    def __post_init__(self) -> None:
        for name in ("wheel_accel_max_rad_s2", "omega_dot_max_rad_s2", "omega_max_rad_s",
                     "psi_max_rad_s", "temperature_max_K"):
            _positive(f"limits.{name}", getattr(self, name))
        _nonneg("limits.energy_min_J", self.energy_min_J)


@dataclass(frozen=True)
class BarrierGains:
    """Gains of one safety constraint's barrier condition."""

    enabled: bool = True
    k1: float = 0.1
    """First class-K gain (1/s): alpha_1(h) = k1 h."""
    k2: float = 0.0
    """Second class-K gain (1/s) for relative-degree-2 constraints (HOCBF); unused otherwise."""
    bias: float = 0.0
    """sigma, added to the final barrier condition."""
    slack_weight: float = 0.0
    """p > 0 makes the constraint soft, with cost p delta^2; 0 = hard."""
    margin: float | None = 0.0
    """Sampled-data allowance (units of h), `robust` preset only: the HOCBF keeps h >= margin, so
    that the overshoot of a zero-order-hold step stays on the safe side of h = 0 (the filter's model
    `paper`). None (a pointing constraint that sets none): derived from the vehicle
    (`constraints.margins`)."""
    margin_gyrostat: float | None = 0.0
    """The same allowance when the filter's model is the gyrostat (`filter.model: gyrostat`), whose
    gyroscopic torque changes during the hold (docs/decisions.md 2b); None: derived."""

    def sampled_data_margin(self, model: str) -> float | None:
        """The configured allowance for the filter's model ('paper' or 'gyrostat'); None: derive it
        (`constraints.margins.sampled_data_margin`)."""
        return self.margin_gyrostat if model == "gyrostat" else self.margin

    def check(self, where: str) -> None:
        """Raise ConfigError naming `where` if a gain is out of range."""
        _positive(f"{where}.k1", self.k1)
        _nonneg(f"{where}.k2", self.k2)
        _nonneg(f"{where}.slack_weight", self.slack_weight)
        for name in ("margin", "margin_gyrostat"):
            if getattr(self, name) is not None:
                _nonneg(f"{where}.{name}", getattr(self, name))
        if not math.isfinite(self.bias):
            raise ConfigError(f"{where}.bias must be finite, got {self.bias!r}")


BACKUP_SECONDARY_TARGETS: tuple[str, ...] = ("earth", "orbit_normal", "velocity")
"""What the backup attitude's secondary axis turns toward: directions fixed in Hill (`dynamics.environment`)."""


def body_axis(where: str, v: tuple[float, ...]) -> tuple[float, float, float]:
    """v (3,) as a signed body axis (+-x, +-y or +-z).

    Raises:
        ConfigError: anything else.
    """
    axes = [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
    out = tuple(float(a) for a in v)
    if len(out) != 3 or not any(out in (e, tuple(-a for a in e)) for e in axes):
        raise ConfigError(f"{where} must be a body axis ([1, 0, 0], [0, -1, 0], ...), got {list(v)}")
    return out[0] + 0.0, out[1] + 0.0, out[2] + 0.0  # (no -0.0)


def unit_vector(where: str, v: tuple[float, ...]) -> tuple[float, float, float]:
    """v (3,) as a unit vector: its norm must be within UNIT_TOLERANCE of 1 (the rounding of typed decimals);
    it is normalised (a configured unit vector is stored normalised).

    Raises:
        ConfigError: not 3 finite numbers, or a norm off 1 by more than UNIT_TOLERANCE.
    """
    if len(v) != 3 or not all(math.isfinite(a) for a in v):
        raise ConfigError(f"{where} must be 3 finite numbers, got {v!r}")
    n = math.sqrt(sum(a * a for a in v))
    if not abs(n - 1.0) <= UNIT_TOLERANCE:
        raise ConfigError(f"{where} must be a unit vector, got {list(v)} (norm {n:.6g})")
    return (v[0] / n, v[1] / n, v[2] / n) if n != 1.0 else (float(v[0]), float(v[1]), float(v[2]))


UNIT_TOLERANCE = 1e-3
"""How far from 1 the norm of a configured unit vector (a boresight, a target, an axis) may be: three typed
decimals (0.577, 0.577, 0.577 has norm 0.99933); it is then normalised."""


@dataclass(frozen=True)
class PointingConstraint:
    """A cone about a target that a body axis must stay outside (keep_out) or inside (keep_in).

    h = theta - half_angle (keep_out) or half_angle - theta (keep_in), theta = angle(boresight, target), rad,
    enforced as an HOCBF (`constraints.cones`). With windows, only within them (h is +inf outside), and the
    barrier tightens ahead of each window's start at `ramp_rad_s` (docs/windows.md)."""

    name: str
    kind: str
    """POINTING_KINDS."""
    boresight_body: tuple[float, float, float]
    """The body axis (unit vector, body frame)."""
    target: str
    """TARGET_NAMES."""
    half_angle_rad: float
    """The cone's half-angle (a keep-out's FOV/2 + buffer, as the paper builds it), rad, in (0, pi)."""
    gains: BarrierGains
    target_vector: tuple[float, float, float] | None = None
    """The fixed vector of target 'hill' or 'inertial' (unit); None for the named targets."""
    windows_s: tuple[tuple[float, float], ...] = ()
    """(start, end) times, s from the run's t = 0, increasing and apart; empty: always."""

    def __post_init__(self) -> None:
        where = f"constraints.pointing.{self.name}"
        if not (self.name and set(self.name) <= NAME_CHARACTERS and self.name[0].isalpha()):
            raise ConfigError(f"{where}: a constraint's name must be lower-case letters, digits and '_', starting "
                              f"with a letter, got {self.name!r}")
        if self.name in FIXED_NAMES or self.name in FIXED_GROUPS or group_of(self.name) != self.name:
            raise ConfigError(f"{where}: {self.name!r} is the name of another constraint; choose another name")
        _choice(f"{where}.kind", self.kind, POINTING_KINDS)
        _choice(f"{where}.target", self.target, TARGET_NAMES)
        object.__setattr__(self, "boresight_body", unit_vector(f"{where}.boresight_body", self.boresight_body))
        if self.target in ("hill", "inertial"):
            if self.target_vector is None:
                raise ConfigError(f"{where}.target_vector is missing (target {self.target!r} takes a unit vector)")
            object.__setattr__(self, "target_vector", unit_vector(f"{where}.target_vector", self.target_vector))
        elif self.target_vector is not None:
            raise ConfigError(f"{where}.target_vector is only for targets 'hill' and 'inertial', not {self.target!r}")
        if not (math.isfinite(self.half_angle_rad) and 0.0 < self.half_angle_rad < math.pi):
            raise ConfigError(f"{where}.half_angle_deg must be in (0, 180), got {math.degrees(self.half_angle_rad)!r}")
        self.gains.check(where)
        if self.gains.enabled:
            _positive(f"{where}.k2", self.gains.k2)
        if len(self.windows_s) > MAX_WINDOWS:
            raise ConfigError(f"{where}.windows_s holds {len(self.windows_s)} windows; at most {MAX_WINDOWS}")
        last = -math.inf
        for a, b in self.windows_s:
            if not (math.isfinite(a) and math.isfinite(b)):
                raise ConfigError(f"{where}.windows_s must be finite times, got [{a!r}, {b!r}]")
            if a < 0.0:
                raise ConfigError(f"{where}.windows_s: the window [{a:g}, {b:g}] s starts before t = 0")
            if not b > a:
                raise ConfigError(f"{where}.windows_s: the window [{a:g}, {b:g}] s must end after it starts")
            if not a > last:
                raise ConfigError(f"{where}.windows_s: the window [{a:g}, {b:g}] s overlaps or precedes the one "
                                  f"before it (windows are in time order and apart)")
            last = b

    @property
    def keep_in(self) -> bool:
        return self.kind == "keep_in"


@dataclass(frozen=True)
class Augmentation:
    """Angle terms that lower the relative degree of temperature and battery (SPEC sec. 4)."""

    delta0_K_rad: float = 1.0
    delta1_K_rad: float = 0.5
    delta2_J_rad: float = 1000.0

    def __post_init__(self) -> None:
        _nonneg("constraints.temperature.delta0_K_rad", self.delta0_K_rad)
        _nonneg("constraints.temperature.delta1_K_rad", self.delta1_K_rad)
        _nonneg("constraints.battery.delta2_J_rad", self.delta2_J_rad)


@dataclass(frozen=True)
class FilterOptions:
    """How the ASIF filter builds and solves its QP."""

    preset: str = "robust"
    sample_time_s: float = 1.0
    zoh_margin: float = 0.02
    fallback: str = "prioritize"
    max_iterations: int = 50
    max_inner_iterations: int = 20
    eps_abs: float = 1e-9
    eps_primal_inf: float = 1e-12
    eps_dual_inf: float = 1e-12
    check_tolerance: float = 1e-6
    pole_guard_rad: float = 1e-3
    soften_weight: float = 1e8
    backup_solver: str = "quadprog"
    solver: str = "active_set"
    model: str = "gyrostat"
    """The filter's model of the spacecraft in its barriers (PLANT_MODELS); the simulated plant is
    `spacecraft.model`."""
    backup_law: str = "none"
    """The gatekeeper's backup law (BACKUP_LAWS); none: no gatekeeper."""
    backup_horizon_s: float = 300.0
    """How far the gatekeeper simulates the backup law after the candidate's hold, s."""
    backup_nominal_s: float = 20.0
    """How long the gatekeeper's rollout follows the filter's own answers (u_des held) before the backup
    law, s (one sample: the candidate alone). A plan verified that way is applied, without a new rollout,
    at each later sample whose state and answer are the ones it predicted (docs/backup.md)."""
    backup_energy_lookahead_s: float = 6000.0
    """With a momentum too large for the sun-safe attitude (its plans hold for the horizon only), a plan is
    accepted only if at its end the battery could stay above E_min for this long more with the panel
    held where the wheels allow it nearest the sun (`filter.gatekeeper.rollout.energy_reserve`); 0: off. About one
    orbit (2 pi / n = 6,118 s): the sun's direction to the momentum repeats each orbit."""
    backup_horizon_at_rest: bool = False
    """With a momentum too large for the sun-safe attitude (plans that hold for the horizon only), accept a plan
    only if the spacecraft is at rest at its end (every body rate within the terminal set's): a plan that ends
    in the middle of the backup law's slew to a new target is safe to its last sample and no further. Measured
    on the first 1,000 runs of seed 7: the star-tracker example 95.0 % -> 98.0 % safe, the default 99.9 % ->
    99.7 %; so on where added cones move the backup law's target, off by default (docs/backup.md)."""
    actuator_lag: str = "compensate"
    """Robust preset with sensor errors on: how the filter treats the wheel drive's lag (ACTUATOR_LAGS)."""
    backup_sun_axis_body: tuple[float, float, float] = (0.0, 0.0, 1.0)
    """The body axis the backup attitude points at the sun (the panel, the paper's +k_B); a body axis (+-x, +-y,
    +-z): the backup law shares the wheels' momentum between the axes, where the wheels are."""
    backup_secondary_axis_body: tuple[float, float, float] = (0.0, 1.0, 0.0)
    """The body axis the backup attitude turns toward `backup_secondary_target` about the sun line (the paper's
    antenna +j_B); a body axis perpendicular to the sun axis."""
    backup_secondary_target: str = "earth"
    """BACKUP_SECONDARY_TARGETS: the direction the secondary axis turns toward (its part across the sun line)."""
    window_slew_fraction: float = 0.5
    """A scheduled window's barrier tightens at this fraction of the rate the vehicle can turn a boresight at
    ((1 - zoh_margin) omega_max less the target's motion), leaving the rest to the approach and the other
    constraints (`constraints.windows`)."""
    null_space_gain_1_s: float = 0.01
    """More than three wheels: the rate at which the null-space law (`filter.wheel_array`) drives the array's
    null-space speeds toward their bias, 1/s."""
    null_space_bias: float = 0.1
    """More than three wheels: the null-space law spins the wheels as far from zero speed as it can with none beyond
    this fraction of the speed the rows keep (`Config.psi_keep_rad_s`); 0: no law (`filter.wheel_array`)."""
    null_space_accel_fraction: float = 0.05
    """More than three wheels: the most the null-space law asks of any wheel, a fraction of its acceleration limit
    (the primary's command keeps the rest)."""
    priorities: tuple[tuple[str, ...], ...] = ()
    """Levels of constraint groups (`Config.groups`: the pointing constraints by name, temperature, battery,
    omega, psi), most important first: with `fallback: prioritize`, an infeasible QP is answered by letting the
    least important level give way first, by as little as possible (`filter.qp.prioritize`). Checked
    against the groups by `Config`; `Config.priority_levels` places the pointing constraints it leaves out."""

    def __post_init__(self) -> None:
        _choice("filter.model", self.model, PLANT_MODELS)
        _choice("filter.solver", self.solver, SOLVERS)
        _choice("filter.preset", self.preset, PRESETS)
        _choice("filter.backup_solver", self.backup_solver, BACKUP_SOLVERS)
        _choice("filter.fallback", self.fallback, FALLBACKS)
        _choice("filter.backup_law", self.backup_law, BACKUP_LAWS)
        _choice("filter.actuator_lag", self.actuator_lag, ACTUATOR_LAGS)
        sun = body_axis("filter.backup_sun_axis_body", self.backup_sun_axis_body)
        second = body_axis("filter.backup_secondary_axis_body", self.backup_secondary_axis_body)
        if sum(a * b for a, b in zip(sun, second)) != 0.0:  # (signed axes: 0 or +-1)
            raise ConfigError(f"filter.backup_secondary_axis_body must be perpendicular to backup_sun_axis_body "
                              f"{list(sun)}, got {list(second)}")
        _choice("filter.backup_secondary_target", self.backup_secondary_target, BACKUP_SECONDARY_TARGETS)
        if not (math.isfinite(self.window_slew_fraction) and 0.0 < self.window_slew_fraction <= 1.0):
            raise ConfigError(f"filter.window_slew_fraction must be in (0, 1], got {self.window_slew_fraction!r}")
        for name in ("null_space_gain_1_s", "null_space_bias", "null_space_accel_fraction"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0 <= v <= 1.0):
                raise ConfigError(f"filter.{name} must be in [0, 1], got {v!r}")
        _positive("filter.backup_horizon_s", self.backup_horizon_s)
        if not (math.isfinite(self.backup_energy_lookahead_s) and 0.0 <= self.backup_energy_lookahead_s <= 1e6):
            raise ConfigError(f"filter.backup_energy_lookahead_s must be between 0 (off) and 1e6 s, got "
                              f"{self.backup_energy_lookahead_s!r}")
        _positive("filter.sample_time_s", self.sample_time_s)
        nominal = self.backup_nominal_s / self.sample_time_s
        if not (math.isfinite(nominal) and 1 <= round(nominal) <= MAX_NOMINAL_STEPS):
            raise ConfigError(f"filter.backup_nominal_s must be between one sample ({self.sample_time_s:g} s) and "
                              f"{MAX_NOMINAL_STEPS} samples, got {self.backup_nominal_s!r}")
        if not 0 <= self.zoh_margin < 1:
            raise ConfigError(f"filter.zoh_margin must be in [0, 1), got {self.zoh_margin!r}")
        for name in ("max_iterations", "max_inner_iterations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 1 <= v <= 100_000):
                raise ConfigError(f"filter.{name} must be an integer in [1, 100000], got {v!r}")
        for name in ("eps_abs", "eps_primal_inf", "eps_dual_inf", "check_tolerance", "pole_guard_rad",
                     "soften_weight"):
            _positive(f"filter.{name}", getattr(self, name))


@dataclass(frozen=True)
class ControllerGains:
    """PD attitude law u_des = psi_dot_max tanh(-kp dq - kd omega)."""

    kp: float = 0.2
    kd: float = 1.5

    def __post_init__(self) -> None:
        _nonneg("controller.kp", self.kp)
        _nonneg("controller.kd", self.kd)


@dataclass(frozen=True)
class Scenario:
    """One named experiment: initial state, primary controller, command schedule, duration."""

    name: str
    description: str
    duration_s: float
    x0: NDArray[np.float64] = field(repr=False)
    """Initial state (19,), model units."""
    controller: str = "pd"
    schedule_s: tuple[float, ...] = (0.0,)
    """Start times of the rows of `schedule_q`, s, increasing, first 0."""
    schedule_q: tuple[tuple[float, float, float, float], ...] = ((0.0, 0.0, 0.0, 1.0),)
    """Commanded quaternions q_c, scalar last, unit norm."""
    slack_weights: tuple[tuple[str, float], ...] | None = None
    """If given, replaces every constraint's slack weight (others become hard)."""
    model: str | None = None
    """If given (PLANT_MODELS), the model of both the plant and the filter in this scenario (the paper's
    figures: `paper`)."""
    epoch_utc: str = DEFAULT_EPOCH_UTC
    """UTC date of t = 0: ROS time stamps (/clock, headers, bag times) are epoch + t."""
    backup_law: str | None = None
    """If given (BACKUP_LAWS), the gatekeeper's backup law in this scenario (the paper's figures: `none`,
    the paper's method has no gatekeeper)."""

    def __post_init__(self) -> None:
        where = f"scenarios.{self.name}"
        epoch_ns(f"{where}.epoch_utc", self.epoch_utc)
        if self.model is not None:
            _choice(f"{where}.model", self.model, PLANT_MODELS)
        if self.backup_law is not None:
            _choice(f"{where}.backup_law", self.backup_law, BACKUP_LAWS)
        _positive(f"{where}.duration_s", self.duration_s)
        _choice(f"{where}.controller", self.controller, CONTROLLERS)
        if self.schedule_s[0] != 0.0 or any(b <= a for a, b in zip(self.schedule_s, self.schedule_s[1:])):
            raise ConfigError(f"{where}.command_schedule times must start at 0 and increase, got {self.schedule_s}")
        if len(self.schedule_s) != len(self.schedule_q):
            raise ConfigError(f"{where}.command_schedule is malformed")
        for name, w in self.slack_weights or ():
            _nonneg(f"{where}.slack_weights.{name}", w)

    @property
    def epoch_ns(self) -> int:
        """t = 0 in ROS time [ns since 1970-01-01T00:00:00Z] (`epoch_utc`)."""
        return epoch_ns(f"scenarios.{self.name}.epoch_utc", self.epoch_utc)

    def command_at(self, t_s: float) -> NDArray[np.float64]:
        """The commanded quaternion q_c (4,) in force at time t_s (s)."""
        k = int(np.searchsorted(np.asarray(self.schedule_s), t_s, side="right")) - 1
        return np.array(self.schedule_q[max(k, 0)], dtype=float)


@dataclass(frozen=True)
class Config:
    """Every parameter of rta_attitude, validated; build with `rta_attitude.config.load`."""

    spacecraft: Spacecraft
    environment: Environment
    thermal: Thermal
    power: Power
    limits: Limits
    barriers: dict[str, BarrierGains]
    """Gains of the constraints that are not pointing cones, by group (FIXED_GROUPS); `gains(name)` reads any."""
    augmentation: Augmentation
    filter: FilterOptions
    controller: ControllerGains
    substeps: int
    scenarios: dict[str, Scenario]
    source: str = "<memory>"
    plant: PlantOptions = field(default_factory=PlantOptions)
    """The simulator of the spacecraft (`plant:` section; optional, default compiled)."""
    sensors: Sensors = field(default_factory=Sensors)
    """Sensor and actuator errors (`sensors:` section; optional, default off)."""
    pointing: tuple[PointingConstraint, ...] = ()
    """The pointing constraints (`constraints.pointing`), in order: the first rows of every table."""
    scenario_errors: dict[str, str] = field(default_factory=dict)
    """Scenarios of the file that did not validate: name -> the one-line error (`scenario` raises it)."""

    def __post_init__(self) -> None:
        if self.plant.simulator == "basilisk" and self.spacecraft.torque_sign != 1.0:
            raise ConfigError(f"plant.simulator basilisk needs spacecraft.torque_sign 1.0 (a wheel's reaction "
                              f"with psi = -Omega), got {self.spacecraft.torque_sign!r}")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ConfigError(f"integrator.substeps must be an integer >= 1, got {self.substeps!r}")
        if self.filter.backup_law != "none" and self.substeps > MAX_BACKUP_SUBSTEPS:
            raise ConfigError(f"integrator.substeps must be <= {MAX_BACKUP_SUBSTEPS} with filter.backup_law "
                              f"{self.filter.backup_law!r}, got {self.substeps!r}")
        self._check_delay()
        for group in FIXED_GROUPS:
            if group not in self.barriers:
                raise ConfigError(f"constraints.{group} is missing")
            self.barriers[group].check(f"constraints.{group}")
        for group in ("temperature", "battery"):
            if self.barriers[group].enabled:
                _positive(f"constraints.{group}.k2", self.barriers[group].k2)
        for group in PER_AXIS_GROUPS:
            if self.barriers[group].slack_weight:
                raise ConfigError(f"constraints.{group}.slack_weight must be 0 (hard), got "
                                  f"{self.barriers[group].slack_weight!r}")
        if len(self.pointing) > MAX_POINTING:
            raise ConfigError(f"constraints.pointing holds {len(self.pointing)} constraints; at most {MAX_POINTING}")
        names = [c.name for c in self.pointing]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ConfigError(f"constraints.pointing: {twice[0]!r} is named twice")
        if self.filter.priorities:
            named = [g for level in self.filter.priorities for g in level]
            for g in named:
                _choice("filter.priorities", g, self.groups)
            missing = [g for g in FIXED_GROUPS if g not in named]  # (a pointing constraint joins a level)
            twice = sorted({g for g in named if named.count(g) > 1})
            if missing or twice or not all(self.filter.priorities):
                why = (f"missing {', '.join(missing)}" if missing else f"{', '.join(twice)} twice" if twice
                       else "an empty level")
                raise ConfigError(f"filter.priorities must name every constraint group once, in non-empty levels "
                                  f"({why})")
        env = self.environment
        if env.eclipse_s > 0.0 and not self.power.peak_W > self.eclipse_power_W:
            raise ConfigError(
                f"environment.eclipse: the panel ({self.power.peak_W:.3g} W on the sun) cannot recharge the "
                f"{env.eclipse_s:.0f} s eclipse at power.load_W {self.power.load_W:.3g} W: it must give "
                f"{self.eclipse_power_W:.3g} W over the {env.orbit_period_s - env.eclipse_s:.0f} s of sunlight")
        for scenario in self.scenarios.values():
            for name, _ in scenario.slack_weights or ():
                _choice(f"scenarios.{scenario.name}.slack_weights", name, self.slackable)

    def _check_delay(self) -> None:
        """spacecraft.transport_delay_s: shorter than a sample, and a whole number of RK4 substeps (the plant
        switches commands at a substep's end, so the substep grid and its safety values stay where they are)."""
        delay, dt = self.spacecraft.transport_delay_s, self.filter.sample_time_s
        h = dt / self.substeps
        if delay >= dt:
            raise ConfigError(f"spacecraft.transport_delay_s must be shorter than filter.sample_time_s ({dt:g} s), "
                              f"got {delay:g}")
        if self.delay_substeps > MAX_BACKUP_SUBSTEPS:
            raise ConfigError(f"spacecraft.transport_delay_s must be at most {MAX_BACKUP_SUBSTEPS} RK4 substeps "
                              f"({MAX_BACKUP_SUBSTEPS * h:g} s here), got {delay:g}")
        if abs(self._delay_in_substeps - self.delay_substeps) > 1e-9:
            raise ConfigError(f"spacecraft.transport_delay_s must be a whole number of RK4 substeps "
                              f"(filter.sample_time_s / integrator.substeps = {h:g} s; raise integrator.substeps "
                              f"to refine it), got {delay:g}")

    @property
    def _delay_in_substeps(self) -> float:
        return self.spacecraft.transport_delay_s * self.substeps / self.filter.sample_time_s

    @property
    def delay_substeps(self) -> int:
        """The RK4 substeps of a sample the previous command still holds (`spacecraft.transport_delay_s`)."""
        return round(self._delay_in_substeps)

    @property
    def eclipse_energy_J(self) -> float:
        """What the load draws over the eclipse, J: the battery must hold it above E_min when the shadow begins."""
        return self.power.load_W * self.environment.eclipse_s

    @property
    def eclipse_ramp_W(self) -> float:
        """The rate at which the battery's floor rises over the sunlit arc, W: from E_min where the shadow ends to
        E_min + `eclipse_energy_J` where it begins (docs/eclipse.md). The panel must give the load plus this."""
        env = self.environment
        if env.eclipse_s <= 0.0:
            return 0.0
        return self.eclipse_energy_J / (env.orbit_period_s - env.eclipse_s)

    @property
    def eclipse_power_W(self) -> float:
        """What the panel must give where the battery is at its eclipse floor in sunlight, W: the load plus
        `eclipse_ramp_W` (the panel's peak must exceed it, or the configuration is refused)."""
        return self.power.load_W + self.eclipse_ramp_W

    @property
    def constraint_names(self) -> tuple[str, ...]:
        """Every safety constraint by name, in row order: the pointing constraints, then FIXED_NAMES but the wheels',
        one per configured wheel (`wheel_constraint_name`: the paper's psi_x, psi_y, psi_z)."""
        wheels = (wheel_constraint_name(w) for w in self.spacecraft.wheel_names)
        return (*(c.name for c in self.pointing), *FIXED_NAMES[:-3], *wheels)

    @property
    def groups(self) -> tuple[str, ...]:
        """The configured groups of constraints: the pointing constraints by name, then FIXED_GROUPS (`omega` and
        `psi` stand for their three axes)."""
        return (*(c.name for c in self.pointing), *FIXED_GROUPS)

    @property
    def slackable(self) -> tuple[str, ...]:
        """The constraints that may carry a slack: all but the per-axis rate and wheel-speed ones."""
        return (*(c.name for c in self.pointing), "temperature", "battery")

    def pointing_constraint(self, name: str) -> PointingConstraint:
        """A pointing constraint by name.

        Raises:
            ConfigError: no pointing constraint of that name.
        """
        for c in self.pointing:
            if c.name == name:
                return c
        raise ConfigError(f"unknown pointing constraint {name!r}; known: {', '.join(c.name for c in self.pointing)}")

    def gains(self, name: str) -> BarrierGains:
        """Gains of one constraint or group by name (e.g. 'omega_y' reads the `omega` group)."""
        group = group_of(name)
        if group in self.barriers:
            return self.barriers[group]
        for c in self.pointing:
            if c.name == name:
                return c.gains
        raise ConfigError(f"unknown constraint {name!r}; known: {', '.join(self.constraint_names)}")

    @property
    def priority_levels(self) -> tuple[tuple[str, ...], ...]:
        """The levels of the `prioritize` fallback, most important first: `filter.priorities`, where a pointing
        constraint it does not name joins its most important level if hard, its least important if slacked
        (so an overlay that adds a cone need not restate the list); without `filter.priorities`, two levels:
        the hard groups, then the slacked ones."""
        levels = [list(level) for level in self.filter.priorities]
        if not levels:
            levels = [[g for g in self.groups if not self.gains(g).slack_weight],
                      [g for g in self.groups if self.gains(g).slack_weight]]
        named = {g for level in levels for g in level}
        for c in self.pointing:
            if c.name not in named:
                levels[-1 if c.gains.slack_weight else 0].append(c.name)
        return tuple(tuple(level) for level in levels if level)
    @property
    def psi_keep_rad_s(self) -> float:
        """The wheel speed psi (the rotor's inertial rate) the filter's rows and the backup law keep within: psi_max,
        or with the limit relative to the body psi_max - omega_max max_i |a_i|_1 (|psi_i + a_i . omega| <= |psi_i|
        + omega_max |a_i|_1 while the rates are kept within omega_max on each axis; |a_i|_1 = 1 for a wheel on a
        body axis: docs/conventions.md)."""
        L = self.limits
        if not L.wheel_speed_relative_to_body:
            return L.psi_max_rad_s
        return L.psi_max_rad_s - L.omega_max_rad_s * self.spacecraft.wheel_rate_reach

    @property
    def accel_limit_rad_s2(self) -> NDArray[np.float64]:
        """b (3,), rad/s^2: how much angular acceleration u may add on each body axis, omega_dot_max less Euler's
        at the rate limits, b = omega_dot_max - |J^-1| e (e_j >= |(w x J w)_j| at |w_k| <= omega_max,
        `config.inertia.euler_bound`). Where not `diagonal`, the filter's QP keeps |(G u)_i| <= b_i as three rows
        (`filter.qp.assemble`): every wheel turns every axis, so a box on u cannot give every axis its
        authority at once."""
        sc, L = self.spacecraft, self.limits
        J, w = sc.inertia_matrix, L.omega_max_rad_s
        e = np.array([euler_bound(J, w, w, w, j) for j in range(3)])
        return L.omega_dot_max_rad_s2 - np.abs(sc.inertia_inverse) @ e

    @property
    def u_max_rad_s2(self) -> NDArray[np.float64]:
        """Bounds of the admissible set U (N,), rad/s^2: actuator and angular-acceleration limits.

        |u_i| <= min(psi_dot_max, (J_i omega_dot_max - |J_j - J_k| omega_max^2) / D) on principal axes with the
        wheels on them. Otherwise every wheel turns every axis: U is the polytope |(G u)_i| <= b_i
        (`accel_limit_rad_s2`, rows of the QP) within the actuator's box, and this is the box that bounds it,
        |u_j| <= min(psi_dot_max, sum_i |(G^-1)_ji| b_i) (what the wheel needs to give every axis its b_i); with
        more than three wheels the polytope reaches every wheel's own limit (along the null space), psi_dot_max.
        A failed wheel's bound is 0 (`Spacecraft.failed_wheels`).
        """
        sc, L = self.spacecraft, self.limits
        if sc.n_wheels > 3:  # every wheel direction but the body's is the null space: the rows bound the rest
            box = np.full(sc.n_wheels, L.wheel_accel_max_rad_s2)
        elif not sc.diagonal:
            reach = np.abs(np.linalg.inv(sc.control_matrix)) @ self.accel_limit_rad_s2
            box = np.minimum(L.wheel_accel_max_rad_s2, reach)
        else:
            J = sc.J
            dJ = np.abs(np.array([J[1] - J[2], J[2] - J[0], J[0] - J[1]]))
            accel = (J * L.omega_dot_max_rad_s2 - dJ * L.omega_max_rad_s**2) / sc.wheel_inertia_kgm2
            box = np.minimum(L.wheel_accel_max_rad_s2, accel)
        return np.where(sc.wheel_failed, 0.0, box)

    @property
    def virtual_vehicle(self) -> Config:
        """The vehicle with three wheels on its body axes that moves as this one's array does (the same body; the
        wheels' momentum A psi on the body axes, their acceleration A u): its actuator bound is the most any body
        axis gets from the working wheels, max_a sum_i |A_ai| U_i, and it has no failed wheel. The filter over an
        array (`filter.wheel_array`) evaluates the body's constraints on it."""
        sc = self.spacecraft
        reach = np.abs(sc.wheel_axes) @ self.u_max_rad_s2
        return replace(self, spacecraft=replace(sc, wheel_axes_body=BODY_AXES, wheel_names=WHEEL_JOINTS,
                                                failed_wheels=()),
                       limits=replace(self.limits, wheel_accel_max_rad_s2=float(reach.max())))

    @property
    def body_model(self) -> Config:
        """What the body's constraints, angles and margins are computed on: this configuration with three wheels,
        its `virtual_vehicle` with more (their first 19 state entries then stand for the body)."""
        return self if self.spacecraft.n_wheels == 3 else self.virtual_vehicle

    @property
    def slacked_constraints(self) -> tuple[str, ...]:
        """Names of the enabled constraints that carry a slack (reported, not counted as failures)."""
        return tuple(n for n in self.slackable if self.gains(n).enabled and self.gains(n).slack_weight > 0)

    def with_preset(self, preset: str) -> Config:
        """A copy using another filter preset ('robust' or 'paper')."""
        return replace(self, filter=replace(self.filter, preset=preset))

    def with_solver(self, solver: str) -> Config:
        """A copy using another QP solver ('proxsuite' or 'active_set')."""
        return replace(self, filter=replace(self.filter, solver=solver))

    def with_backup(self, law: str | None, horizon_s: float | None = None) -> Config:
        """A copy with another gatekeeper backup law (BACKUP_LAWS) and horizon (None: keep the config's)."""
        o = self.filter
        return replace(self, filter=replace(o, backup_law=o.backup_law if law is None else law,
                                            backup_horizon_s=o.backup_horizon_s if horizon_s is None else horizon_s))

    def with_simulator(self, simulator: str) -> Config:
        """A copy whose spacecraft is integrated by another simulator ('compiled' or 'basilisk').

        Raises:
            ConfigError: unknown simulator, or basilisk without the optional extra.
        """
        return replace(self, plant=replace(self.plant, simulator=simulator))

    def with_noise(self, enabled: bool = True, seed: int | None = None) -> Config:
        """A copy with the `sensors:` errors on (or off), optionally with another seed."""
        sensors = replace(self.sensors, enabled=enabled)
        return replace(self, sensors=sensors if seed is None else replace(sensors, seed=seed))

    def with_fallback(self, fallback: str) -> Config:
        """A copy using another fallback policy."""
        return replace(self, filter=replace(self.filter, fallback=fallback))

    def with_models(self, plant: str | None = None, filter: str | None = None) -> Config:
        """A copy with another model (PLANT_MODELS) of the simulated plant and/or of the filter."""
        cfg = self
        if plant is not None:
            cfg = replace(cfg, spacecraft=replace(cfg.spacecraft, model=plant))
        if filter is not None:
            cfg = replace(cfg, filter=replace(cfg.filter, model=filter))
        return cfg

    def for_scenario(self, scenario: Scenario) -> Config:
        """A copy with the scenario's slack weights, model and backup law, where it names them."""
        cfg = self if scenario.model is None else self.with_models(scenario.model, scenario.model)
        if scenario.backup_law is not None:
            cfg = cfg.with_backup(scenario.backup_law)
        if scenario.slack_weights is None:
            return cfg
        return cfg.with_slack_weights(dict(scenario.slack_weights))

    def with_slack_weights(self, weights: dict[str, float]) -> Config:
        """A copy in which the constraints named in weights carry those slack weights and every other slackable
        constraint is hard."""
        barriers = dict(self.barriers)
        for group in ("temperature", "battery"):
            barriers[group] = replace(barriers[group], slack_weight=float(weights.get(group, 0.0)))
        pointing = tuple(replace(c, gains=replace(c.gains, slack_weight=float(weights.get(c.name, 0.0))))
                         for c in self.pointing)
        return replace(self, barriers=barriers, pointing=pointing)

    def scenario(self, name: str) -> Scenario:
        """A scenario by name; '-' and '_' are interchangeable."""
        key = name.replace("-", "_")
        if key in self.scenario_errors:
            raise ConfigError(self.scenario_errors[key])
        if key not in self.scenarios:
            known = ", ".join(s.replace("_", "-") for s in self.scenarios)
            raise ConfigError(f"unknown scenario {name!r}; known: {known}")
        return self.scenarios[key]
