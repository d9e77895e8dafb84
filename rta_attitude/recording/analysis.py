"""Bag replay analysis: a recorded MCAP bag -> the run's time series, summary and paper-style figure.

    rta-attitude analyze BAG [--out DIR] [--compare BAG2] [--config FILE] [--namespace NS]

ROS-free (the bag is read with `rta_attitude.recording.bag`; the topic vocabulary comes from the pure-Python
`rta_attitude.topics`; nothing imports rclpy or a message package). From the topics of one run under a
namespace (default: the one whose `state` topic the bag has, normally `/rta`):

| topic            | type                                | used for                                        |
|------------------|-------------------------------------|-------------------------------------------------|
| `state`          | sensor_msgs/msg/JointState          | x_k (19 values, by name), t_k = header stamp    |
| `torque_applied` | geometry_msgs/msg/Vector3Stamped    | u_k = sat(tau / D): what the plant held (opt.)  |
| `torque_cmd`     | geometry_msgs/msg/Vector3Stamped    | u_k where torque_applied is absent              |
| `torque_des`     | geometry_msgs/msg/Vector3Stamped    | u_des,k = tau_des / D                           |
| `filter_status`  | diagnostic_msgs/msg/DiagnosticArray | slack, intervening, box, status, fallback, time |
| `run_status`     | diagnostic_msgs/msg/DiagnosticArray | scenario, number of steps (optional)            |

plus the recorder's MCAP metadata record `rta_attitude` (scenario, rta, preset; optional: a bag
from `ros2 bag record -s mcap` of the same topics has none, then `--scenario` names the run).
The last state read ends the run (the plant's final state t_N, which the chain also answers, or
where a truncated bag stops); the number of steps recorded by the plant caps it.

Messages are matched by header stamp (the stamp of the state a command answers). What the bag
does not hold is recomputed exactly from what it does: h at the samples from the states, and the
minima of h *between* samples (which `simulate` takes from its RK4 substeps) by re-integrating every
recorded step from its recorded state with its recorded command (`dynamics.spacecraft`'s ZOH/RK4,
the plant's own code, step by step). The re-integrated end of each step is compared with
the next recorded state: the largest difference (`bag.reintegration_residual`) is ~0 for a lockstep
run, which proves the recomputed substep minima are the plant's own. A bag cut short (writer killed)
is analysed up to its last complete step and the summary says where the data stops.

The summary has the keys and values of `simulate`'s (`metrics.summarize`) plus a `bag` section
(file, topics, truncation, residual, the commands the filter rejected and the verdict's qualifiers:
`recording.summary`); only `wall_time_s` is absent (no simulation ran here).

One module because everything in it serves `load_run`: the private helpers are the steps of one
rebuild (which topics, pairing by stamp, which torque was applied, what goes into `notes`), whose rules
are read together; the parts with a life of their own have left (the raw CDR reader for
`recording/cdr.py`, summaries and comparison for `recording/summary.py`).
"""

from __future__ import annotations

import logging
import os
import struct
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude import topics
from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import AXES, STATE_NAMES, STATE_SIZE
from rta_attitude.errors import BagError, ConfigError
from rta_attitude.recording import bag as bagio
from rta_attitude.recording.cdr import Cdr, CdrError, read_diagnostics, read_state, read_vector
from rta_attitude.simulation.trajectory import substep_minima

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

DEFAULT_NAMESPACE = topics.DEFAULT_NAMESPACE
STATE_TOPIC, TORQUE_DES_TOPIC, TORQUE_CMD_TOPIC = topics.STATE, topics.TORQUE_DES, topics.TORQUE_CMD
FILTER_STATUS_TOPIC, TORQUE_APPLIED_TOPIC, RUN_STATUS_TOPIC = topics.FILTER_STATUS, topics.TORQUE_APPLIED, \
    topics.RUN_STATUS
STATE_TRUE_TOPIC = topics.STATE_TRUE
TOPIC_TYPES: dict[str, str] = {name: topics.TOPICS[name].type_name for name in (
    STATE_TOPIC, TORQUE_DES_TOPIC, TORQUE_CMD_TOPIC, FILTER_STATUS_TOPIC, TORQUE_APPLIED_TOPIC, RUN_STATUS_TOPIC,
    STATE_TRUE_TOPIC)}
"""Relative topic names read from a bag and their types (the vocabulary of rta_attitude.topics)."""
REQUIRED_TOPICS = (STATE_TOPIC, TORQUE_CMD_TOPIC)
METADATA_RECORD = "rta_attitude"
"""Name of the MCAP metadata record in which the recorder stores the run's facts."""


RUN_FACTS: tuple[str, ...] = ("run_state", "stepping", *topics.PLANT_COUNTERS)
"""Facts of the plant's run_status / the recorder's metadata copied into the summary's `bag` section."""
RESIDUAL_TOLERANCE = 1e-9
"""Relative state difference below which re-integration counts as reproducing the recorded run."""
NS_PER_S = 1_000_000_000


@dataclass
class BagRun:
    """One run rebuilt from a bag: the series `plots.plot_runs` and `metrics.summarize` take.

    Step arrays have N rows, sample arrays N + 1 (as simulation.Trajectory).

    Attributes:
        path: the MCAP file read.
        namespace: the namespace of the run's topics, e.g. '/rta'.
        names: constraint names (m,).
        t_s: sample times (N + 1,), s (the state stamps).
        x: recorded states (N + 1, 19), model units: the true state where the bag has it (state_true).
        u_des, u: desired and applied wheel accelerations (N, 3), rad/s^2 (u saturated like the plant).
        omega_dot: body angular acceleration at the start of each step (N, 3), rad/s^2.
        h: physical constraint values at the samples (N + 1, m).
        h_substep_min, h_substep_argmin_s: minimum of h within each step and its time (N, m), recomputed.
        slack, intervening: (N, m); box_active: (N, 3); status, fallback: (N,); solve_time_s: (N,) s.
        slacked: constraints that carry a slack in this run.
        rta: a filter ran (the bag has filter_status).
        preset, scenario: as recorded, or as given / guessed (see `notes`).
        dt_s: sample time, s.
        truncated: the file has no MCAP footer (writer killed); `data_end_s` is the last sample used.
        reintegration_residual: largest relative difference between a re-integrated step end and the
            next recorded state (dimensionless); ~0 means the substep minima are exact.
        topic_types, counts: the run's topics found in the bag, their types and messages read.
        notes: what could not be taken from the bag, one line each.
        run_facts: what the plant and recorder reported about the run (RUN_FACTS keys found).
    """

    path: Path
    namespace: str
    names: tuple[str, ...]
    t_s: Array
    x: Array
    u_des: Array
    u: Array
    omega_dot: Array
    h: Array
    h_substep_min: Array
    h_substep_argmin_s: Array
    slack: Array
    intervening: Array  # bool, as in simulation.Trajectory
    box_active: Array  # bool
    status: NDArray[np.str_]
    fallback: NDArray[np.str_]
    solve_time_s: Array
    slacked: tuple[str, ...]
    rta: bool
    preset: str | None
    scenario: str
    dt_s: float
    truncated: bool
    data_end_s: float
    reintegration_residual: float
    topic_types: dict[str, str] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    run_facts: dict[str, Any] = field(default_factory=dict)
    y: Array | None = None
    """The measured states the controller and the filter read (N + 1, 19), when the bag has the true
    state beside them (sensor errors on; `x` is then the truth); None: x is what everyone read."""
    input_counts: dict[str, int] = field(default_factory=dict)
    """The filter node's input counters (topics.INPUT_COUNTERS) and its `calls`, from the last filter_status
    of the bag ({} without filter_status)."""
    rejection: str = ""
    """Why the filter rejected its latest rejected torque_des (topics.REJECTION_KEY, e.g. "frame 'base_link'");
    '' if it rejected none, or the bag does not say."""

    @property
    def steps(self) -> int:
        """Number of control steps N."""
        return len(self.u)

    @property
    def label(self) -> str:
        """'RTA on (robust)' or 'RTA off'."""
        return f"RTA on ({self.preset})" if self.rta else "RTA off"


# ----------------------------------------------------------------------------- reading


def resolve_bag_path(path: str | os.PathLike[str]) -> Path:
    """The MCAP file of `path`: the file itself, or the single `.mcap` in a rosbag2 bag directory.

    Raises:
        BagError: no such file, a directory without exactly one .mcap file.
    """
    p = Path(path)
    if p.is_dir():
        files = sorted(p.glob("*.mcap"))
        if len(files) != 1:
            what = "no .mcap file" if not files else f"{len(files)} .mcap files (split bags are not supported)"
            raise BagError(f"{p}: bag directory with {what}")
        return files[0]
    if not p.exists():
        raise BagError(f"{p}: no such file")
    return p


def _stamp_ns(msg: Any) -> int:
    stamp = msg.header.stamp
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def find_namespace(available: Mapping[str, str], path: Path) -> str:
    """The namespace of the run in a bag: the prefix of its JointState `.../state` topic.

    Raises:
        BagError: no such topic (a foreign bag), or several runs in one bag.
    """
    found = sorted(t.rsplit("/", 1)[0] or "/" for t, ty in available.items()
                   if t.rsplit("/", 1)[-1] == STATE_TOPIC and ty == TOPIC_TYPES[STATE_TOPIC])
    if not found:
        listed = ", ".join(f"{t} ({ty})" for t, ty in sorted(available.items())) or "none"
        raise BagError(f"{path}: not an rta_attitude run: no sensor_msgs/msg/JointState 'state' topic "
                       f"(topics: {listed})")
    if len(found) > 1:
        raise BagError(f"{path}: several runs in one bag (namespaces {', '.join(found)}); pass --namespace")
    return found[0]


def _full(namespace: str, name: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"


def _plain_value(text: str) -> Any:
    """A KeyValue string as a bool ('true'/'false'), an int, a float or the text itself."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_diagnostics(msg: Any) -> dict[str, dict[str, str]]:
    """A DiagnosticArray (filter_status, run_status) as {status name: {key: value text}}."""
    return {str(s.name): {str(kv.key): str(kv.value) for kv in s.values} for s in msg.status}


def _flag(text: str | None) -> bool:
    return text is not None and text.strip().lower() == "true"


def _decoded(name: str | None, msg: Any) -> tuple[int, Any]:
    """(stamp [ns], payload) of a message decoded by mcap_ros2, as the raw readers give it."""
    stamp = _stamp_ns(msg)
    if name in (STATE_TOPIC, STATE_TRUE_TOPIC):
        return stamp, (tuple(msg.name), np.asarray(msg.position, dtype=float))
    if name in (FILTER_STATUS_TOPIC, RUN_STATUS_TOPIC):
        return stamp, parse_diagnostics(msg)
    return stamp, np.array([msg.vector.x, msg.vector.y, msg.vector.z], dtype=float)


def _raw(name: str | None, data: bytes) -> tuple[int, Any]:
    """(stamp [ns], payload) read straight from CDR bytes; CdrError if they are not as expected."""
    try:
        c = Cdr(data)
        if name in (STATE_TOPIC, STATE_TRUE_TOPIC):
            stamp, names, pos = read_state(c)
            return stamp, (names, pos)
        if name in (FILTER_STATUS_TOPIC, RUN_STATUS_TOPIC):
            return read_diagnostics(c)
        return read_vector(c)
    except (struct.error, ValueError, IndexError, UnicodeDecodeError) as exc:
        raise CdrError(str(exc)) from None


@dataclass
class _Records:
    """The topics of one run, keyed by stamp [ns]."""

    states: dict[int, Array] = field(default_factory=dict)
    true_states: dict[int, Array] = field(default_factory=dict)
    torque_des: dict[int, Array] = field(default_factory=dict)
    torque_cmd: dict[int, Array] = field(default_factory=dict)
    torque_applied: dict[int, Array] = field(default_factory=dict)
    status: dict[int, dict[str, dict[str, str]]] = field(default_factory=dict)
    run_status: list[dict[str, dict[str, str]]] = field(default_factory=list)
    duplicates: int = 0


def _state_vector(names: tuple[str, ...], pos: Array, stamp: int, path: Path,
                  order: dict[tuple[str, ...], NDArray[np.intp]]) -> Array:
    idx = order.get(names)
    if idx is None:
        missing = [n for n in STATE_NAMES if n not in names]
        if missing or len(set(names)) != len(names):
            raise BagError(f"{path}: a state message does not name the 19 state entries "
                           f"(missing {', '.join(missing[:4]) or 'none'}; got {len(names)} names)")
        idx = np.array([names.index(n) for n in STATE_NAMES])
        order[names] = idx
    if pos.shape != (len(names),):
        raise BagError(f"{path}: a state message has {pos.size} positions for {len(names)} names")
    x = pos[idx]
    if not np.all(np.isfinite(x)):
        raise BagError(f"{path}: the state at t = {stamp / NS_PER_S:.3f} s is not finite")
    return x


def _collect(contents: bagio.BagContents, namespace: str, path: Path) -> _Records:
    """Sort the messages of `contents` (raw, or decoded if `contents` was read with decode=True)."""
    rec = _Records()
    order: dict[tuple[str, ...], NDArray[np.intp]] = {}
    name_of = {_full(namespace, n): n for n in TOPIC_TYPES}
    torques = {TORQUE_DES_TOPIC: rec.torque_des, TORQUE_CMD_TOPIC: rec.torque_cmd,
               TORQUE_APPLIED_TOPIC: rec.torque_applied}
    for m in contents.messages:
        name = name_of.get(m.topic)
        if name is None:
            continue
        if m.message is None:
            stamp, payload = _raw(name, m.data)
        else:
            try:
                stamp, payload = _decoded(name, m.message)
            except AttributeError:
                raise BagError(f"{path}: a message on {m.topic} is not a {TOPIC_TYPES[name]}") from None
        if name == RUN_STATUS_TOPIC:
            rec.run_status.append(payload)
        elif name == STATE_TOPIC:
            if stamp in rec.states:
                rec.duplicates += 1
                continue
            names, positions = payload
            rec.states[stamp] = _state_vector(names, positions, stamp, path, order)
        elif name == STATE_TRUE_TOPIC:
            names, positions = payload
            rec.true_states.setdefault(stamp, _state_vector(names, positions, stamp, path, order))
        elif name in torques:
            if not np.all(np.isfinite(payload)):
                raise BagError(f"{path}: the torque on {m.topic} at t = {stamp / NS_PER_S:.3f} s is not finite")
            torques[name].setdefault(stamp, payload)
        elif name == FILTER_STATUS_TOPIC:
            rec.status.setdefault(stamp, payload)
    return rec


def _read_records(file: Path, wanted: list[str], namespace: str) -> tuple[bagio.BagContents, _Records]:
    """Read the run's topics: raw CDR through the fast reader, else through mcap_ros2's decoder."""
    contents = bagio.read_bag(file, topics=wanted, decode=False)
    try:
        return contents, _collect(contents, namespace, file)
    except CdrError as exc:
        log.debug("%s: fast CDR reader gave up (%s); decoding generically", file, exc)
    contents = bagio.read_bag(file, topics=wanted, decode=True)
    return contents, _collect(contents, namespace, file)


def _run_info(contents: bagio.BagContents, rec: _Records) -> dict[str, Any]:
    """Run facts: the plant's run_status values (first to last), then the recorder's metadata record."""
    info: dict[str, Any] = {}
    for status in rec.run_status:
        info.update({k: _plain_value(v) for k, v in status.get(topics.RUN_STATUS_NAME, {}).items()})
    for key, value in contents.metadata.get(METADATA_RECORD, {}).items():
        info[key] = value if key in ("scenario", "preset", "config", "namespace") else _plain_value(value)
    return info


def _epoch_ns(info: Mapping[str, Any], cfg: Config, scenario: str, first_ns: int) -> int:
    """ROS time of the run's t = 0: the recorder's `epoch_ns`; for a bag without it (`ros2 bag record`, or
    recorded before scenarios had an epoch), the scenario's epoch from `cfg` if the stamps are not earlier,
    else 0 (stamps in scenario time)."""
    recorded = info.get("epoch_ns")
    if isinstance(recorded, int) and not isinstance(recorded, bool):
        return recorded
    try:
        epoch = cfg.scenario(scenario).epoch_ns
    except ConfigError:
        epoch = cfg.scenario(next(iter(cfg.scenarios))).epoch_ns if cfg.scenarios else 0
    return epoch if first_ns >= epoch else 0


def _pair_steps(rec: _Records, path: Path, max_steps: int | None) -> tuple[list[int], list[int]]:
    """(sample stamps t_0..t_N, command stamp of each step k < N).

    Step k runs from state k with the command stamped like state k; in a real-time run where that
    command is missing, with the latest earlier one (zero-order hold). The last state read ends the
    run (the plant's final state, or where a truncated bag stops); `max_steps` caps N.
    """
    stamps = sorted(rec.states)
    if not stamps:
        raise BagError(f"{path}: no state messages")
    cmd_stamps = sorted(set(rec.torque_cmd) | set(rec.torque_applied))
    if not cmd_stamps or cmd_stamps[0] > stamps[0]:
        raise BagError(f"{path}: no torque_cmd answers the first state (t = {stamps[0] / NS_PER_S:.3f} s)")
    if max_steps is not None:
        stamps = stamps[: max_steps + 1]
    used: list[int] = []
    j = 0
    for s in stamps[:-1]:
        while j + 1 < len(cmd_stamps) and cmd_stamps[j + 1] <= s:
            j += 1
        used.append(cmd_stamps[j])
    if not used:
        raise BagError(f"{path}: only one state sample (t = {stamps[0] / NS_PER_S:.3f} s); no control step")
    return stamps, used


def load_run(
    path: str | os.PathLike[str],
    cfg: Config,
    namespace: str | None = None,
    scenario: str | None = None,
) -> BagRun:
    """Read a bag and rebuild the run: samples, commands, filter records, recomputed h and substep minima.

    Args:
        path: MCAP file, or a rosbag2 bag directory holding one.
        cfg: configuration of the run (limits, D, RK4 substeps; slack weights of the scenario).
        namespace: topics' namespace; None = the one whose `state` topic the bag has.
        scenario: scenario name for the report (and its slack weights); default: as recorded
            (metadata record or run_status), else the file name.

    Raises:
        BagError: missing, empty, non-MCAP, corrupt or foreign bag; malformed messages.
    """
    t_start = time.perf_counter()
    file = resolve_bag_path(path)
    available = bagio.topics(file)
    ns = find_namespace(available, file) if namespace is None else "/" + namespace.strip("/")
    wanted = {_full(ns, n): ty for n, ty in TOPIC_TYPES.items()}
    for name in REQUIRED_TOPICS:
        topic = _full(ns, name)
        if topic not in available:
            raise BagError(f"{file}: no {topic} topic ({TOPIC_TYPES[name]}); the bag has "
                           f"{', '.join(sorted(available)) or 'no topics'}")
    for topic, ty in wanted.items():
        if topic in available and available[topic] != ty:
            raise BagError(f"{file}: {topic} has type {available[topic]}, expected {ty}")
    contents, rec = _read_records(file, [t for t in wanted if t in available], ns)
    info = _run_info(contents, rec)
    notes: list[str] = []
    if rec.duplicates:
        notes.append(f"state messages with a repeated stamp ignored (first kept): {rec.duplicates}")

    scen_name = scenario or str(info.get("scenario") or "")
    run_cfg = cfg
    if scen_name:
        try:
            run_cfg = cfg.for_scenario(cfg.scenario(scen_name))
        except ConfigError:
            notes.append(f"scenario {scen_name!r} is not in {cfg.source}: slack weights from the config")
    else:
        scen_name = file.stem
        notes.append("scenario not recorded: named after the file")
    steps_recorded = info.get("steps")
    max_steps = int(steps_recorded) if isinstance(steps_recorded, (int, float)) and not isinstance(
        steps_recorded, bool) and steps_recorded >= 1 else None
    stamps, cmd_used = _pair_steps(rec, file, max_steps)
    n = len(cmd_used)
    if max_steps is not None and n < max_steps and not contents.truncated:
        notes.append(f"the run has {n} of its {max_steps} steps (the plant stopped early)")
    held = sum(1 for s, c in zip(stamps, cmd_used) if s != c)
    if held:
        notes.append(f"steps without a command of their state's stamp: {held} (the latest earlier one was taken: "
                     "zero-order hold)")

    # commands: the torque the plant applied (torque_applied) where recorded, else torque_cmd
    applied = [rec.torque_applied.get(c) for c in cmd_used]
    from_cmd = sum(a is None for a in applied)
    if rec.torque_applied and from_cmd:
        notes.append(f"steps without torque_applied: {from_cmd} (torque_cmd taken)")
    tau = np.array([a if a is not None else rec.torque_cmd[c] for a, c in zip(applied, cmd_used)])
    overridden = sum(a is not None and c in rec.torque_cmd and not np.array_equal(a, rec.torque_cmd[c])
                     for a, c in zip(applied, cmd_used))
    if overridden:
        notes.append(f"steps where the plant applied another torque than torque_cmd: {overridden} (real-time "
                     "deadline misses: held or zero torque); the series use what it applied")
    plant = spacecraft.plant_record(run_cfg)
    u = spacecraft.saturated(spacecraft.torque_to_wheels(tau, plant), plant)  # what the actuator applied
    des_missing = sum(c not in rec.torque_des for c in cmd_used)
    if des_missing:
        notes.append(f"steps without torque_des: {des_missing} (u_des taken as the applied command)")
    tau_des = np.array([rec.torque_des.get(c, t) for c, t in zip(cmd_used, tau)])
    u_des = spacecraft.torque_to_wheels(tau_des, plant)

    t_ns = np.array(stamps, dtype=np.int64)  # sorted, distinct
    dt_steps = np.diff(t_ns) / NS_PER_S  # (N,)
    epoch = _epoch_ns(info, run_cfg, scen_name, stamps[0])
    t_s = (t_ns - epoch) / NS_PER_S
    x = np.array([rec.states[s] for s in stamps])
    y = None
    if rec.true_states:  # sensor errors: safety is judged on the truth; the filter read `state`
        if all(s in rec.true_states for s in stamps):
            y = x
            x = np.array([rec.true_states[s] for s in stamps])
            err = np.abs(y - x).max(axis=0)
            notes.append(f"safety judged on the true state ({STATE_TRUE_TOPIC}); the controller and the filter "
                         f"read {STATE_TOPIC} (largest error: omega {err[4:7].max():.3g} rad/s, psi "
                         f"{err[7:10].max():.3g} rad/s, T {err[10]:.3g} K, E {err[11]:.3g} J)")
        else:
            notes.append(f"{STATE_TRUE_TOPIC} does not cover every step: safety judged on {STATE_TOPIC} (measured)")

    # re-integrate every step with the plant's own integrator: its substeps, exactly (with a transport delay,
    # the previous step's command over the delay, as the plant held it)
    constraints = ConstraintSet(run_cfg)
    x_end = np.empty((n, STATE_SIZE))
    subs = np.empty((run_cfg.substeps, n, STATE_SIZE))
    for k in range(n):
        x_end[k], subs[:, k] = spacecraft.integrate(x[k], u[k], float(dt_steps[k]), plant, run_cfg.substeps,
                                                    u[k - 1] if k > 0 else None)
    residual = float(np.max(np.abs(x_end - x[1:]) / np.maximum(1.0, np.abs(x[1:]))))
    if residual > RESIDUAL_TOLERANCE:
        notes.append(f"re-integrating the recorded commands does not reproduce the recorded states (largest "
                     f"relative difference {residual:.3g}): minima between samples are estimates")
    h = constraints.safety_values(x, t_s)
    S = run_cfg.substeps
    t_sub = t_s[:-1] + dt_steps * np.arange(1, S + 1)[:, None] / S  # (S, N): each substep's time
    h_min, h_arg = substep_minima(h[:-1], constraints.safety_values(subs, t_sub), t_s[:-1], dt_steps)
    omega_dot = spacecraft.omega_dot(x[:-1], u, plant)

    # filter records
    m = len(constraints.names)
    rta = bool(rec.status) or info.get("rta") is True
    slack, inter = np.zeros((n, m)), np.zeros((n, m), dtype=bool)
    box = np.zeros((n, 3), dtype=bool)
    status = np.full(n, "missing" if rta else "off", dtype=object)
    fallback = np.full(n, "", dtype=object)
    solve = np.zeros(n)
    preset = str(info["preset"]) if info.get("preset") else None
    slacked_recorded: set[str] = set()
    status_missing = 0
    for k, c in enumerate(cmd_used):
        st = rec.status.get(c)
        if st is None:
            status_missing += rta
            continue
        top = st.get(topics.QP_STATUS_NAME, {})
        try:
            status[k] = top.get(topics.KEY_STATUS, "missing")
            fb = top.get(topics.KEY_FALLBACK, "")
            fallback[k] = "" if fb in ("", topics.NO_FALLBACK) else fb
            solve[k] = float(top.get(topics.KEY_SOLVE_TIME, "0"))
            if preset is None and top.get(topics.KEY_PRESET):
                preset = top[topics.KEY_PRESET]
            for a, axis in enumerate(AXES):
                box[k, a] = _flag(top.get(f"{topics.KEY_BOX_ACTIVE}_{axis}"))
            for i, name in enumerate(constraints.names):
                entry = st.get(topics.CONSTRAINT_STATUS_PREFIX + name)
                if entry is None:
                    continue
                slack[k, i] = float(entry.get(topics.KEY_SLACK, "0"))
                inter[k, i] = _flag(entry.get(topics.KEY_INTERVENING))
                if _flag(entry.get(topics.KEY_SLACKED)):
                    slacked_recorded.add(name)
        except ValueError:
            raise BagError(f"{file}: the filter_status at t = {c / NS_PER_S:.3f} s has a non-numeric "
                           f"{topics.KEY_SOLVE_TIME} or {topics.KEY_SLACK}") from None
    if status_missing:
        notes.append(f"steps without filter_status: {status_missing} (counted as status 'missing')")
    if rta and preset is None:
        preset = run_cfg.filter.preset
        notes.append(f"filter preset not recorded: taken from the config ({preset})")

    slacked = tuple(c for c in constraints.names if c in slacked_recorded) if slacked_recorded \
        else run_cfg.slacked_constraints
    last = rec.status[max(rec.status)].get(topics.QP_STATUS_NAME, {}) if rec.status else {}
    input_counts = {k: int(last[k]) for k in (*topics.INPUT_COUNTERS, "calls") if last.get(k, "").isdigit()}
    run = BagRun(
        path=file, namespace=ns, names=constraints.names, t_s=t_s, x=x, u_des=u_des, u=u, omega_dot=omega_dot,
        h=h, h_substep_min=h_min, h_substep_argmin_s=h_arg, slack=slack, intervening=inter, box_active=box,
        status=status.astype(str), fallback=fallback.astype(str), solve_time_s=solve, slacked=slacked, rta=rta,
        preset=preset if rta else None, scenario=scen_name, dt_s=float(np.median(dt_steps)),
        truncated=contents.truncated, data_end_s=float(t_s[-1]), reintegration_residual=residual,
        topic_types={t: available[t] for t in wanted if t in available}, counts=dict(contents.counts), notes=notes,
        run_facts={k: info[k] for k in RUN_FACTS if k in info}, y=y, input_counts=input_counts,
        rejection=last.get(topics.REJECTION_KEY, ""),
    )  # fmt: skip
    log.debug("read %s: %d steps in %.2f s", file, n, time.perf_counter() - t_start)
    return run


__all__ = [
    "DEFAULT_NAMESPACE", "TOPIC_TYPES", "BagRun", "find_namespace", "load_run", "parse_diagnostics", "resolve_bag_path",
]  # fmt: skip
