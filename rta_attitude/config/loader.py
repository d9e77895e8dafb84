"""The one loader: YAML file -> validated `Config`. deg -> rad and degC -> K happen here only.

The file is a ROS 2 parameters file (`/**: ros__parameters: {...}`), so the nodes read the same
file with `--ros-args --params-file`. Unknown keys, wrong types and out-of-range values raise
`ConfigError` with one line naming the key, the value and what is allowed.

Overlays. A user's file holds only what differs from the package's defaults (config/rta_attitude.yaml): it is
merged onto them (`merge`: mappings key by key, recursively, but a wheel array replaces the default's; a list or
a value replaces; a key set to null removes the default's entry, e.g. a pointing constraint) and the result is
validated as one. `-p KEY=VALUE` (`parse_overrides`, `apply_overrides`) sets one dotted key on top, as on the
nodes' command line.

Scenarios are checked one by one: an error in one names it and is raised when that scenario is used
(`Config.scenario`), so the others still run.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rta_attitude.config.schema import (
    BODY_AXES,
    DEFAULT_EPOCH_UTC,
    UNIT_TOLERANCE,
    Augmentation,
    BarrierGains,
    Config,
    ControllerGains,
    Environment,
    FilterOptions,
    Limits,
    PlantOptions,
    PointingConstraint,
    Power,
    Scenario,
    Sensors,
    Spacecraft,
    Thermal,
    unit_vector,
)
from rta_attitude.dynamics.state import make_state
from rta_attitude.errors import ConfigError
from rta_attitude.topics import WHEEL_JOINTS

CONFIG_FILE_NAME = "rta_attitude.yaml"
CELSIUS_OFFSET_K = 273.15
CONFIG_ENV = "RTA_ATTITUDE_CONFIG"


def default_config_path() -> Path:
    """Where the parameter file is: $RTA_ATTITUDE_CONFIG, else the package's (`package_config_path`).

    Raises:
        ConfigError: no parameter file found.
    """
    env = os.environ.get(CONFIG_ENV)
    if env:
        return Path(env)
    return package_config_path()


def package_config_path() -> Path:
    """The package's parameter file (the defaults every other file is merged onto): the source tree's, or the
    install's share/.

    Raises:
        ConfigError: no parameter file found.
    """
    candidates = [Path(__file__).resolve().parents[2] / "config" / CONFIG_FILE_NAME]
    prefixes = [*os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep), sys.prefix]
    candidates += [Path(p) / "share" / "rta_attitude" / "config" / CONFIG_FILE_NAME for p in prefixes if p]
    for path in candidates:
        if path.is_file():
            return path
    raise ConfigError(f"no {CONFIG_FILE_NAME} found (looked in {', '.join(map(str, candidates))}); "
                      f"set {CONFIG_ENV}")


def read_parameters(path: str | os.PathLike[str] | None = None) -> tuple[dict[str, Any], Path]:
    """The `ros__parameters` mapping of a parameter file merged onto the package's defaults (`merge`), and the
    file's path.

    Raises:
        ConfigError: missing file, unreadable YAML, or no `ros__parameters` section.
    """
    file = Path(path) if path is not None else default_config_path()
    params = _read_file(file)
    base = package_config_path()
    if file.resolve() != base.resolve():
        params = merge(_read_file(base), params)
    return params, file


WHOLE_SECTIONS = frozenset({"spacecraft.wheel_spin_axes_body"})
"""Sections an overlay replaces as a whole: a vehicle's wheel array is its own, not added to the paper's three."""


def merge(base: Mapping[str, Any], overlay: Mapping[str, Any], _path: str = "") -> dict[str, Any]:
    """overlay merged onto base: mappings key by key (recursively; a WHOLE_SECTIONS mapping replaces the base's);
    a list or a value replaces the base's; a key set to null (None) removes the base's entry."""
    out = dict(base)
    for key, value in overlay.items():
        path = f"{_path}{key}"
        if value is None:
            out.pop(key, None)
        elif isinstance(value, Mapping) and isinstance(out.get(key), Mapping) and path not in WHOLE_SECTIONS:
            out[key] = merge(out[key], value, path + ".")
        else:
            out[key] = value
    return out


def parse_overrides(items: Sequence[str], option: str = "-p") -> dict[str, Any]:
    """KEY=VALUE texts -> {dotted key: value}; the value is read as YAML (1.5, true, [1, 2], text).

    Raises:
        ConfigError: an item without '=' or a key, or a value that is not YAML.
    """
    import yaml

    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"{option} {item!r}: expected KEY=VALUE")
        try:
            out[key.strip()] = yaml.safe_load(text)
        except yaml.YAMLError:
            raise ConfigError(f"{option} {item!r}: value is not valid YAML") from None
    return out


def apply_overrides(params: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """params with each dotted key of overrides set ({'filter.preset': 'paper'}); the loader then checks that
    the key exists and the value is valid."""
    out = merge(params, {})
    for name, value in overrides.items():
        *parents, leaf = name.split(".")
        node = out
        for i, part in enumerate(parents):
            child = node.get(part)
            if child is None:
                child = {}
            elif not isinstance(child, Mapping):
                raise ConfigError(f"parameter {'.'.join(parents[: i + 1])} is a value, not a section (in {name})")
            node[part] = child = dict(child)
            node = child
        node[leaf] = value
    return out


def _read_file(file: Path) -> dict[str, Any]:
    """The `ros__parameters` mapping of one file."""
    import yaml

    if file.is_dir():
        raise ConfigError(f"config file {str(file)!r} is a directory, not a file")
    if not file.is_file():
        raise ConfigError(f"config file {str(file)!r} does not exist")
    try:
        text = file.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
        raise ConfigError(f"config file {str(file)!r} cannot be read ({reason})") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        where = f" at line {line + 1}" if line is not None else ""
        raise ConfigError(f"config file {str(file)!r} is not valid YAML{where}") from None
    if not isinstance(doc, dict) or len(doc) != 1:
        raise ConfigError(f"config file {str(file)!r} must hold one node key (e.g. '/**') with ros__parameters")
    (node_params,) = doc.values()
    if not isinstance(node_params, dict) or not isinstance(node_params.get("ros__parameters"), dict):
        raise ConfigError(f"config file {str(file)!r} has no ros__parameters mapping")
    return dict(node_params["ros__parameters"])


class _Section:
    """Typed access to one mapping; remembers which keys were read so leftovers are errors."""

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{where} must be a mapping, got {type(data).__name__}")
        self.data, self.where, self.used = data, where, set()

    def _get(self, key: str, default: Any) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _REQUIRED:
                raise ConfigError(f"{self.where}.{key} is missing")
            return default
        return self.data[key]

    def number(self, key: str, default: Any = None) -> float:
        value = self._get(key, _REQUIRED if default is None else default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{self.where}.{key} must be a finite number, got {value!r}")
        return float(value)

    def integer(self, key: str, default: Any = None) -> int:
        value = self._get(key, _REQUIRED if default is None else default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{self.where}.{key} must be an integer, got {value!r}")
        return value

    def flag(self, key: str, default: Any = None) -> bool:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, bool):
            raise ConfigError(f"{self.where}.{key} must be true or false, got {value!r}")
        return value

    def text(self, key: str, default: Any = None) -> str:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, str):
            raise ConfigError(f"{self.where}.{key} must be a string, got {value!r}")
        return value

    def vector(self, key: str, size: int | None = None, default: tuple[float, ...] | None = None) -> tuple[float, ...]:
        value = self._get(key, _REQUIRED if default is None else list(default))
        ok = isinstance(value, list) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        if not ok or (size is not None and len(value) != size):
            n = f"{size} " if size is not None else ""
            raise ConfigError(f"{self.where}.{key} must be a list of {n}finite numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def windows(self, key: str) -> tuple[tuple[float, float], ...]:
        """A flat list of [start, end] pairs (a ROS double array), s; missing: none."""
        if key not in self.data:
            self.used.add(key)
            return ()
        flat = self.vector(key)
        if len(flat) % 2:
            raise ConfigError(f"{self.where}.{key} must be [start, end] pairs of times (s), got {len(flat)} numbers")
        return tuple((flat[i], flat[i + 1]) for i in range(0, len(flat), 2))

    def levels(self, key: str, default: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, ...], ...]:
        """A list of strings, each one level of names separated by commas or spaces (a ROS string array)."""
        value = self._get(key, default)
        if value is default:
            return default
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise ConfigError(f"{self.where}.{key} must be a list of strings (one level each, names separated by "
                              f"commas), got {value!r}")
        return tuple(tuple(v.replace(",", " ").split()) for v in value)

    def names(self, key: str) -> tuple[str, ...]:
        """Names separated by commas or spaces in one string (a ROS string: '' is none), or a list of them;
        missing: none."""
        value = self._get(key, "")
        if isinstance(value, str):
            return tuple(value.replace(",", " ").split())
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise ConfigError(f"{self.where}.{key} must be names separated by commas, got {value!r}")
        return tuple(value)

    def section(self, key: str) -> _Section:
        return _Section(self._get(key, _REQUIRED), f"{self.where}.{key}")

    def done(self) -> None:
        extra = sorted(set(self.data) - self.used)
        if extra:
            raise ConfigError(f"{self.where}: unknown key {extra[0]!r} (value {self.data[extra[0]]!r}; "
                              f"known: {', '.join(sorted(self.used))})")


_REQUIRED = object()


def _barrier(s: _Section, second_order: bool, derive: bool = False) -> BarrierGains:
    """A barrier's gains; with derive (a pointing constraint), a margin not given is derived from the vehicle
    (None here: `constraints.margins`)."""
    absent = None if derive else 0.0
    margin = (s.number("margin") if "margin" in s.data else absent) if second_order else 0.0
    s.used.add("margin")
    gains = BarrierGains(
        enabled=s.flag("enabled", True),
        k1=s.number("k1"),
        k2=s.number("k2") if second_order else 0.0,
        bias=s.number("bias", 0.0),
        slack_weight=s.number("slack_weight", 0.0),
        margin=margin,
        margin_gyrostat=(s.number("margin_gyrostat") if "margin_gyrostat" in s.data else margin)  # the paper's
        if second_order else 0.0,
    )
    return gains


def _wheels(sc: _Section) -> tuple[tuple[str, ...], tuple[tuple[float, float, float], ...]]:
    """`spacecraft.wheel_spin_axes_body`: (names, unit spin axes), a vector per wheel keyed by its joint name, in
    the order written (the paper's three, `topics.WHEEL_JOINTS`, in theirs); missing: the paper's wheels."""
    sc.used.add("wheel_spin_axes_body")
    if "wheel_spin_axes_body" not in sc.data:
        return WHEEL_JOINTS, BODY_AXES
    ws = sc.section("wheel_spin_axes_body")
    names = WHEEL_JOINTS if set(ws.data) == set(WHEEL_JOINTS) else tuple(str(name) for name in ws.data)
    axes = tuple(unit_vector(f"{ws.where}.{name}", ws.vector(name, 3)) for name in names)
    ws.done()
    return names, axes  # type: ignore[return-value]


def _pointing(name: str, s: _Section) -> PointingConstraint:
    """One entry of `constraints.pointing` (degrees here, radians after)."""
    target = s.text("target")
    constraint = PointingConstraint(
        name=name,
        kind=s.text("kind"),
        boresight_body=s.vector("boresight_body", 3),  # type: ignore[arg-type]
        target=target,
        half_angle_rad=math.radians(s.number("half_angle_deg")),
        gains=_barrier(s, True, derive=True),
        target_vector=s.vector("target_vector", 3) if "target_vector" in s.data else None,  # type: ignore[arg-type]
        windows_s=s.windows("windows_s"),
    )
    s.done()
    return constraint


def _scenario(name: str, s: _Section) -> Scenario:
    q = np.array(s.vector("q", 4))
    if not abs(np.linalg.norm(q) - 1.0) <= UNIT_TOLERANCE:
        raise ConfigError(f"{s.where}.q must be a unit quaternion (norm within {UNIT_TOLERANCE:g} of 1: the "
                          f"rounding of typed decimals), got norm {np.linalg.norm(q):.6g}")
    x0 = make_state(
        q,
        np.radians(s.vector("omega_deg_s", 3)),
        s.vector("psi_rad_s", 3),
        T_K=s.number("temperature_degC") + CELSIUS_OFFSET_K,
        E_J=s.number("energy_J"),
        theta_S_rad=math.radians(s.number("theta_S_deg")),
    )
    flat = s.vector("command_schedule")
    if len(flat) == 0 or len(flat) % 5:
        raise ConfigError(f"{s.where}.command_schedule must be rows of 5 numbers [t_s, q1, q2, q3, q4], "
                          f"got {len(flat)} numbers")
    rows = np.array(flat).reshape(-1, 5)
    norms = np.linalg.norm(rows[:, 1:], axis=1)
    if np.any(np.abs(norms - 1.0) > UNIT_TOLERANCE):
        k = int(np.argmax(np.abs(norms - 1.0)))
        raise ConfigError(f"{s.where}.command_schedule: the quaternion of row {k} must be a unit quaternion (norm "
                          f"within {UNIT_TOLERANCE:g} of 1), got norm {norms[k]:.6g}")
    qs = rows[:, 1:] / norms[:, None]
    slack: tuple[tuple[str, float], ...] | None = None
    if "slack_weights" in s.data:
        sw = s.section("slack_weights")
        slack = tuple((k, sw.number(k)) for k in list(sw.data))
        sw.done()
    scenario = Scenario(
        name=name,
        description=s.text("description", ""),
        duration_s=s.number("duration_s"),
        x0=x0,
        controller=s.text("controller", "pd"),
        schedule_s=tuple(float(t) for t in rows[:, 0]),
        schedule_q=tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in qs),
        slack_weights=slack,
        model=s.text("model") if "model" in s.data else None,
        backup_law=s.text("backup_law") if "backup_law" in s.data else None,
        epoch_utc=s.text("epoch_utc", DEFAULT_EPOCH_UTC),
    )
    s.done()
    return scenario


def from_parameters(params: Mapping[str, Any], source: str = "<memory>") -> Config:
    """Build a Config from the `ros__parameters` mapping (nested dicts, file units).

    Raises:
        ConfigError: unknown key, wrong type, out-of-range value (one line naming which).
    """
    root = _Section(params, "parameters")
    sc = root.section("spacecraft")
    wheel_names, wheel_axes = _wheels(sc)
    spacecraft = Spacecraft(sc.vector("inertia_kgm2", 3), sc.number("wheel_inertia_kgm2"),  # type: ignore[arg-type]
                            sc.number("torque_sign", 1.0), sc.text("model", "gyrostat"),
                            sc.number("inertia_uncertainty", 0.0), sc.number("transport_delay_s", 0.0),
                            sc.vector("products_of_inertia_kgm2", 3, (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
                            wheel_axes, sc.names("failed_wheels"), wheel_names)
    sc.done()
    ev = root.section("environment")
    environment = Environment(
        ev.number("mean_motion_rad_s"), ev.number("solar_constant_W_m2"), ev.number("albedo_factor"),
        ev.number("earth_temperature_K"), ev.number("stefan_boltzmann_W_m2K4"), ev.number("earth_view_factor"),
        ev.flag("rotating_hill", False), ev.flag("gravity_gradient", False),
        math.radians(ev.number("sun_beta_deg", 0.0)), ev.flag("eclipse", False))
    ev.done()
    th = root.section("thermal")
    thermal = Thermal(th.number("mass_kg"), th.number("area_m2"), th.number("specific_heat_J_kgK"),
                      th.number("absorptivity"), th.number("emissivity"), th.flag("clamp_view_factor", True),
                      th.vector("face_normal_body", 3) if "face_normal_body" in th.data else (0.0, -1.0, 0.0))  # type: ignore[arg-type]
    th.used.add("face_normal_body")
    th.done()
    pw = root.section("power")
    power = Power(pw.number("ideal_W_m2"), pw.number("degradation"), pw.number("panel_area_m2"),
                  pw.number("load_W"), pw.number("bus_voltage_V", 8.0),
                  pw.vector("panel_normal_body", 3) if "panel_normal_body" in pw.data else (0.0, 0.0, 1.0))  # type: ignore[arg-type]
    pw.used.add("panel_normal_body")
    pw.done()
    li = root.section("limits")
    limits = Limits(
        wheel_accel_max_rad_s2=li.number("wheel_accel_max_rad_s2"),
        omega_dot_max_rad_s2=math.radians(li.number("omega_dot_max_deg_s2")),
        omega_max_rad_s=math.radians(li.number("omega_max_deg_s")),
        psi_max_rad_s=li.number("psi_max_rad_s"),
        temperature_max_K=li.number("temperature_max_degC") + CELSIUS_OFFSET_K,
        energy_min_J=li.number("energy_min_J"),
        wheel_speed_relative_to_body=li.flag("wheel_speed_relative_to_body", False),
    )
    li.done()
    co = root.section("constraints")
    barriers: dict[str, BarrierGains] = {}
    pointing: tuple[PointingConstraint, ...] = ()
    co.used.add("pointing")
    if "pointing" in co.data:  # optional: no pointing constraint without it
        pt = co.section("pointing")
        pointing = tuple(_pointing(str(name), pt.section(str(name))) for name in list(pt.data))
        pt.done()
    s = co.section("temperature")
    barriers["temperature"] = _barrier(s, True)
    d0, d1 = s.number("delta0_K_rad"), s.number("delta1_K_rad")
    s.done()
    s = co.section("battery")
    barriers["battery"] = _barrier(s, True)
    d2 = s.number("delta2_J_rad")
    s.done()
    for group in ("omega", "psi"):
        s = co.section(group)
        barriers[group] = _barrier(s, False)
        s.done()
    co.done()
    fi = root.section("filter")
    filter_options = FilterOptions(
        preset=fi.text("preset"), sample_time_s=fi.number("sample_time_s"), zoh_margin=fi.number("zoh_margin"),
        fallback=fi.text("fallback"), max_iterations=fi.integer("max_iterations"),
        max_inner_iterations=fi.integer("max_inner_iterations"), eps_abs=fi.number("eps_abs"),
        eps_primal_inf=fi.number("eps_primal_inf"), eps_dual_inf=fi.number("eps_dual_inf"),
        check_tolerance=fi.number("check_tolerance"), pole_guard_rad=fi.number("pole_guard_rad"),
        soften_weight=fi.number("soften_weight"), backup_solver=fi.text("backup_solver"),
        solver=fi.text("solver", "active_set"), model=fi.text("model", "gyrostat"),
        backup_law=fi.text("backup_law", "none"), backup_horizon_s=fi.number("backup_horizon_s", 300.0),
        backup_nominal_s=fi.number("backup_nominal_s", 20.0),
        backup_energy_lookahead_s=fi.number("backup_energy_lookahead_s", 6000.0),
        backup_horizon_at_rest=fi.flag("backup_horizon_at_rest", False),
        actuator_lag=fi.text("actuator_lag", "compensate"),
        window_slew_fraction=fi.number("window_slew_fraction", 0.5),
        null_space_gain_1_s=fi.number("null_space_gain_1_s", FilterOptions.null_space_gain_1_s),
        null_space_bias=fi.number("null_space_bias", FilterOptions.null_space_bias),
        null_space_accel_fraction=fi.number("null_space_accel_fraction", FilterOptions.null_space_accel_fraction),
        backup_sun_axis_body=fi.vector("backup_sun_axis_body", 3) if "backup_sun_axis_body" in fi.data
        else (0.0, 0.0, 1.0),  # type: ignore[arg-type]
        backup_secondary_axis_body=fi.vector("backup_secondary_axis_body", 3) if "backup_secondary_axis_body" in fi.data
        else (0.0, 1.0, 0.0),  # type: ignore[arg-type]
        backup_secondary_target=fi.text("backup_secondary_target", "earth"),
        priorities=fi.levels("priorities", ()))
    fi.used.update({"backup_sun_axis_body", "backup_secondary_axis_body"})
    fi.done()
    ct = root.section("controller")
    controller = ControllerGains(ct.number("kp"), ct.number("kd"))
    ct.done()
    it = root.section("integrator")
    substeps = it.integer("substeps")
    it.done()
    plant = PlantOptions()
    root.used.add("plant")
    if "plant" in root.data:  # optional section: the compiled simulator without it
        pl = root.section("plant")
        plant = PlantOptions(pl.text("simulator", "compiled"),
                             pl.vector("inertia_kgm2", 3) if "inertia_kgm2" in pl.data else None)  # type: ignore[arg-type]
        pl.used.add("inertia_kgm2")
        pl.done()
    sensors = Sensors()
    root.used.add("sensors")
    if "sensors" in root.data:  # optional section: exact measurements without it
        se = root.section("sensors")
        sensors = Sensors(
            enabled=se.flag("enabled", False), seed=se.integer("seed", 1),
            attitude_noise_rad=math.radians(se.number("attitude_noise_deg", 0.0)),
            gyro_noise_rad_s=math.radians(se.number("gyro_noise_deg_s", 0.0)),
            gyro_bias_rad_s=math.radians(se.number("gyro_bias_deg_s", 0.0)),
            gyro_bias_walk_rad_s_sqrt_s=math.radians(se.number("gyro_bias_walk_deg_s_sqrt_s", 0.0)),
            wheel_speed_noise_rad_s=se.number("wheel_speed_noise_rad_s", 0.0),
            temperature_noise_K=se.number("temperature_noise_K", 0.0), energy_noise_J=se.number("energy_noise_J", 0.0),
            torque_noise_rad_s2=se.number("torque_noise_rad_s2", 0.0), actuator_lag_s=se.number("actuator_lag_s", 0.0),
            bound_sigma=se.number("bound_sigma", 4.0), bias_horizon_s=se.number("bias_horizon_s", 2000.0))
        se.done()
    sn = root.section("scenarios")
    scenarios: dict[str, Scenario] = {}
    broken: dict[str, str] = {}
    for name in list(sn.data):
        try:
            scenarios[name] = _scenario(name, sn.section(name))
        except ConfigError as exc:  # this scenario only: the others still run (`Config.scenario` raises it)
            broken[name] = str(exc)
    sn.done()
    root.done()
    return Config(spacecraft, environment, thermal, power, limits, barriers, Augmentation(d0, d1, d2),
                  filter_options, controller, substeps, scenarios, source=source, plant=plant,
                  sensors=sensors, pointing=pointing, scenario_errors=broken)


def load(path: str | os.PathLike[str] | None = None, *, preset: str | None = None,
         overrides: Mapping[str, Any] | None = None) -> Config:
    """Load and validate the parameter file (default: `default_config_path()`), merged onto the package's
    defaults, with dotted-key overrides on top.

    Args:
        path: YAML parameter file (a whole file or an overlay); None for the default one.
        preset: override `filter.preset` ('robust' or 'paper').
        overrides: {dotted key: value} (`parse_overrides` of `-p KEY=VALUE`), in file units.

    Raises:
        ConfigError: the file is missing or any value is invalid.
    """
    params, file = read_parameters(path)
    if overrides:
        params = apply_overrides(params, overrides)
    cfg = from_parameters(params, source=str(file))
    return cfg.with_preset(preset) if preset is not None else cfg


__all__ = ["CONFIG_ENV", "apply_overrides", "default_config_path", "from_parameters", "load", "merge",
           "package_config_path", "parse_overrides", "read_parameters"]
