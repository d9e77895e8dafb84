"""The ROS vocabulary in one place: node names, topics, their types and QoS, who publishes and who
subscribes, diagnostic keys and the node-only parameters ("knobs").

Pure Python: nothing here imports rclpy at module level, so the launcher and bag analysis can use
the names without starting ROS. `qos_profile` builds the rclpy profile lazily.

QoS policy (see docs/ros_interface.md):

- every topic the closed loop or the bag needs is RELIABLE + KEEP_ALL + VOLATILE: in lockstep a lost
  message stalls the loop, and the recorder must see every message (KEEP_ALL lets a slow reader push
  back on the writer instead of losing samples). Writers wait at startup until the expected readers
  are matched (`expected_readers`), so VOLATILE loses nothing;
- `run_status` is RELIABLE + TRANSIENT_LOCAL, keep_last 10: late joiners see the run's state;
- `attitude_command` is an operator input: RELIABLE + VOLATILE keep_last 10 on the reader, which
  accepts both volatile and transient-local (latched) reliable writers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

# ----------------------------------------------------------------------------- nodes

DEFAULT_NAMESPACE = "/rta"
"""Namespace of every node unless remapped (`--ros-args -r __ns:=/other`)."""
PACKAGE = "rta_attitude"
PLANT, CONTROLLER, FILTER, RECORDER = "plant", "controller", "filter", "recorder"
NODE_NAMES: dict[str, str] = {
    PLANT: "plant", CONTROLLER: "pd_controller", FILTER: "asif_filter", RECORDER: "bag_recorder",
}  # fmt: skip
"""ROS node name of each role."""
EXECUTABLES: dict[str, str] = {
    PLANT: "plant_node", CONTROLLER: "pd_controller_node", FILTER: "asif_filter_node",
    RECORDER: "bag_recorder_node",
}  # fmt: skip
"""Console scripts (`ros2 run rta_attitude <name>`) of each role."""
MODULES: dict[str, str] = {
    PLANT: "rta_attitude.nodes.plant_node", CONTROLLER: "rta_attitude.nodes.controller_node",
    FILTER: "rta_attitude.nodes.filter_node", RECORDER: "rta_attitude.nodes.recorder_node",
}  # fmt: skip
"""Python modules of each role (`python -m <module> --ros-args ...`)."""

BODY_FRAME = "body"
"""frame_id of body-frame vectors (torques) and Odometry.child_frame_id."""
HILL_FRAME = "hill"
"""frame_id of Hill-frame quantities (Odometry pose, sun vector)."""

# ----------------------------------------------------------------------------- QoS


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile as plain data (rclpy-free); depth is ignored for keep_all."""

    reliability: str = "reliable"
    durability: str = "volatile"
    history: str = "keep_all"
    depth: int = 0


STREAM_QOS = QosSpec()
"""Lockstep and recorded data: reliable, keep all, volatile."""
STATUS_QOS = QosSpec(durability="transient_local", history="keep_last", depth=10)
"""run_status: late joiners get the latest statuses."""
COMMAND_QOS = QosSpec(history="keep_last", depth=10)
"""attitude_command reader: reliable, volatile (accepts volatile and latched writers)."""


def qos_profile(spec: QosSpec) -> Any:
    """The rclpy QoSProfile of a QosSpec (imports rclpy)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    keep_all = spec.history == "keep_all"
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=max(spec.depth, 1),
        reliability=ReliabilityPolicy.RELIABLE if spec.reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE),
    )


# ----------------------------------------------------------------------------- topics


@dataclass(frozen=True)
class TopicSpec:
    """One topic of the run.

    Attributes:
        name: relative name (resolved under the node namespace) or absolute (`/clock`).
        type_name: `pkg/msg/Type`.
        qos: writer profile (readers use the same unless noted).
        publisher: role that publishes it ('' = external, e.g. an operator).
        readers: roles that subscribe, as (role, only_with_rta, only_without_rta) rules.
        content: one line for docs and `--help`.
    """

    name: str
    type_name: str
    qos: QosSpec
    publisher: str
    readers: tuple[tuple[str, bool, bool], ...]
    content: str


CLOCK = "/clock"
STATE = "state"
ATTITUDE_COMMAND = "attitude_command"
TORQUE_DES = "torque_des"
TORQUE_CMD = "torque_cmd"
FILTER_STATUS = "filter_status"
TORQUE_APPLIED = "torque_applied"
ODOMETRY = "odometry"
TEMPERATURE = "temperature"
BATTERY = "battery"
SUN_VECTOR = "sun_vector"
RUN_STATUS = "run_status"

_ALL = ((RECORDER, False, False),)
TOPICS: dict[str, TopicSpec] = {
    t.name: t
    for t in (
        TopicSpec(CLOCK, "rosgraph_msgs/msg/Clock", STREAM_QOS, PLANT, _ALL,
                  "simulation time t_k, one per step (nodes run with use_sim_time)"),
        TopicSpec(STATE, "sensor_msgs/msg/JointState", STREAM_QOS, PLANT,
                  ((CONTROLLER, False, False), (FILTER, True, False), *_ALL),
                  "the whole state: name = STATE_NAMES, position = values (model units), stamp = t_k"),
        TopicSpec(ATTITUDE_COMMAND, "geometry_msgs/msg/QuaternionStamped", COMMAND_QOS, "",
                  ((CONTROLLER, False, False), *_ALL),
                  "operator override of q_c (Hill -> body, x y z w), in force from its stamp on"),
        TopicSpec(TORQUE_DES, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, CONTROLLER,
                  ((FILTER, False, False), *_ALL),
                  "desired body torque D u_des [N m], frame body, stamp = the state it answers"),
        TopicSpec(TORQUE_CMD, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, FILTER,
                  ((PLANT, False, False), *_ALL),
                  "filtered body torque D u_act [N m] (without RTA: torque_des passed through), same stamp"),
        TopicSpec(FILTER_STATUS, "diagnostic_msgs/msg/DiagnosticArray", STREAM_QOS, FILTER, _ALL,
                  "per constraint h, Psi, BC, slack, intervening; QP status, fallback, solve time"),
        TopicSpec(TORQUE_APPLIED, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, PLANT, _ALL,
                  "torque the plant held over [t_k, t_k + dt) before saturation (ZOH, deadline fallback)"),
        TopicSpec(ODOMETRY, "nav_msgs/msg/Odometry", STREAM_QOS, PLANT, _ALL,
                  "inspection: attitude (body in Hill), body rates, CW position/velocity"),
        TopicSpec(TEMPERATURE, "sensor_msgs/msg/Temperature", STREAM_QOS, PLANT, _ALL,
                  "inspection: -j_B face temperature [degC]"),
        TopicSpec(BATTERY, "sensor_msgs/msg/BatteryState", STREAM_QOS, PLANT, _ALL,
                  "inspection: battery energy as charge [Ah] at the nominal voltage"),
        TopicSpec(SUN_VECTOR, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, PLANT, _ALL,
                  "inspection: unit vector to the sun, frame hill"),
        TopicSpec(RUN_STATUS, "diagnostic_msgs/msg/DiagnosticArray", STATUS_QOS, PLANT, _ALL,
                  "run state (running, done, failed), step counts, deadline misses, expected counts"),
    )
}  # fmt: skip
"""Every topic of a run, by (relative) name."""

INSPECTION_TOPICS: tuple[str, ...] = (ODOMETRY, TEMPERATURE, BATTERY, SUN_VECTOR)


def msg_class(type_name: str) -> Any:
    """The rclpy message class of `pkg/msg/Type` (imports the message package)."""
    import importlib

    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def subscribed(role: str, rta: bool) -> list[TopicSpec]:
    """Topics a role subscribes to in a run with/without RTA."""
    out = []
    for spec in TOPICS.values():
        for who, only_rta, only_plain in spec.readers:
            if who == role and not (only_rta and not rta) and not (only_plain and rta):
                out.append(spec)
    return out


def published(role: str, rta: bool) -> list[TopicSpec]:
    """Topics a role publishes (filter_status only with RTA: without, the filter passes through)."""
    return [t for t in TOPICS.values() if t.publisher == role and (rta or t.name != FILTER_STATUS)]


def recorded(rta: bool) -> list[TopicSpec]:
    """Topics the recorder writes to the bag: all of the run's (filter_status only with RTA)."""
    return [t for t in subscribed(RECORDER, rta) if rta or t.name != FILTER_STATUS]


def expected_readers(topic: str, rta: bool, record: bool) -> int:
    """How many of the run's own nodes subscribe to `topic`; a writer waits for this many matches
    before its first message (tools such as `ros2 topic echo` only add readers)."""
    n = 0
    for who, only_rta, only_plain in TOPICS[topic].readers:
        if (only_rta and not rta) or (only_plain and rta) or (who == RECORDER and not record):
            continue
        n += 1
    return n


# ----------------------------------------------------------------------------- diagnostics

STATUS_HARDWARE_ID = "rta_attitude"
QP_STATUS_NAME = "filter"
"""filter_status: the entry of the filter call (QP status, fallback, box, timing, counters); one entry
per constraint follows, named like the constraint (params.CONSTRAINT_NAMES). rta_attitude.analysis
reads this layout."""
CONSTRAINT_STATUS_PREFIX = ""
QP_KEYS: tuple[str, ...] = (
    "status", "solver_status", "iterations", "fallback", "solve_time_s", "preset",
    "u_des_x", "u_des_y", "u_des_z", "u_x", "u_y", "u_z", "box_active_x", "box_active_y", "box_active_z",
    "calls", "fast_path", "solved", "fallbacks", "solver_failures",
)  # fmt: skip
"""Keys of the `filter` entry: status ('pass', 'solved', 'fallback'), proxsuite status, iterations,
fallback policy applied ('none' if none), solve time [s], preset, u_des and u [rad/s^2], box flags,
and the filter's running counters."""
NO_FALLBACK = "none"
CONSTRAINT_KEYS: tuple[str, ...] = ("h", "psi0", "psi1", "bc", "slack", "intervening", "uncontrollable", "slacked")
"""Keys of each constraint entry (floats as repr, exact; flags 'true'/'false')."""

RUN_STATUS_NAME = "plant/run"
RUN_RUNNING, RUN_DONE, RUN_FAILED = "running", "done", "failed"
EXPECTED_PREFIX = "expected:"
"""run_status keys `expected:<topic>` give the final message count of a topic, when known."""

# ----------------------------------------------------------------------------- knobs


@dataclass(frozen=True)
class Knob:
    """A node-only parameter (not part of the core YAML)."""

    name: str
    default: Any
    roles: tuple[str, ...]
    description: str
    choices: tuple[str, ...] = ()


_EVERY = (PLANT, CONTROLLER, FILTER, RECORDER)
KNOBS: tuple[Knob, ...] = (
    Knob("config_file", "", _EVERY, "parameter file the nodes read their defaults from ('' = installed one)"),
    Knob("scenario", "paper_example", _EVERY, "scenario name from the parameter file"),
    Knob("rta", True, _EVERY, "true: the filter runs; false: the plant applies torque_des"),
    Knob("record", True, _EVERY, "a bag_recorder_node takes part (writers wait for its subscriptions)"),
    Knob("startup_timeout_s", 30.0, _EVERY, "wall time to wait for the run's readers to match [s]"),
    Knob("executor", "events", _EVERY, "events: rclpy's C++ EventsExecutor; single: SingleThreadedExecutor",
         ("events", "single")),
    Knob("stepping", "lockstep", (PLANT,), "lockstep (deterministic) or realtime (wall-clock timer)",
         ("lockstep", "realtime")),
    Knob("real_time_factor", 1.0, (PLANT,), "realtime: sim seconds per wall second"),
    Knob("deadline_fallback", "hold", (PLANT,),
         "realtime, no command for t_k at t_k+1: hold the last applied torque, or apply zero",
         ("hold", "zero")),
    Knob("step_timeout_s", 10.0, (PLANT,), "lockstep: wall time to wait for one command before failing [s]"),
    Knob("inspection_every", 1, (PLANT,), "publish the inspection topics every n-th step"),
    Knob("battery_voltage_V", 8.0, (PLANT,), "nominal bus voltage for BatteryState (display only) [V]"),
    Knob("exit_when_done", True, (PLANT, RECORDER), "exit after the run ends (plant) / the bag is closed"),
    Knob("bag_path", "", (RECORDER,), "MCAP file to write (required)"),
    Knob("bag_overwrite", False, (RECORDER,), "replace an existing bag file"),
    Knob("drain_timeout_s", 10.0, (RECORDER,), "after run_status done: longest wait for the last messages [s]"),
    Knob("drain_quiet_s", 0.3, (RECORDER,), "after done, topics without a known count: close after this quiet [s]"),
)  # fmt: skip
"""Node-only parameters; every other parameter comes from the core YAML."""
SYSTEM_PARAMETERS: tuple[str, ...] = ("use_sim_time", "start_type_description_service")
"""Parameters rclpy declares itself (never part of the core config)."""


def knobs_for(role: str) -> tuple[Knob, ...]:
    """The knobs a role declares."""
    return tuple(k for k in KNOBS if role in k.roles)


__all__ = [
    "ATTITUDE_COMMAND", "BATTERY", "BODY_FRAME", "CLOCK", "COMMAND_QOS", "CONSTRAINT_KEYS",
    "CONSTRAINT_STATUS_PREFIX", "CONTROLLER", "DEFAULT_NAMESPACE", "EXECUTABLES", "EXPECTED_PREFIX", "FILTER",
    "FILTER_STATUS", "HILL_FRAME", "INSPECTION_TOPICS", "KNOBS", "MODULES", "NODE_NAMES", "NO_FALLBACK", "ODOMETRY",
    "PACKAGE",
    "PLANT", "QP_KEYS", "QP_STATUS_NAME", "RECORDER", "RUN_DONE", "RUN_FAILED", "RUN_RUNNING", "RUN_STATUS",
    "RUN_STATUS_NAME", "STATE", "STATUS_HARDWARE_ID", "STATUS_QOS", "STREAM_QOS", "SUN_VECTOR", "SYSTEM_PARAMETERS",
    "TEMPERATURE", "TOPICS", "TORQUE_APPLIED", "TORQUE_CMD", "TORQUE_DES", "Knob", "QosSpec", "TopicSpec",
    "expected_readers", "knobs_for", "msg_class", "published", "qos_profile", "recorded", "subscribed",
]  # fmt: skip
