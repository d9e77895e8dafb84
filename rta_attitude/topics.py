"""The ROS vocabulary in one place: node names, topics, their types and QoS, who publishes and who
subscribes, diagnostic keys and the node-only parameters ("knobs").

Pure Python, below every layer that uses it: the bag reader and analysis, the launcher and the ROS
nodes share these names without starting ROS. The rclpy objects built from them (QoS profiles,
message classes) are `rta_attitude.ros.interface`'s.

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
"""Namespace the launch file and `rta-attitude launch` give every node (`namespace:=`, `--namespace`). A node
takes its namespace from ROS only (`-r __ns:=/sat1`, the launch `namespace`; `/` when none is given)."""
PACKAGE = "rta_attitude"
PLANT, CONTROLLER, FILTER, RECORDER, SCENE = "plant", "controller", "filter", "recorder", "scene"
NODE_NAMES: dict[str, str] = {
    PLANT: "plant", CONTROLLER: "pd_controller", FILTER: "asif_filter", RECORDER: "bag_recorder",
    SCENE: "attitude_scene",
}  # fmt: skip
"""ROS node name of each role. The scene is a view, off the control path: no node of the loop waits for it."""
EXECUTABLES: dict[str, str] = {
    PLANT: "plant_node", CONTROLLER: "pd_controller_node", FILTER: "asif_filter_node",
    RECORDER: "bag_recorder_node", SCENE: "scene_node",
}  # fmt: skip
"""Console scripts (`ros2 run rta_attitude <name>`) of each role."""
MODULES: dict[str, str] = {
    PLANT: "rta_attitude.ros.plant_node", CONTROLLER: "rta_attitude.ros.controller_node",
    FILTER: "rta_attitude.ros.filter_node", RECORDER: "rta_attitude.ros.recorder_node",
    SCENE: "rta_attitude.ros.scene_node",
}  # fmt: skip
"""Python modules of each role (`python -m <module> --ros-args ...`)."""

BODY_FRAME = "body"
"""frame_id of body-frame vectors (torques) and Odometry.child_frame_id."""
HILL_FRAME = "hill"
"""frame_id of Hill-frame quantities (Odometry pose, sun vector)."""
WHEEL_JOINTS: tuple[str, ...] = ("wheel_x", "wheel_y", "wheel_z")
"""The paper's wheels' names (on the body's x, y, z axes), the default array: JointState.name on `joint_states`
is the configured wheels' (`Spacecraft.wheel_names`)."""

# ----------------------------------------------------------------------------- QoS


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile as plain data (rclpy-free); depth is ignored for keep_all."""

    reliability: str = "reliable"
    durability: str = "volatile"
    history: str = "keep_all"
    depth: int = 0
    liveliness: bool = False
    """Automatic liveliness with the lease of the `liveliness_lease_s` knob (writers and the run's readers
    alike): a reader learns within the lease that a writer's process died (SIGKILL) or hangs, where
    without a lease it keeps the writer matched until Fast DDS's participant lease (20 s) expires."""


STREAM_QOS = QosSpec()
"""Lockstep and recorded data: reliable, keep all, volatile."""
STATE_QOS = QosSpec(liveliness=True)
"""`odometry` and `state`: as STREAM_QOS, plus automatic liveliness with the run's lease, so that controller,
filter (odometry), recorder and scene (state) learn within the lease that the plant died. Only these two
have it: a reader that requests a lease does not match a writer without one, and torque_des must match any
primary controller's writer (the filter covers a dead controller with `desired_timeout_s`)."""
STATUS_QOS = QosSpec(durability="transient_local", history="keep_last", depth=10)
"""run_status: late joiners get the latest statuses."""
COMMAND_QOS = QosSpec(history="keep_last", depth=10)
VIEW_QOS = QosSpec(reliability="best_effort", history="keep_last", depth=1000)
"""The scene node's readers of the loop's topics: best effort, keep last 1000. A view never holds back the loop:
a writer does not wait for a best-effort reader's acknowledgements (reliable readers acknowledge the last
samples of a burst only at the writer's next periodic heartbeat), and a view that falls more
than 1000 states behind, or loses a sample under load, skips states (its counters say how many it drew)."""
DIAGNOSTICS = "/diagnostics"
"""The standard status topic (rqt_robot_monitor, the diagnostic aggregator); `ros.diagnostics` publishes a
node's summary there at ~1 Hz, outside the loop (no run node waits for its readers)."""
DIAGNOSTICS_QOS = QosSpec(history="keep_last", depth=10)
"""attitude_command reader: reliable, volatile (accepts volatile and latched writers)."""




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
STATE_TRUE = "state_true"
ATTITUDE_COMMAND = "attitude_command"
TORQUE_DES = "torque_des"
TORQUE_CMD = "torque_cmd"
FILTER_STATUS = "filter_status"
TORQUE_APPLIED = "torque_applied"
ODOMETRY = "odometry"
WHEELS = "joint_states"
TEMPERATURE = "temperature"
BATTERY = "battery"
SUN_VECTOR = "sun_vector"
RUN_STATUS = "run_status"
SCENE_TRANSFORM = "scene/transform"
SCENE_MARKERS = "scene/markers"

_ALL = ((RECORDER, False, False),)
TOPICS: dict[str, TopicSpec] = {
    t.name: t
    for t in (
        TopicSpec(CLOCK, "rosgraph_msgs/msg/Clock", STREAM_QOS, PLANT, _ALL,
                  "simulation time t_k, one per step (nodes run with use_sim_time)"),
        TopicSpec(STATE, "sensor_msgs/msg/JointState", STATE_QOS, PLANT, ((SCENE, False, False), *_ALL),
                  "record and debug: the whole state packed, name = STATE_NAMES, position = values (model units, "
                  "full precision), stamp = t_k; as measured (sensors: on, docs/noise.md). The loop reads the "
                  "STATE_INPUTS"),
        TopicSpec(STATE_TRUE, "sensor_msgs/msg/JointState", STREAM_QOS, PLANT, _ALL,
                  "the true state, as `state` (published and recorded only with sensors: on)"),
        TopicSpec(ATTITUDE_COMMAND, "geometry_msgs/msg/QuaternionStamped", COMMAND_QOS, "",
                  ((CONTROLLER, False, False), *_ALL),
                  "operator override of q_c (Hill -> body, x y z w), in force from its stamp on"),
        TopicSpec(TORQUE_DES, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, CONTROLLER,
                  ((FILTER, False, False), *_ALL),
                  "desired body torque D u_des [N m], frame body, stamp = the state it answers"),
        TopicSpec(TORQUE_CMD, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, FILTER,
                  ((PLANT, False, False), *_ALL),
                  "filtered body torque D u_act [N m] (without RTA: torque_des passed through), same stamp"),
        TopicSpec(FILTER_STATUS, "diagnostic_msgs/msg/DiagnosticArray", STREAM_QOS, FILTER,
                  ((SCENE, True, False), *_ALL),
                  "per constraint h, Psi, BC, slack, intervening; QP status, fallback, solve time"),
        TopicSpec(TORQUE_APPLIED, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, PLANT, _ALL,
                  "torque the plant held over [t_k, t_k + dt) before saturation (ZOH, deadline fallback)"),
        TopicSpec(ODOMETRY, "nav_msgs/msg/Odometry", STATE_QOS, PLANT,
                  ((CONTROLLER, False, False), (FILTER, True, False), *_ALL),
                  "attitude (body in Hill: frame hill, child body), body rates, CW position (Hill) and velocity "
                  "(body), as measured; stamp = t_k"),
        TopicSpec(WHEELS, "sensor_msgs/msg/JointState", STREAM_QOS, PLANT, ((FILTER, True, False), *_ALL),
                  "reaction wheels: name = the configured wheels' names, velocity = rotor speed [rad/s] as measured, "
                  "effort = motor torque of the last hold [N m]"),
        TopicSpec(TEMPERATURE, "sensor_msgs/msg/Temperature", STREAM_QOS, PLANT, ((FILTER, True, False), *_ALL),
                  "-j_B face temperature [degC], as measured"),
        TopicSpec(BATTERY, "sensor_msgs/msg/BatteryState", STREAM_QOS, PLANT, ((FILTER, True, False), *_ALL),
                  "battery energy as charge [Ah, float32] at power.bus_voltage_V, as measured"),
        TopicSpec(SUN_VECTOR, "geometry_msgs/msg/Vector3Stamped", STREAM_QOS, PLANT, ((FILTER, True, False), *_ALL),
                  "unit vector to the sun, frame hill (ephemeris)"),
        TopicSpec(RUN_STATUS, "diagnostic_msgs/msg/DiagnosticArray", STATUS_QOS, PLANT, _ALL,
                  "run state (running, done, failed), step counts, deadline misses, expected counts"),
        TopicSpec(SCENE_TRANSFORM, "geometry_msgs/msg/TransformStamped", STREAM_QOS, SCENE, _ALL,
                  "view (scene node): the attitude as a transform hill -> body (3D panels read it as tf)"),
        TopicSpec(SCENE_MARKERS, "visualization_msgs/msg/MarkerArray", STREAM_QOS, SCENE, _ALL,
                  "view (scene node), frame hill: body and axes, each pointing constraint's boresight and cone "
                  "about its target, the targets, the panel normal, filter state text"),
    )
}  # fmt: skip
"""Every topic of a run, by (relative) name."""

STATE_INPUTS: tuple[str, ...] = (ODOMETRY, WHEELS, TEMPERATURE, BATTERY, SUN_VECTOR)
"""The state as the flight software receives it, one message each per sample, all stamped t_k: the filter
reads all five and pairs them by exact stamp; the controller reads odometry. Their fields are
`dynamics.sensors.encode`'s, so a reader rebuilds exactly the state `simulate` gives its filter."""
CONTROLLER_INPUTS: tuple[str, ...] = (ODOMETRY,)
PER_STEP_ANSWERS: tuple[str, ...] = (TORQUE_DES, TORQUE_CMD, FILTER_STATUS)
"""The chain's answers to each state: one message per state in a run without faults (the recorder
waits for them at the end while their writers are there)."""
TRUTH_TOPICS: tuple[str, ...] = (STATE_TRUE,)
"""Topics of a run with sensor errors only (`truth`): the true state beside the measured one."""
SCENE_TOPICS: tuple[str, ...] = (SCENE_TRANSFORM, SCENE_MARKERS)
"""Topics of a run with a scene node (`scene`); one message each per drawn state, off the control path."""
SCENE_OFF, SCENE_NODE, SCENE_RECORDER = "none", "node", "recorder"
SCENE_MODES: tuple[str, ...] = (SCENE_OFF, SCENE_NODE, SCENE_RECORDER)
"""The `scene` knob ("none", not "off": ROS parses `-p scene:=off` as YAML, a boolean): no scene node; a
scene_node process of its own, reading `state` and `filter_status`
(runs without a recorder, `ros2 run`); or the scene node hosted in the recorder's process, fed the bytes the
recorder receives (no second reception of the loop's messages) and writing what it draws into the bag
itself, as well as publishing it (the launch file and `rta-attitude launch` with a recorder)."""


def _in_run(name: str, truth: bool, scene: str = SCENE_OFF) -> bool:
    return (truth or name not in TRUTH_TOPICS) and (scene != SCENE_OFF or name not in SCENE_TOPICS)




def subscribed(role: str, rta: bool) -> list[TopicSpec]:
    """Topics a role subscribes to in a run with/without RTA."""
    out = []
    for spec in TOPICS.values():
        for who, only_rta, only_plain in spec.readers:
            if who == role and not (only_rta and not rta) and not (only_plain and rta):
                out.append(spec)
    return out


def published(role: str, rta: bool, truth: bool = False) -> list[TopicSpec]:
    """Topics a role publishes (filter_status only with RTA: without, the filter passes through;
    TRUTH_TOPICS only with sensor errors, `truth`)."""
    return [t for t in TOPICS.values()
            if t.publisher == role and (rta or t.name != FILTER_STATUS) and _in_run(t.name, truth, role == SCENE)]


def recorded(rta: bool, truth: bool = False, scene: str = SCENE_OFF) -> list[TopicSpec]:
    """Topics the recorder writes to the bag: all of the run's (filter_status only with RTA,
    TRUTH_TOPICS only with sensor errors, SCENE_TOPICS only with a scene node; a hosted one's messages the
    recorder writes itself)."""
    return [t for t in subscribed(RECORDER, rta)
            if (rta or t.name != FILTER_STATUS) and _in_run(t.name, truth, scene)]


def reader_roles(topic: str, rta: bool, record: bool, truth: bool = False, scene: str = SCENE_OFF,
                 external_controller: bool = False) -> list[str]:
    """The roles of the run's own nodes that subscribe to `topic` (`scene`, SCENE_MODES: a scene_node of its
    own has best-effort readers of `state` and `filter_status`, waited for at start-up like any reader, so
    the view misses no state, but never holding a writer back during the run; a scene hosted by the
    recorder reads nothing, and the recorder does not read its topics). With `external_controller` the
    run has no pd_controller_node: the CONTROLLER role reads nothing (the plant counts the readers of the
    node that publishes torque_des instead, `ros.plant_node`)."""
    if not _in_run(topic, truth, scene) or (topic in SCENE_TOPICS and scene == SCENE_RECORDER):
        return []
    return [who for who, only_rta, only_plain in TOPICS[topic].readers
            if not ((only_rta and not rta) or (only_plain and rta) or (who == RECORDER and not record)
                    or (who == SCENE and scene != SCENE_NODE) or (who == CONTROLLER and external_controller))]


def expected_readers(topic: str, rta: bool, record: bool, truth: bool = False, scene: str = SCENE_OFF,
                     external_controller: bool = False) -> int:
    """How many of the run's own nodes subscribe to `topic`; a writer waits for this many matches
    before its first message (tools such as `ros2 topic echo` only add readers)."""
    return len(reader_roles(topic, rta, record, truth, scene, external_controller))


# ----------------------------------------------------------------------------- diagnostics

STATUS_HARDWARE_ID = "rta_attitude"
QP_STATUS_NAME = "filter"
"""filter_status: the entry of the filter call (QP status, fallback, box, timing, counters); one entry
per constraint follows, named like the constraint (`Config.constraint_names`). rta_attitude.recording.analysis
reads this layout."""
CONSTRAINT_STATUS_PREFIX = ""
INPUT_COUNTERS: tuple[str, ...] = (
    "state_rejected", "state_renormalised", "state_stale", "state_duplicate", "state_out_of_order",
    "torque_des_rejected", "torque_des_duplicate", "torque_des_out_of_order", "torque_des_late",
    "torque_des_missing", "unpaired_dropped", "output_guard", "plant_lost", "clock_jumps",
)  # fmt: skip
"""The filter node's input counters (running totals, in every filter_status):

- `state_rejected`: a state whose values are unusable (NaN/inf, wrong length or names, quaternion norm
  beyond `quaternion_tolerance`) but whose stamp is valid: filtered as an invalid state (the core's
  `invalid_state` fallback, u = 0), so the plant still gets a command for that step;
- `state_renormalised`: quaternion norm off 1 by more than UNIT_NORM_EPS, within `quaternion_tolerance`;
- `state_stale`: older than the /clock time by more than `max_state_age_s` (dropped, not answered);
- `state_duplicate` / `state_out_of_order`: stamp equal to / older than the newest state taken (dropped);
- `torque_des_rejected`: NaN/inf or wrong frame with a valid stamp: filtered as non-finite u_des (the core's
  `non_finite_u_des` fallback);
- `torque_des_duplicate` / `torque_des_out_of_order`: stamp equal to / older than the newest taken (dropped);
- `torque_des_late`: arrived for a state already answered without it (dropped);
- `torque_des_missing`: a state answered with u_des = 0 because no torque_des came (`desired_timeout_s`,
  or at once when the controller's publisher is gone);
- `unpaired_dropped`: unpaired messages dropped beyond MAX_PENDING per topic; messages whose stamp
  itself is invalid are counted as `*_rejected` and dropped;
- `output_guard`: a filter output that was not finite or not inside U, replaced by u = 0 (never expected);
- `plant_lost`: the plant's `state` writer lost its liveliness (no sign of life for `liveliness_lease_s`:
  the process was killed or hangs); the states that wait for their torque_des are dropped (no command is
  sent to a dead plant); it counts as back after 3 leases alive again (one episode, one report);
- `clock_jumps`: /clock jumped backwards (a replay restarted): the stamp screens were reset.
"""
REJECTED_COMMANDS: tuple[str, ...] = (
    "torque_des_rejected", "torque_des_duplicate", "torque_des_out_of_order", "torque_des_late",
)  # fmt: skip
"""The INPUT_COUNTERS of desired commands the filter did not use as sent (wrong frame, not finite, invalid
stamp; stale: a repeated, older or late stamp): what `rta-attitude analyze`'s verdict reports as rejected."""
REJECTION_KEY = "torque_des_rejected_reason"
"""filter_status key: why the latest rejected torque_des was rejected (`frame 'base_link'`, `not finite`,
`invalid stamp`, `stale (late)`, `stale (duplicate)`, `stale (out of order)`); empty while none was. The last key
of the `filter` entry (the scene reads `gave_way` before it by position; no value is a single word, so none can
be taken for a constraint entry's name)."""
INPUT_SOURCE_KEY = "u_des_source"
"""filter_status key: where this call's u_des came from: `torque_des`, or `missing` (u_des = 0 after a
timeout or with the controller gone)."""
KEY_STATUS, KEY_FALLBACK, KEY_SOLVE_TIME, KEY_PRESET = "status", "fallback", "solve_time_s", "preset"
KEY_BOX_ACTIVE = "box_active"
"""filter_status keys that readers (bag analysis, echo) look up by name; box_active has one key per axis."""
QP_KEYS: tuple[str, ...] = (
    KEY_STATUS, "solver_status", "iterations", KEY_FALLBACK, KEY_SOLVE_TIME, KEY_PRESET,
    "u_des_x", "u_des_y", "u_des_z", "u_x", "u_y", "u_z", "u_held_x", "u_held_y", "u_held_z",
    *(f"{KEY_BOX_ACTIVE}_{a}" for a in "xyz"),
    "calls", "fast_path", "solved", "fallbacks", "solver_failures", "backup_solves", "invalid_states",
    INPUT_SOURCE_KEY, *INPUT_COUNTERS, "gate", "gave_way", REJECTION_KEY, "wheels",
)  # fmt: skip
"""Keys of the `filter` entry: status ('pass', 'solved', 'fallback'), solver status (outcome.solve_text), iterations,
fallback policy applied ('none' if none), solve time [s], preset, u_des, u (the command sent) and u_held (the
filter's answer: what the wheels hold, u but where the drive's lag is compensated) [rad/s^2], box flags,
the filter's running counters (core: calls .. invalid_states), the source of u_des, the node's
input counters (INPUT_COUNTERS), what the gatekeeper did (`filter.outcome.GATE_NAMES`: 'off'
without a backup law), why the latest rejected torque_des was rejected (REJECTION_KEY) and the wheels ('ok', or
with `spacecraft.failed_wheels` what is lost: the entry is then an ERROR)."""
NO_FALLBACK = "none"
KEY_SLACK, KEY_INTERVENING, KEY_SLACKED = "slack", "intervening", "slacked"
CONSTRAINT_KEYS: tuple[str, ...] = (
    "h", "psi0", "psi1", "bc", KEY_SLACK, KEY_INTERVENING, "uncontrollable", KEY_SLACKED,
)  # fmt: skip
"""Keys of each constraint entry (floats as repr, exact; flags 'true'/'false')."""

RUN_STATUS_NAME = "plant/run"
RUN_RUNNING, RUN_DONE, RUN_FAILED, RUN_INTERRUPTED = "running", "done", "failed", "interrupted"
"""run_status states: `running` (at the start, and again when a plant fault episode starts or ends),
then one final `done`, `failed: reason` or `interrupted: SIGINT|SIGTERM`."""
PLANT_COUNTERS: tuple[str, ...] = (
    "commands", "rejected", "late", "duplicate", "future", "outside_u", "saturated", "deadline_misses",
    "fallback_zero", "fallback_hold",
)  # fmt: skip
"""The plant's counters in run_status: commands received; `rejected` (NaN/inf or wrong frame, not
applied); `late` (stamp older than the current step: answered after a deadline miss); `duplicate` (a
second command for a step already applied); `future` (stamp newer than the current step);
`outside_u` (a command outside the admissible set U, |u_i| > u_max,i: applied as it is, which only
happens without RTA or with a broken filter); `saturated` (beyond the actuator limit psi_dot_max:
the wheels saturate it, as `simulation.integrate` does); `deadline_misses` (no command for t_k in
time: realtime by t_k+1, lockstep within `command_timeout_s`) and the fallback applied each time
(`fallback_zero`, `fallback_hold`)."""
EXPECTED_PREFIX = "expected:"
"""run_status keys `expected:<topic>` give the final message count of a topic, when known."""

# ----------------------------------------------------------------------------- knobs


@dataclass(frozen=True)
class Knob:
    """A node-only parameter (not part of the core YAML).

    Numbers must lie in [minimum, maximum] (`positive`: > minimum); `check_knob` enforces it.
    """

    name: str
    default: Any
    roles: tuple[str, ...]
    description: str
    choices: tuple[str, ...] = ()
    minimum: float = 0.0
    positive: bool = False
    maximum: float | None = None

    @property
    def allowed(self) -> str:
        """The allowed values in words, for error messages and docs."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        kind = {bool: "true or false", int: "an integer", float: "a float", str: "a string"}[type(self.default)]
        if not isinstance(self.default, (int, float)) or isinstance(self.default, bool):
            return kind
        low = f"{'>' if self.positive else '>='} {self.minimum:g}"
        return f"{kind} {low}" + (f" and < {self.maximum:g}" if self.maximum is not None else "")


_EVERY = (PLANT, CONTROLLER, FILTER, RECORDER, SCENE)
KNOBS: tuple[Knob, ...] = (
    Knob("config_file", "", _EVERY, "parameter file the nodes read their defaults from ('' = installed one)"),
    Knob("scenario", "paper_example", _EVERY, "scenario name from the parameter file"),
    Knob("rta", True, _EVERY, "true: the filter runs; false: the plant applies torque_des"),
    Knob("record", True, _EVERY, "a bag_recorder_node takes part (writers wait for its subscriptions)"),
    Knob("startup_timeout_s", 30.0, _EVERY, "wall time to wait for the run's readers to match [s]", positive=True),
    Knob("stop_timeout_s", 3.0, _EVERY,
         "after SIGINT/SIGTERM (plant: also at the end of the run): longest wait for readers to acknowledge "
         "what the node published (recorder: for the last messages) [s]"),
    Knob("executor", "events", _EVERY, "events: rclpy's C++ EventsExecutor; single: SingleThreadedExecutor",
         ("events", "single")),
    Knob("exit_with_parent", False, _EVERY,
         "stop cleanly (as on SIGTERM: the run ends `interrupted`, the bag is closed) when the process that "
         "started this node exits; the launch file and `rta-attitude launch` set it (a SIGTERM to `ros2 launch` "
         "leaves its nodes running otherwise)"),
    Knob("liveliness_lease_s", 2.0, _EVERY,
         "automatic liveliness lease of `state` (the plant offers it, its readers request it): a plant that "
         "shows no sign of life for this long (killed, hung) is reported lost once; 0 = no lease. Readers "
         "do not match a writer with a longer lease or none (a one-line warning says so) [s]"),
    Knob("quaternion_tolerance", 0.01, (CONTROLLER, FILTER),
         "state and attitude_command: | |q| - 1 | up to this is renormalised (counted), beyond it rejected",
         positive=True, maximum=0.5),
    Knob("max_state_age_s", 2.0, (CONTROLLER, FILTER),
         "with use_sim_time: a state older than the /clock time by more than this is stale (dropped); 0 = off"),
    Knob("desired_timeout_s", 1.0, (FILTER,),
         "a state without torque_des this long (wall) is filtered with u_des = 0 (at once if the controller "
         "is gone) [s]", positive=True),
    Knob("external_controller", False, (PLANT,),
         "true: no pd_controller_node; the run starts once a node that publishes torque_des on the run's "
         "namespace reads the state (`rta-attitude launch --controller none`, the launch file's controller:=none)"),
    Knob("stepping", "lockstep", (PLANT,), "lockstep (deterministic) or realtime (wall-clock timer)",
         ("lockstep", "realtime")),
    Knob("real_time_factor", 1.0, (PLANT,), "realtime: sim seconds per wall second", positive=True),
    Knob("command_timeout_s", 5.0, (PLANT,),
         "lockstep: wall time to wait for the command of a step before a deadline miss (the first command "
         "of the run may take startup_timeout_s, up to 4 times that while its writer is alive) [s]", positive=True),
    Knob("deadline_fallback", "hold", (PLANT,),
         "no command for t_k in time (deadline miss): hold the last applied torque, or apply zero",
         ("hold", "zero")),
    Knob("hold_max_steps", 1, (PLANT,),
         "deadline_fallback hold: consecutive misses for which the last torque is held; zero after that"),
    Knob("exit_when_done", True, (PLANT, RECORDER), "exit after the run ends (plant) / the bag is closed"),
    Knob("bag_path", "", (RECORDER,), "MCAP file to write (default: rta_attitude_YYYY_MM_DD-HH_MM_SS.mcap)"),
    Knob("bag_overwrite", False, (RECORDER,), "replace an existing bag file"),
    Knob("bag_chunk_kb", 256, (RECORDER,), "uncompressed KiB per MCAP chunk: a killed recorder loses at most one",
         minimum=1),
    Knob("drain_timeout_s", 10.0, (RECORDER,), "after run_status done: longest wait for the last messages [s]"),
    Knob("drain_quiet_s", 0.3, (RECORDER,), "after done, topics without a known count: close after this quiet [s]"),
    Knob("scene", SCENE_OFF, _EVERY, "the run's scene node (the launch sets it with scene:=true): none; node (a "
         "scene_node process of its own: the plant and filter wait for its readers at start-up); recorder (hosted "
         "in the recorder's process, fed what the recorder receives)", SCENE_MODES),
    Knob("scene_every", 1, (SCENE, RECORDER), "draw every n-th state (the steps k with k % n == 0)", minimum=1),
    Knob("scene_warn_deg", 5.0, (SCENE, RECORDER), "a pointing margin below this is drawn as a warning (orange) "
         "[deg]", positive=True, maximum=180.0),
)  # fmt: skip
"""Node-only parameters; every other parameter comes from the core YAML."""
SYSTEM_PARAMETERS: tuple[str, ...] = ("use_sim_time", "start_type_description_service")
"""Parameters rclpy declares itself (never part of the core config)."""


CONFIG_SECTIONS: dict[str, tuple[str, ...]] = {
    PLANT: ("spacecraft", "environment", "thermal", "power", "limits", "integrator", "plant", "sensors",
            "filter.sample_time_s"),
    CONTROLLER: ("controller", "spacecraft.wheel_inertia_kgm2", "limits.wheel_accel_max_rad_s2"),
    FILTER: ("spacecraft", "environment", "thermal", "power", "limits", "constraints", "filter", "integrator",
             "sensors"),
    RECORDER: ("filter.preset", "filter.sample_time_s"),
    SCENE: ("limits", "constraints.pointing", "environment", "power", "filter.sample_time_s"),
}  # fmt: skip
"""The core parameters (sections, or single dotted names) each role uses and declares as ROS parameters,
besides its own scenario's (`scenarios.<scenario>.*`). The node's configuration is still built from the
whole parameter file and every override, so a parameter a role does not declare cannot make two nodes
disagree; it is only not shown by `ros2 param list` there."""
LIVE_PARAMETERS: dict[str, tuple[str, ...]] = {CONTROLLER: ("controller.kp", "controller.kd"),
                                                PLANT: ("spacecraft.failed_wheels",),
                                                FILTER: ("spacecraft.failed_wheels",)}
"""Core parameters a role lets `ros2 param set` change while it runs (validated by the core loader, logged);
every other parameter is read at start-up and read_only. A failed wheel is the plant's fault injection and the
filter's knowledge of it: set it on both."""


def config_sections(role: str, scenario: str) -> tuple[str, ...]:
    """The dotted prefixes of the core parameters `role` declares when it runs `scenario` (its key in the
    parameter file, `Scenario.name`)."""
    return (*CONFIG_SECTIONS[role], f"scenarios.{scenario}")


def knobs_for(role: str) -> tuple[Knob, ...]:
    """The knobs a role declares."""
    return tuple(k for k in KNOBS if role in k.roles)


__all__ = [
    "ATTITUDE_COMMAND", "BATTERY", "BODY_FRAME", "CLOCK", "COMMAND_QOS", "CONFIG_SECTIONS", "CONSTRAINT_KEYS",
    "CONSTRAINT_STATUS_PREFIX", "CONTROLLER", "DEFAULT_NAMESPACE",
    "DIAGNOSTICS", "DIAGNOSTICS_QOS", "EXECUTABLES", "EXPECTED_PREFIX", "FILTER",
    "FILTER_STATUS", "HILL_FRAME", "INPUT_COUNTERS", "INPUT_SOURCE_KEY", "STATE_INPUTS", "CONTROLLER_INPUTS",
    "WHEELS", "WHEEL_JOINTS", "KNOBS",
    "LIVE_PARAMETERS", "MODULES",
    "NODE_NAMES", "NO_FALLBACK", "ODOMETRY", "PACKAGE", "PER_STEP_ANSWERS", "PLANT", "PLANT_COUNTERS", "QP_KEYS",
    "QP_STATUS_NAME",
    "RECORDER", "REJECTED_COMMANDS", "REJECTION_KEY",
    "RUN_DONE", "RUN_FAILED", "RUN_INTERRUPTED", "RUN_RUNNING", "RUN_STATUS",
    "RUN_STATUS_NAME", "SCENE", "SCENE_MARKERS", "SCENE_MODES", "SCENE_NODE", "SCENE_OFF", "SCENE_RECORDER",
    "SCENE_TOPICS", "SCENE_TRANSFORM", "STATE", "STATE_QOS",
    "STATE_TRUE", "TRUTH_TOPICS", "VIEW_QOS",
    "STATUS_HARDWARE_ID", "STATUS_QOS", "STREAM_QOS", "SUN_VECTOR",
    "SYSTEM_PARAMETERS",
    "TEMPERATURE", "TOPICS", "TORQUE_APPLIED", "TORQUE_CMD", "TORQUE_DES", "Knob", "QosSpec", "TopicSpec",
    "config_sections", "expected_readers", "reader_roles", "knobs_for", "published", "recorded", "subscribed",
]  # fmt: skip
