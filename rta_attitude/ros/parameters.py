"""Node parameters: the core YAML's leaves as ROS parameters, plus the node-only knobs.

One source: every leaf under `ros__parameters` of the parameter file is a parameter, named by its
dotted path (`filter.preset`, `scenarios.paper_example.duration_s`). The node

1. declares its knobs (topics.KNOBS, each role its own) and `config_file`;
2. reads `config_file` (default: the installed rta_attitude.yaml), lays every override it was given
   (`--params-file`, `-p`) over it, and validates the result with `config.from_parameters`, the loader
   the CLI uses, so a wrong type or an unknown key fails the same way everywhere (ConfigError, one line);
3. declares, of those core parameters, only the ones it uses (topics.config_sections: its sections and
   its own scenario), so `ros2 param list` shows what matters to that node.

Parameters are read once: each is declared read_only with a description (`ros2 param describe`), knobs
with their choices and range; a later `ros2 param set` is refused, except for the role's live
parameters (topics.LIVE_PARAMETERS: the controller's gains), which are validated with the whole
configuration and logged.
`flatten` and `nest` are ROS-free (the launcher uses them); `load` imports rclpy.
"""

from __future__ import annotations

import array
import math
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from rta_attitude import config, topics
from rta_attitude.config.schema import Config
from rta_attitude.errors import ConfigError
from rta_attitude.topics import KNOBS, SYSTEM_PARAMETERS, Knob

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.parameter import Parameter


def flatten(tree: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(dotted name, leaf value) of a nested mapping; lists are leaves."""
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            yield from flatten(value, name + ".")
        else:
            yield name, value


def nest(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Inverse of `flatten`: {'a.b': 1} -> {'a': {'b': 1}}.

    Raises:
        ConfigError: a name is both a leaf and a section.
    """
    out: dict[str, Any] = {}
    for name, value in flat.items():
        *parents, leaf = name.split(".")
        node = out
        for i, part in enumerate(parents):
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"parameter {'.'.join(parents[: i + 1])} is both a value and a section")
        if isinstance(node.get(leaf), dict):
            raise ConfigError(f"parameter {name} is both a value and a section")
        node[leaf] = value
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, (array.array, tuple)):
        return list(value)
    return value


def descriptor(name: str, knob: Knob | None = None) -> Any:
    """The ParameterDescriptor a node declares `name` with: a description, read_only (every parameter is
    read at start-up), and for a knob its choices (additional_constraints) and its range
    (FloatingPointRange / IntegerRange, inclusive as ROS ranges are; `check_knob` then also rejects a
    value equal to an exclusive bound)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    if knob is None:
        return ParameterDescriptor(
            description=f"core parameter {name} (config/rta_attitude.yaml; validated by rta_attitude.config)",
            read_only=True, dynamic_typing=True)
    d = ParameterDescriptor(description=knob.description, read_only=True, dynamic_typing=True,
                            additional_constraints=knob.allowed)
    kind = type(knob.default)
    if kind is float:
        top = knob.maximum if knob.maximum is not None else sys.float_info.max
        d.floating_point_range = [FloatingPointRange(from_value=float(knob.minimum), to_value=float(top), step=0.0)]
    elif kind is int:
        top = int(knob.maximum) if knob.maximum is not None else 2**62
        d.integer_range = [IntegerRange(from_value=int(knob.minimum), to_value=top, step=0)]
    return d


def _declare(node: Node, name: str, value: Any, knob: Knob | None = None, writable: bool = False) -> None:
    from rclpy.exceptions import InvalidParameterValueException

    if node.has_parameter(name):
        return
    d = descriptor(name, knob)
    if writable:
        d.read_only = False
        d.description += "; may be changed while the node runs (ros2 param set), validated and logged"
    try:
        node.declare_parameter(name, value, d)
    except InvalidParameterValueException:
        assert knob is not None  # only knobs have ranges
        given = getattr(node, "_parameter_overrides", {}).get(name)  # rclpy keeps the overrides there
        got = f", got {_plain(given.value)!r}" if given is not None else ""
        raise ConfigError(f"parameter {knob.name} must be {knob.allowed}{got}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"parameter {name}={value!r} cannot be a ROS parameter ({exc})") from None


def check_knob(knob: Knob, value: Any) -> Any:
    """A knob's value checked against its type, choices and range (ROS-free; the launcher uses it too).

    Returns:
        The value (an int where a float is expected becomes a float).

    Raises:
        ConfigError: one line naming the parameter, the value and what is allowed.
    """
    value = _plain(value)
    want = type(knob.default)
    if want is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    bad_type = not isinstance(value, want) or (want is int and isinstance(value, bool))
    bad_number = not bad_type and want in (int, float) and (
        not math.isfinite(value) or value < knob.minimum or (knob.positive and value <= knob.minimum)
        or (knob.maximum is not None and value >= knob.maximum))
    if bad_type or bad_number or (knob.choices and value not in knob.choices):
        raise ConfigError(f"parameter {knob.name} must be {knob.allowed}, got {value!r}")
    return value


def _knob_value(node: Node, knob: Knob) -> Any:
    return check_knob(knob, node.get_parameter(knob.name).value)


def _in_sections(name: str, sections: Sequence[str]) -> bool:
    return any(name == s or name.startswith(s + ".") for s in sections)


def load(node: Node, role: str,
         on_live: Callable[[Config, dict[str, Any]], None] | None = None) -> tuple[Config, dict[str, Any]]:
    """Declare and read a node's parameters.

    The configuration is built from the whole parameter file (`config_file`) and every override the node
    was given (`--params-file`, `-p`), validated by the core loader; of the core parameters only the
    role's (topics.config_sections) are declared, each read_only unless it is one of the role's
    topics.LIVE_PARAMETERS.

    Args:
        node: created with `automatically_declare_parameters_from_overrides=False`.
        role: topics.PLANT, CONTROLLER, FILTER or RECORDER: its knobs (topics.knobs_for), sections and
            live parameters.
        on_live: what the node does with an accepted live change (`ros2 param set` of a live parameter):
            called with the new Config and {name: value} after the value was validated with the whole
            configuration (a bad one is refused with the loader's one-line reason) and logged.

    Returns:
        (validated Config, {knob name: value}).

    Raises:
        ConfigError: missing or invalid parameter file, a wrong value, or an unknown key.
    """
    knobs = topics.knobs_for(role)
    live = topics.LIVE_PARAMETERS.get(role, ())
    for knob in knobs:
        _declare(node, knob.name, knob.default, knob)
    values = {k.name: _knob_value(node, k) for k in knobs}
    file_params, path = config.read_parameters(values.get("config_file") or None)
    every_knob = {k.name for k in KNOBS}
    overrides = {name: _plain(p.value) for name, p in getattr(node, "_parameter_overrides", {}).items()
                 if name not in every_knob and name not in SYSTEM_PARAMETERS and not name.startswith("qos_overrides.")}
    flat = dict(flatten(file_params))
    flat.update(overrides)
    cfg = config.from_parameters(nest(flat), source=str(path))  # an unknown key or a bad value fails here
    cfg.spacecraft.require_three_wheels(f"the {role} node")  # its messages carry three wheels
    sections = topics.config_sections(role, cfg.scenario(values["scenario"]).name)  # '-' or '_' as the loader reads it
    shown = [n for n in flat if _in_sections(n, sections)]
    for name in shown:
        _declare(node, name, flat[name], writable=name in live)
    frozen = set(shown) - set(live) | {k.name for k in knobs}

    from rcl_interfaces.msg import SetParametersResult

    def on_set(params: list[Parameter]) -> SetParametersResult:
        refused = [p.name for p in params if p.name in frozen]
        if refused:
            return SetParametersResult(successful=False,
                                       reason=f"{refused[0]} is read at startup only; restart the node to change it")
        changes = {p.name: _plain(p.value) for p in params if p.name in live}
        if not changes:
            return SetParametersResult(successful=True)
        candidate = {**flat, **changes}
        try:
            new_cfg = config.from_parameters(nest(candidate), source=str(path))
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        flat.update(changes)
        node.get_logger().info("parameters changed at run time: " + ", ".join(f"{k}={v!r}" for k, v in changes.items()))
        if on_live is not None:
            on_live(new_cfg, changes)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return cfg, values


def declared_names(role: str, scenario: str = "paper_example", path: str | None = None) -> list[str]:
    """The parameters a node of `role` declares when it runs `scenario` with the parameter file `path` (default:
    the package's) and no overrides, sorted: what `ros2 param list` lists for it. Its knobs (topics.knobs_for),
    the file's leaves in its sections (topics.config_sections) and rclpy's own (topics.SYSTEM_PARAMETERS),
    as `load` declares them. ROS-free."""
    file_params, source = config.read_parameters(path)
    flat = dict(flatten(file_params))
    key = config.from_parameters(file_params, source=str(source)).scenario(scenario).name
    sections = topics.config_sections(role, key)
    names = {k.name for k in topics.knobs_for(role)} | {n for n in flat if _in_sections(n, sections)}
    return sorted(names | set(SYSTEM_PARAMETERS))


COUNTED_ROLES: tuple[str, ...] = (topics.PLANT, topics.FILTER, topics.CONTROLLER, topics.RECORDER, topics.SCENE)


def counts_sentence(scenario: str = "paper_example") -> str:
    """The sentence of docs/ros_interface.md that states how many parameters each node declares with the
    package's parameter file (`declared_names`); a test checks that the doc has it and that running nodes
    list these parameters."""
    counts = [f"{len(declared_names(role, scenario))} on `{topics.NODE_NAMES[role]}`" for role in COUNTED_ROLES]
    listed = ", ".join(counts[:-1]) + f" and {counts[-1]}"
    return (f"With the package's parameter file and the scenario `{scenario}`, `ros2 param list` shows "
            f"{listed.replace(' on ', ' parameters on ', 1)} (rclpy's own `{'` and `'.join(SYSTEM_PARAMETERS)}` "
            "included).")


__all__ = ["COUNTED_ROLES", "check_knob", "counts_sentence", "declared_names", "descriptor", "flatten", "load",
           "nest"]
