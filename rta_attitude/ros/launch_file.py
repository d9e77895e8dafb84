"""The logic of launch/rta_attitude.launch.py, importable (and tested) without ros2launch installed.

    ros2 launch rta_attitude rta_attitude.launch.py scenario:=paper_example bag:=/tmp/run.mcap

Two jobs, each a plain function or class the launch file calls:

- `validate(values)`: every launch argument checked before any node starts (choices for enums and
  booleans, numbers parsed and ranged, the parameter file loaded and the scenario found in it, the bag
  path writable and not silently reused). A bad argument raises ConfigError with one line naming it;
  the launch file lets it propagate, so `ros2 launch` prints it once ("Caught exception in launch")
  and exits 1 with no process started. An empty `bag` gets a rosbag2-style unique, time-stamped name.
- `RunEnd`: the event wiring. The launch file reports every node's exit to it; it answers whether the
  run goes on, ended normally (the plant exited 0 and, when recording, the recorder has closed the
  bag), or failed (a node exited with a non-zero code, or a node other than the plant and recorder
  ended before the run did). On an end the launch file emits Shutdown (the other nodes get SIGINT
  and stop cleanly, exit code 0); on a failure it raises, which makes `ros2 launch` shut everything
  down and exit 1. Exits after the end has been decided are the shutdown's own and are ignored, and
  so are exits after a shutdown the user asked for (Ctrl-C: the launch file checks the context).

Every node gets `sigterm_timeout` = SIGTERM_TIMEOUT_S: on SIGINT a node waits up to stop_timeout_s +
2 s for its readers to acknowledge what it published, which raced launch's default 5 s and printed
"failed to terminate '5' seconds after receiving 'SIGINT', escalating to 'SIGTERM'" on Ctrl-C. Every node
also gets `exit_with_parent` (NODE_PARAMETERS): stock launch leaves its processes running when it gets
SIGTERM (what `docker stop` sends), and with it each node stops cleanly when `ros2 launch` is gone.
"""

from __future__ import annotations

import datetime as dt
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rta_attitude import topics
from rta_attitude.errors import ConfigError
from rta_attitude.recording.bag import default_bag_name

TRUE_FALSE = ("true", "false")
CONTROLLERS = ("pd", "none")
"""`controller:=`: the paper's PD controller node, or none (a node of the user's publishes torque_des)."""
STEPPING = ("lockstep", "realtime")
DISCOVERY = ("LOCALHOST", "SUBNET", "OFF")
MAX_DOMAIN_ID = 232
"""Largest ROS_DOMAIN_ID (ROS 2's documented range is 0-232; 0-101 is safe on every Linux)."""
SIGTERM_TIMEOUT_S = 15.0
"""How long launch waits after SIGINT before it escalates to SIGTERM: longer than a node's own bound on
its stop (stop_timeout_s 3 s + spin.STOP_MARGIN_S 2 s, plus interpreter teardown)."""
NAMESPACE = re.compile(r"/|(/[A-Za-z_][A-Za-z0-9_]*)+")
"""An absolute ROS namespace (ROS 2 name rules)."""


@dataclass(frozen=True)
class LaunchArgument:
    """One `name:=value` argument of the launch file."""

    name: str
    default: str
    description: str
    choices: tuple[str, ...] = ()
    kind: str = "text"  # text | bool | float | int | file


ARGUMENTS: tuple[LaunchArgument, ...] = (
    LaunchArgument("namespace", topics.DEFAULT_NAMESPACE, "namespace of every node and topic (except /clock)"),
    LaunchArgument("params_file", "", "the parameter YAML, the one the core reads (default: the package's)",
                   kind="file"),
    LaunchArgument("scenario", "paper_example", "scenario name in params_file"),
    LaunchArgument("rta", "true", "false: the filter node passes torque_des through", TRUE_FALSE, "bool"),
    LaunchArgument("controller", "pd", "pd: start pd_controller_node; none: no controller node, the plant waits "
                   "for a node of yours that publishes torque_des on the namespace and reads the state", CONTROLLERS),
    LaunchArgument("record", "true", "start bag_recorder_node (writers wait for its subscriptions)", TRUE_FALSE,
                   "bool"),
    LaunchArgument("bag", "", "MCAP file the recorder writes (default: rta_attitude_YYYY_MM_DD-HH_MM_SS.mcap "
                   "in the working directory)"),
    LaunchArgument("bag_overwrite", "false", "replace an existing bag file", TRUE_FALSE, "bool"),
    LaunchArgument("scene", "true", "start scene_node (3D view: scene/transform, scene/markers; off the control path)",
                   TRUE_FALSE, "bool"),
    LaunchArgument("stepping", "lockstep", "lockstep or realtime", STEPPING),
    LaunchArgument("real_time_factor", "1.0", "realtime stepping: sim seconds per wall second (> 0)", kind="float"),
    LaunchArgument("domain_id", "", f"ROS_DOMAIN_ID of the nodes, 0-{MAX_DOMAIN_ID} (default: $ROS_DOMAIN_ID, "
                   "else 0)", kind="int"),
    LaunchArgument("discovery_range", "LOCALHOST", "ROS_AUTOMATIC_DISCOVERY_RANGE of the nodes", DISCOVERY),
)  # fmt: skip
"""Every argument, in the order `ros2 launch ... --show-args` lists them."""

_BY_NAME = {a.name: a for a in ARGUMENTS}
NODE_PARAMETERS: dict[str, bool] = {"exit_with_parent": True}
"""Knobs the launch file gives every node it starts."""


def node_roles(values: dict[str, Any]) -> list[str]:
    """The roles the launch file starts for validated arguments (`validate`), readers first: the recorder
    (record:=true), the scene as a process of its own (scene:=true without a recorder, which would host it),
    the filter, the controller (controller:=pd), the plant."""
    roles = [topics.RECORDER] if values["record"] else []
    if values["scene"] and not values["record"]:
        roles.append(topics.SCENE)
    roles.append(topics.FILTER)
    if values["controller"] == "pd":
        roles.append(topics.CONTROLLER)
    return [*roles, topics.PLANT]


def _bad(name: str, value: str, what: str) -> ConfigError:
    return ConfigError(f"launch argument {name}:={value!r}: {what}")


def validate(values: Mapping[str, str], default_params: str | os.PathLike[str] | None = None,
             cwd: Path | None = None, now: dt.datetime | None = None) -> dict[str, Any]:
    """Check every launch argument; return them typed (bools, floats, ints, paths).

    Args:
        values: the launch configurations, `name -> text` (missing names take their defaults).
        default_params: the package's parameter file, used when `params_file` is empty.
        cwd: where a relative or default bag goes (default: the working directory).
        now: the time stamp of a default bag name.

    Raises:
        ConfigError: one line naming the first bad argument.
    """
    from rta_attitude import config

    unknown = sorted(set(values) - set(_BY_NAME))
    if unknown:
        raise ConfigError(f"unknown launch argument {unknown[0]} (arguments: {', '.join(_BY_NAME)})")
    text = {a.name: str(values.get(a.name, a.default)).strip() for a in ARGUMENTS}
    out: dict[str, Any] = {}
    for a in ARGUMENTS:
        v = text[a.name]
        if a.choices:
            choice = v.upper() if a.choices == DISCOVERY else v.lower()
            if choice not in a.choices:
                raise _bad(a.name, v, f"must be one of {', '.join(a.choices)}")
            out[a.name] = choice == "true" if a.kind == "bool" else choice
        elif a.kind == "float":
            try:
                out[a.name] = float(v)
            except ValueError:
                raise _bad(a.name, v, "must be a number") from None
            if not out[a.name] > 0 or out[a.name] == float("inf"):
                raise _bad(a.name, v, "must be a finite number > 0")
        elif a.kind == "int":
            v = v or os.environ.get("ROS_DOMAIN_ID", "") or "0"
            if not v.isdigit() or int(v) > MAX_DOMAIN_ID:
                raise _bad(a.name, v, f"must be an integer 0-{MAX_DOMAIN_ID}")
            out[a.name] = int(v)
        else:
            out[a.name] = v
    ns = out["namespace"]
    if not NAMESPACE.fullmatch(ns):
        raise _bad("namespace", ns, "must be an absolute ROS name such as /rta or /sat1")
    params = Path(out["params_file"] or (default_params or config.default_config_path()))
    if not params.is_file():
        raise _bad("params_file", str(params), "no such file")
    try:
        cfg = config.load(params)
    except ConfigError as exc:
        raise _bad("params_file", str(params), str(exc)) from None
    out["params_file"] = str(params)
    out["scenario"] = cfg.scenario(out["scenario"]).name  # ConfigError names the scenarios there are
    if out["record"]:
        base = cwd or Path.cwd()
        bag = Path(out["bag"]) if out["bag"] else Path(default_bag_name(now))
        bag = bag if bag.is_absolute() else base / bag
        if bag.is_dir():
            raise _bad("bag", str(bag), "is a directory (name the .mcap file)")
        if bag.exists() and not out["bag_overwrite"]:
            raise _bad("bag", str(bag), "exists (pass bag_overwrite:=true to replace it)")
        if not bag.parent.is_dir():
            raise _bad("bag", str(bag), f"directory {bag.parent} does not exist")
        if not os.access(bag.parent, os.W_OK):
            raise _bad("bag", str(bag), f"directory {bag.parent} is not writable")
        out["bag"] = str(bag)
    return out


class RunEnd:
    """Decides, from the nodes' exits, when a launched run is over and whether it failed.

    `exited(node, code)` returns ("running", ""), ("done", reason) or ("failed", reason); after the
    first "done" or "failed" every later exit is ("ignored", ...): those are the shutdown's own.
    """

    def __init__(self, record: bool) -> None:
        self.record = record
        self.exits: dict[str, int] = {}
        self.decided: tuple[str, str] | None = None

    def _decide(self, node: str, code: int) -> tuple[str, str]:
        plant, recorder = topics.EXECUTABLES[topics.PLANT], topics.EXECUTABLES[topics.RECORDER]
        if code != 0:
            return "failed", f"{node} exited with code {code}"
        if node == plant:
            if self.record and recorder not in self.exits:
                return "running", ""  # the recorder closes the bag once every message is in
            return "done", "the plant finished the run" + (" and the recorder closed the bag" if self.record else "")
        if node == recorder:
            if plant in self.exits:  # the plant exited 0 before (a non-zero exit decided already)
                return "done", "the plant finished the run and the recorder closed the bag"
            return "running", ""  # the bag is closed after the final run_status: the plant's exit code decides
        if plant in self.exits:
            return "running", ""
        return "failed", f"{node} ended before the run did"

    def exited(self, node: str, code: int | None) -> tuple[str, str]:
        """Record one node's exit (code None: unknown, treated as a failure) and decide."""
        code = -1 if code is None else int(code)
        self.exits[node] = code
        if self.decided is not None:
            return "ignored", f"{node} exited with code {code} during shutdown"
        verdict = self._decide(node, code)
        if verdict[0] != "running":
            self.decided = verdict
        return verdict


__all__ = ["ARGUMENTS", "CONTROLLERS", "NODE_PARAMETERS", "SIGTERM_TIMEOUT_S", "LaunchArgument", "RunEnd", "node_roles",
           "validate"]
