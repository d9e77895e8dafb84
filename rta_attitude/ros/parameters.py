"""Node parameters: the core YAML's leaves as ROS parameters, plus the node-only knobs.

One source: every leaf under `ros__parameters` of the parameter file is a declared parameter,
named by its dotted path (`filter.preset`, `scenarios.paper_example.duration_s`). The node

1. declares its knobs (topics.KNOBS) and `config_file`;
2. declares every leaf of `config_file` (default: the installed rta_attitude.yaml) with the file's
   value as default; values from `--params-file` / `-p` override them as usual in ROS, and keys
   that only appear in overrides are declared from them too
   (`automatically_declare_parameters_from_overrides`);
3. rebuilds the nested mapping and validates it with `config.from_parameters`, the loader the CLI
   uses, so a wrong type or an unknown key fails the same way everywhere (ConfigError, one line).

Parameters are read once: each is declared read_only with a description (`ros2 param describe`), knobs
with their choices and range; a later `ros2 param set` is refused.
`flatten` and `nest` are ROS-free (the launcher uses them); `load` imports rclpy.
"""

from __future__ import annotations

import array
import math
import sys
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from rta_attitude import config
from rta_attitude.config.schema import Config
from rta_attitude.errors import ConfigError
from rta_attitude.topics import SYSTEM_PARAMETERS, Knob

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


def _declare(node: Node, name: str, value: Any, knob: Knob | None = None) -> None:
    from rclpy.exceptions import InvalidParameterValueException

    if node.has_parameter(name):  # declared from an override (no descriptor yet): declare it again, described
        if node.describe_parameter(name).read_only:
            return
        value = node.get_parameter(name).value
        node.undeclare_parameter(name)
    try:
        node.declare_parameter(name, value, descriptor(name, knob))
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


def load(node: Node, knobs: Sequence[Knob]) -> tuple[Config, dict[str, Any]]:
    """Declare and read a node's parameters.

    Args:
        node: created with `automatically_declare_parameters_from_overrides=True`.
        knobs: the node-only parameters it takes (topics.knobs_for(role)).

    Returns:
        (validated Config, {knob name: value}).

    Raises:
        ConfigError: missing or invalid parameter file, a wrong value, or an unknown key.
    """
    for knob in knobs:
        _declare(node, knob.name, knob.default, knob)
    values = {k.name: _knob_value(node, k) for k in knobs}
    file_params, path = config.read_parameters(values.get("config_file") or None)
    for name, value in flatten(file_params):
        _declare(node, name, value)
    skip = {k.name for k in knobs} | set(SYSTEM_PARAMETERS)
    declared = [n for n in node.list_parameters([], 0).names if n not in skip and not n.startswith("qos_overrides.")]
    flat = {p.name: _plain(p.value) for p in node.get_parameters(declared)}
    cfg = config.from_parameters(nest(flat), source=str(path))
    names = set(flat) | {k.name for k in knobs}

    from rcl_interfaces.msg import SetParametersResult

    def refuse(params: list[Parameter]) -> SetParametersResult:
        frozen = [p.name for p in params if p.name in names]
        if frozen:
            return SetParametersResult(successful=False,
                                       reason=f"{frozen[0]} is read at startup only; restart the node to change it")
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(refuse)
    return cfg, values


__all__ = ["check_knob", "descriptor", "flatten", "load", "nest"]
