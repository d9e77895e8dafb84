"""Messages <-> numpy at the node boundary, with validation. No physics here: where a view needs a
rotation or the sun direction, it calls the core.

Builders return rclpy message objects. Parsers take any object with the message's attributes, so
they read rclpy messages and the objects that mcap_ros2 decodes from a bag alike, and raise
`MessageError` (one line naming what is wrong) on malformed input.

Floats in DiagnosticStatus values are written with `repr`, which round-trips float64 exactly.

One module because each message the run reads back has its builder and its parser side by side
(state, torques, filter_status, run_status), so a layout and the code that reads it change together;
it is also the one module that imports the message packages directly.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import BatteryState, JointState, Temperature

from rta_attitude import topics
from rta_attitude.config.loader import CELSIUS_OFFSET_K
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import AXES, CW, ENERGY, OMEGA, STATE_NAMES, STATE_SIZE, TEMP, THETA_S, Q
from rta_attitude.errors import MessageError
from rta_attitude.filter.asif import FilterCounters, FilterResult

Array = NDArray[np.float64]
NS_PER_S = 1_000_000_000
UNIT_NORM_EPS = 1e-12
"""A quaternion whose norm is this close to 1 counts as unit and is left unchanged (the plant renormalises
after every RK4 substep, so its states are within a few ulp; dividing again would change bits and break the
lockstep identity with the in-process run). Further off, within the nodes' `quaternion_tolerance`, it is
renormalised and counted."""
_STATE_NAME_LIST = list(STATE_NAMES)

# ----------------------------------------------------------------------------- time


def seconds_to_ns(t_s: float) -> int:
    """Sim time [s] -> integer nanoseconds (rounded)."""
    return round(t_s * NS_PER_S)


def stamp(ns: int) -> Time:
    """builtin_interfaces/Time of a time in ns >= 0."""
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp_ns(stamp_msg: Any) -> int:
    """Nanoseconds of a Time (sec >= 0, 0 <= nanosec < 1e9), else MessageError."""
    sec, nanosec = stamp_msg.sec, stamp_msg.nanosec
    if sec < 0 or not 0 <= nanosec < NS_PER_S:
        raise MessageError(f"stamp {sec}.{nanosec:09d} is not a time >= 0")
    return sec * NS_PER_S + nanosec


def cdr_stamp_ns(data: bytes) -> int:
    """The leading builtin_interfaces/Time of a serialized message (a Header's stamp, or Clock.clock)
    read straight from the CDR bytes: 4-byte encapsulation header, then int32 sec, uint32 nanosec."""
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        raise MessageError(f"not a CDR message with a leading stamp ({len(data)} bytes)")
    sec, nanosec = struct.unpack("<iI" if data[1] == 1 else ">iI", data[4:12])
    if sec < 0 or nanosec >= NS_PER_S:
        raise MessageError(f"stamp {sec}.{nanosec:09d} is not a time >= 0")
    return sec * NS_PER_S + nanosec


# ----------------------------------------------------------------------------- state


def state_msg(x: Array, t_ns: int) -> JointState:
    """JointState of one state (19,): name = STATE_NAMES, position = values in model units."""
    msg = JointState()
    msg.header.stamp = stamp(t_ns)
    msg.name = _STATE_NAME_LIST
    msg.position = np.asarray(x, dtype=float).tolist()
    return msg


def state_from_msg(msg: Any) -> tuple[int, Array]:
    """(stamp [ns], state (19,)) of a JointState; MessageError if names, size or values are wrong."""
    t_ns = stamp_ns(msg.header.stamp)
    if len(msg.position) != STATE_SIZE:
        raise MessageError(f"state has {len(msg.position)} positions, expected {STATE_SIZE}")
    if list(msg.name) != _STATE_NAME_LIST:
        raise MessageError(f"state names must be {STATE_NAMES}, got {tuple(msg.name)[:4]}...")
    x = np.array(msg.position, dtype=float)
    if not np.all(np.isfinite(x)):
        bad = STATE_NAMES[int(np.flatnonzero(~np.isfinite(x))[0])]
        raise MessageError(f"state entry {bad} is not finite")
    return t_ns, x


# ----------------------------------------------------------------------------- vectors, torques


def vector_msg(v: Array, t_ns: int, frame_id: str) -> Vector3Stamped:
    """Vector3Stamped of a (3,) vector."""
    msg = Vector3Stamped()
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = frame_id
    msg.vector.x, msg.vector.y, msg.vector.z = (float(c) for c in v)
    return msg


def torque_msg(tau_Nm: Array, t_ns: int) -> Vector3Stamped:
    """A body torque command (3,) [N m], frame `body`."""
    return vector_msg(tau_Nm, t_ns, topics.BODY_FRAME)


def torque_from_msg(msg: Any) -> tuple[int, Array]:
    """(stamp [ns], torque (3,) [N m]) of a Vector3Stamped; frame must be `body`, values finite."""
    t_ns = stamp_ns(msg.header.stamp)
    if msg.header.frame_id != topics.BODY_FRAME:
        raise MessageError(f"torque frame_id must be {topics.BODY_FRAME!r}, got {msg.header.frame_id!r}")
    tau = np.array([msg.vector.x, msg.vector.y, msg.vector.z], dtype=float)
    if not np.all(np.isfinite(tau)):
        raise MessageError(f"torque is not finite: {tau.tolist()}")
    return t_ns, tau


def unit_quaternion(q: Array, tolerance: float, what: str = "quaternion") -> tuple[Array, bool]:
    """A quaternion (4,) checked for unit norm: (q, False) if | |q| - 1 | <= UNIT_NORM_EPS (unchanged),
    (q / |q|, True) if it is off by up to `tolerance`; MessageError beyond (or not finite)."""
    with np.errstate(over="ignore"):  # a huge but finite q: norm inf, rejected below
        norm = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else math.nan
    if not abs(norm - 1.0) <= tolerance:
        raise MessageError(f"{what} must be a unit quaternion (| |q| - 1 | <= {tolerance:g}), got norm {norm:.6g}")
    if abs(norm - 1.0) <= UNIT_NORM_EPS:
        return q, False
    return q / norm, True


def unit_attitude(x: Array, tolerance: float) -> tuple[Array, bool]:
    """A state (19,) with its quaternion checked by `unit_quaternion`: (x, renormalised?)."""
    q, renormalised = unit_quaternion(x[Q], tolerance, "state quaternion")
    if renormalised:
        x = x.copy()
        x[Q] = q
    return x, renormalised


def quaternion_from_msg(msg: Any, tolerance: float = 0.5) -> tuple[int, Array]:
    """(stamp [ns], unit quaternion (4,) scalar last) of a QuaternionStamped; | |q| - 1 | must be within
    `tolerance` (then q is renormalised), else MessageError."""
    t_ns = stamp_ns(msg.header.stamp)
    q = np.array([msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w], dtype=float)
    norm = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else math.nan
    if not abs(norm - 1.0) < tolerance:
        raise MessageError(f"attitude command must be a unit quaternion (| |q| - 1 | < {tolerance:g}), "
                           f"got norm {norm:.6g}")
    return t_ns, q / norm


# ----------------------------------------------------------------------------- plant views


def clock_msg(t_ns: int) -> Clock:
    """rosgraph_msgs/Clock at t."""
    return Clock(clock=stamp(t_ns))


def odometry_msg(x: Array, t_ns: int) -> Odometry:
    """Attitude (body in Hill: the same x y z w as q), body rates, CW position (Hill) and velocity
    (rotated into the body frame, as Odometry's twist is in child_frame_id)."""
    msg = Odometry()
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = topics.HILL_FRAME
    msg.child_frame_id = topics.BODY_FRAME
    q, w, cw = x[Q], x[OMEGA], x[CW]
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = (float(c) for c in cw[:3])
    o.x, o.y, o.z, o.w = (float(c) for c in q)
    v_body = quat.attitude_matrices(q) @ cw[3:]
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    lin.x, lin.y, lin.z = (float(c) for c in v_body)
    ang.x, ang.y, ang.z = (float(c) for c in w)
    return msg


def temperature_msg(x: Array, t_ns: int) -> Temperature:
    """The -j_B face temperature in degC."""
    msg = Temperature()
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = topics.BODY_FRAME
    msg.temperature = float(x[TEMP] - CELSIUS_OFFSET_K)
    return msg


def battery_msg(x: Array, t_ns: int, plant: NDArray[np.void], voltage_V: float) -> BatteryState:
    """Battery energy E as charge = E / (V 3600) [Ah] at a nominal voltage; current = net power / V
    (the model's panel power minus load). Capacity and percentage are unknown (NaN): the paper
    gives no capacity."""
    msg = BatteryState()
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = topics.BODY_FRAME
    msg.voltage = float(voltage_V)
    msg.charge = float(x[ENERGY] / (voltage_V * 3600.0))
    msg.current = float(spacecraft.state_derivative(x, np.zeros(3), plant)[ENERGY] / voltage_V)
    msg.capacity = msg.design_capacity = msg.percentage = math.nan
    msg.temperature = math.nan
    msg.present = True
    msg.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN
    msg.power_supply_status = (BatteryState.POWER_SUPPLY_STATUS_CHARGING if msg.current > 0
                               else BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
    return msg


def sun_vector_msg(x: Array, t_ns: int) -> Vector3Stamped:
    """Unit vector to the sun in Hill ([cos, sin, 0] of theta_S, `spacecraft.sun_hill`)."""
    cs, sn = spacecraft.sun_hill(float(x[THETA_S]))
    return vector_msg(np.array([cs, sn, 0.0]), t_ns, topics.HILL_FRAME)


# ----------------------------------------------------------------------------- diagnostics


def _text(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return str(value)


def _status(name: str, level: bytes, message: str, values: Sequence[tuple[str, Any]]) -> DiagnosticStatus:
    st = DiagnosticStatus()
    st.level, st.name, st.message, st.hardware_id = level, name, message, topics.STATUS_HARDWARE_ID
    st.values = [KeyValue(key=k, value=_text(v)) for k, v in values]
    return st


def _level_text(status: str) -> bytes:
    return DiagnosticStatus.OK if status == "pass" else DiagnosticStatus.WARN if status == "solved" \
        else DiagnosticStatus.ERROR


def _bool(v: Any) -> str:
    return "true" if v else "false"


class FilterStatusBuilder:
    """Builds filter_status messages: the `filter` entry (level OK pass, WARN solved, ERROR fallback),
    then one entry per constraint named like it (OK, WARN intervening, ERROR violated: h < 0).

    The message's ~120 KeyValue objects are made once and their values rewritten at each `build`
    (a message is serialised when published, so reusing it is safe): this runs at every step of the
    loop, and constructing the objects each time cost ~0.6 ms a message.
    """

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        hid = topics.STATUS_HARDWARE_ID
        self.msg = DiagnosticArray()
        self.qp = DiagnosticStatus(name=topics.QP_STATUS_NAME, hardware_id=hid)
        self.qp.values = [KeyValue(key=k) for k in list(topics.QP_KEYS)]
        self.per = []
        for name in self.names:
            st = DiagnosticStatus(name=topics.CONSTRAINT_STATUS_PREFIX + name, hardware_id=hid)
            st.values = [KeyValue(key=k) for k in topics.CONSTRAINT_KEYS]
            self.per.append(st)
        self.msg.status = [self.qp, *self.per]

    def build(self, res: FilterResult, t_ns: int, counters: FilterCounters, preset: str, slacked: Sequence[str],
              inputs: Mapping[str, int] | None = None, source: str = "torque_des") -> DiagnosticArray:
        """The message of one filter result (the builder's message object, rewritten).

        Args:
            inputs: the node's input counters (topics.INPUT_COUNTERS; missing ones are 0).
            source: where u_des came from ('torque_des', or 'missing': u_des = 0 after a timeout).
        """
        inputs = inputs or {}
        r = res.record
        status, fallback = str(res.status), str(res.fallback)
        u_des, u, box = r["u_des"].tolist(), r["u"].tolist(), r["box_active"].tolist()
        texts = [
            status, str(res.solver_status), str(int(r["iterations"])), fallback or topics.NO_FALLBACK,
            repr(float(r["solve_time_s"])), preset, *map(repr, u_des), *map(repr, u), *map(_bool, box),
            str(counters.calls), str(counters.fast_path), str(counters.solved), str(counters.fallbacks),
            str(counters.solver_failures), str(counters.backup_solves), str(counters.invalid_states), source,
            *(str(inputs.get(k, 0)) for k in topics.INPUT_COUNTERS), str(res.gate), str(res.gave_way),
        ]  # fmt: skip
        for kv, text in zip(self.qp.values, texts, strict=True):
            kv.value = text
        self.qp.level = _level_text(status)
        self.qp.message = status + (f" ({fallback})" if fallback else "")
        h, psi0, psi1, bc, slack = (r[k].tolist() for k in ("h", "psi0", "psi1", "bc", "slack"))
        inter_all, unctl = r["intervening"].tolist(), r["uncontrollable"].tolist()
        for i, st in enumerate(self.per):
            violated, inter = h[i] < 0, bool(inter_all[i])
            st.level = DiagnosticStatus.ERROR if violated else DiagnosticStatus.WARN if inter else DiagnosticStatus.OK
            st.message = "violated" if violated else "intervening" if inter else "ok"
            kv = st.values
            kv[0].value, kv[1].value, kv[2].value = repr(h[i]), repr(psi0[i]), repr(psi1[i])
            kv[3].value, kv[4].value = repr(bc[i]), repr(slack[i])
            kv[5].value, kv[6].value = _bool(inter), _bool(unctl[i])
            kv[7].value = _bool(self.names[i] in slacked)
        self.msg.header.stamp = stamp(t_ns)
        return self.msg


def filter_status_msg(res: FilterResult, t_ns: int, counters: FilterCounters, preset: str,
                      slacked: Sequence[str], inputs: Mapping[str, int] | None = None,
                      source: str = "torque_des") -> DiagnosticArray:
    """One filter_status message (a new object; the filter node reuses a `FilterStatusBuilder`)."""
    return FilterStatusBuilder(res.names).build(res, t_ns, counters, preset, slacked, inputs, source)


def _value(text: str) -> Any:
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def diagnostic_values(msg: Any) -> dict[str, dict[str, Any]]:
    """{status name: {key: value}} of a DiagnosticArray; values parsed back to bool/int/float/str
    and `message` under the key '_message'."""
    out: dict[str, dict[str, Any]] = {}
    for st in msg.status:
        values = {kv.key: _value(kv.value) for kv in st.values}
        values["_message"] = st.message
        out[st.name] = values
    return out


def filter_record(msg: Any, names: Sequence[str]) -> dict[str, Any]:
    """One filter_status as arrays: h, psi0, psi1, bc, slack (m,) floats; intervening,
    uncontrollable, slacked (m,) bools, in the order of `names`; box_active (3,); u_des, u (3,)
    rad/s^2; status, solver_status, fallback ('' if none), preset (str); iterations (int);
    solve_time_s (float).

    Raises:
        MessageError: a constraint or key is missing.
    """
    values = diagnostic_values(msg)
    qp = values.get(topics.QP_STATUS_NAME)
    if qp is None:
        raise MessageError(f"filter_status has no {topics.QP_STATUS_NAME!r} entry")
    try:
        fallback = str(qp["fallback"])
        rec: dict[str, Any] = {
            "status": str(qp["status"]), "solver_status": str(qp["solver_status"]),
            "fallback": "" if fallback == topics.NO_FALLBACK else fallback, "preset": str(qp["preset"]),
            "iterations": int(qp["iterations"]), "solve_time_s": float(qp["solve_time_s"]),
            "u_des": np.array([qp[f"u_des_{a}"] for a in AXES], dtype=float),
            "u": np.array([qp[f"u_{a}"] for a in AXES], dtype=float),
            "box_active": np.array([qp[f"box_active_{a}"] for a in AXES], dtype=bool),
        }  # fmt: skip
        per = [values[topics.CONSTRAINT_STATUS_PREFIX + n] for n in names]
        for key in ("h", "psi0", "psi1", "bc", "slack"):
            rec[key] = np.array([p[key] for p in per], dtype=float)
        for key in ("intervening", "uncontrollable", "slacked"):
            rec[key] = np.array([p[key] for p in per], dtype=bool)
    except KeyError as exc:
        raise MessageError(f"filter_status lacks {exc.args[0]!r}") from None
    if not rec["status"]:
        raise MessageError("filter_status has an empty QP status")
    return rec


def run_status_msg(t_ns: int, state: str, values: Mapping[str, Any]) -> DiagnosticArray:
    """run_status: one `plant/run` entry, message = state (running, done, failed: ...)."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp(t_ns)
    level = DiagnosticStatus.ERROR if state.startswith(topics.RUN_FAILED) else DiagnosticStatus.OK
    msg.status = [_status(topics.RUN_STATUS_NAME, level, state, list(values.items()))]
    return msg


def run_status_from_msg(msg: Any) -> tuple[str, dict[str, Any]]:
    """(state, values) of a run_status message; MessageError if it has no `plant/run` entry."""
    values = diagnostic_values(msg).get(topics.RUN_STATUS_NAME)
    if values is None:
        raise MessageError(f"run_status has no {topics.RUN_STATUS_NAME!r} entry")
    return str(values.pop("_message")), values


__all__ = [
    "NS_PER_S", "UNIT_NORM_EPS", "FilterStatusBuilder", "battery_msg", "cdr_stamp_ns", "clock_msg",
    "diagnostic_values", "filter_record", "filter_status_msg", "odometry_msg", "quaternion_from_msg",
    "run_status_from_msg", "run_status_msg",
    "seconds_to_ns", "stamp", "stamp_ns", "state_from_msg", "state_msg", "sun_vector_msg", "temperature_msg",
    "torque_from_msg", "torque_msg", "unit_attitude", "unit_quaternion", "vector_msg",
]  # fmt: skip
