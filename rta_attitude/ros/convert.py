"""Messages <-> numpy at the node boundary, with validation. No physics here: where a view needs a
rotation or the sun direction, it calls the core.

Builders return rclpy message objects; the loop's per-step messages are also written straight into CDR
bytes (`CdrLayout`, `FilterStatusBuilder.build_cdr`), which is what the nodes publish. Parsers take any
object with the message's attributes, so they read rclpy messages and the objects that mcap_ros2 decodes
from a bag alike (the loop's parsers also the CDR bytes of a raw subscription), and raise `MessageError`
(one line naming what is wrong) on malformed input.

Floats in DiagnosticStatus values are written with `repr`, which round-trips float64 exactly.

One module because each message the run reads back has its builder and its parser side by side
(state, torques, filter_status, run_status), so a layout and the code that reads it change together;
it is also the one module that imports the message packages directly (the scene's messages too:
`SceneBuilder`).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, TransformStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import BatteryState, JointState, Temperature
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from rta_attitude import topics
from rta_attitude.config.schema import PointingConstraint
from rta_attitude.dynamics.sensors import (
    F_CHARGE_AH,
    F_OMEGA,
    F_POS,
    F_Q,
    F_SUN,
    F_TEMP_C,
    F_VEL_BODY,
    F_WHEEL,
    FIELD_MESSAGES,
    FIELD_SIZE,
)
from rta_attitude.dynamics.state import AXES, STATE_NAMES, STATE_SIZE, Q
from rta_attitude.errors import MessageError
from rta_attitude.filter.asif import FilterCounters, FilterResult
from rta_attitude.recording.scene import Scene, margin_level, target_owners

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


def cdr_stamp_ns(data: bytes, offset: int = 0) -> int:
    """The leading builtin_interfaces/Time of a serialized message (a Header's stamp, or Clock.clock)
    read straight from the CDR bytes: 4-byte encapsulation header, then int32 sec, uint32 nanosec;
    `offset` bytes after the encapsulation header (STAMP_OFFSETS: a MarkerArray's first marker)."""
    if len(data) < 12 + offset or data[0] != 0 or data[1] not in (0, 1):
        raise MessageError(f"not a CDR message with a leading stamp ({len(data)} bytes)")
    sec, nanosec = struct.unpack("<iI" if data[1] == 1 else ">iI", data[4 + offset:12 + offset])
    if sec < 0 or nanosec >= NS_PER_S:
        raise MessageError(f"stamp {sec}.{nanosec:09d} is not a time >= 0")
    return sec * NS_PER_S + nanosec


STAMP_OFFSETS: dict[str, int] = {"visualization_msgs/msg/MarkerArray": 4}
"""Where a type without a leading header keeps its stamp, for `cdr_stamp_ns`: a MarkerArray starts with
its uint32 marker count, then the first marker's header (the scene node stamps every marker alike)."""


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


class FrameError(MessageError):
    """A message in another frame than its topic's; `frame_id` is the one it carried."""

    def __init__(self, what: str, expected: str, frame_id: str) -> None:
        super().__init__(f"{what} frame_id must be {expected!r}, got {frame_id!r}")
        self.frame_id = frame_id


def _frame(msg: Any, what: str, frame_id: str) -> None:
    if msg.header.frame_id != frame_id:
        raise FrameError(what, frame_id, str(msg.header.frame_id))


def torque_from_msg(msg: Any) -> tuple[int, Array]:
    """(stamp [ns], torque (3,) [N m]) of a Vector3Stamped (a message, or its CDR bytes as a raw subscription
    takes them); frame must be `body`, values finite."""
    got, msg = _read(layouts().torque, msg)
    if got is not None:
        t_ns, tau = got[0], np.array(got[1][0])
    else:
        t_ns = stamp_ns(msg.header.stamp)
        _frame(msg, "torque", topics.BODY_FRAME)
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


def _header(msg: Any, t_ns: int, frame_id: str) -> None:
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = frame_id


def odometry_msg(f: Array, t_ns: int) -> Odometry:
    """Attitude (body in Hill: the same x y z w as q), body rates, CW position (Hill) and velocity (body
    frame, as Odometry's twist is in child_frame_id) of the message fields f (`sensors.encode`)."""
    msg = Odometry()
    _header(msg, t_ns, topics.HILL_FRAME)
    msg.child_frame_id = topics.BODY_FRAME
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = (float(c) for c in f[F_Q:F_Q + 4])
    p.x, p.y, p.z = (float(c) for c in f[F_POS:F_POS + 3])
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    lin.x, lin.y, lin.z = (float(c) for c in f[F_VEL_BODY:F_VEL_BODY + 3])
    ang.x, ang.y, ang.z = (float(c) for c in f[F_OMEGA:F_OMEGA + 3])
    return msg


def wheels_msg(f: Array, t_ns: int, effort_Nm: Array, names: Sequence[str] = topics.WHEEL_JOINTS) -> JointState:
    """The reaction wheels as joints named as configured (`Spacecraft.wheel_names`; the paper's
    `topics.WHEEL_JOINTS`): velocity = rotor speed [rad/s] (fields f), effort = the motor torque on each rotor over
    the hold that ended at t [N m]; no position (the rotors' angles are not modelled)."""
    msg = JointState()
    _header(msg, t_ns, topics.BODY_FRAME)
    msg.name = list(names)
    msg.velocity = [float(c) for c in f[F_WHEEL:F_WHEEL + 3]]
    msg.effort = [float(c) for c in effort_Nm]
    return msg


def temperature_msg(f: Array, t_ns: int) -> Temperature:
    """The -j_B face temperature in degC (fields f); variance 0 (unknown)."""
    msg = Temperature()
    _header(msg, t_ns, topics.BODY_FRAME)
    msg.temperature = float(f[F_TEMP_C])
    return msg


def battery_msg(f: Array, t_ns: int, voltage_V: float, current_A: float) -> BatteryState:
    """Battery energy as charge = E / (V 3600) [Ah] at the nominal voltage (fields f; exact: the field is
    already a float32); current = net power / V. Capacity and percentage are unknown (NaN): the paper
    gives no capacity."""
    msg = BatteryState()
    _header(msg, t_ns, topics.BODY_FRAME)
    msg.voltage = float(voltage_V)
    msg.charge = float(f[F_CHARGE_AH])
    msg.current = float(current_A)
    msg.capacity = msg.design_capacity = msg.percentage = math.nan
    msg.temperature = math.nan
    msg.present = True
    msg.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN
    msg.power_supply_status = (BatteryState.POWER_SUPPLY_STATUS_CHARGING if current_A > 0
                               else BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
    return msg


def sun_vector_msg(f: Array, t_ns: int) -> Vector3Stamped:
    """Unit vector to the sun in Hill (fields f: [cos, sin, 0] of theta_S)."""
    return vector_msg(f[F_SUN:F_SUN + 3], t_ns, topics.HILL_FRAME)


def state_messages(f: Array, t_ns: int, voltage_V: float, current_A: float, effort_Nm: Array,
                   wheel_names: Sequence[str] = topics.WHEEL_JOINTS) -> dict[str, Any]:
    """The messages of `topics.STATE_INPUTS` that carry one state's fields f (`sensors.encode`), by topic."""
    return {topics.ODOMETRY: odometry_msg(f, t_ns), topics.WHEELS: wheels_msg(f, t_ns, effort_Nm, wheel_names),
            topics.TEMPERATURE: temperature_msg(f, t_ns), topics.BATTERY: battery_msg(f, t_ns, voltage_V, current_A),
            topics.SUN_VECTOR: sun_vector_msg(f, t_ns)}


def state_messages_cdr(f: Array, t_ns: int, voltage_V: float, current_A: float, effort_Nm: Array,
                       wheel_names: Sequence[str] = topics.WHEEL_JOINTS) -> dict[str, bytes]:  # fmt: skip
    """`state_messages` serialized (`CdrLayout`): the same bytes rclpy makes of those messages, by topic."""
    L = layouts()
    status = (BatteryState.POWER_SUPPLY_STATUS_CHARGING if current_A > 0
              else BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
    fl = f.tolist()
    return {topics.ODOMETRY: L.odometry.pack(t_ns, fl[F_Q:F_Q + 4], fl[F_POS:F_POS + 3],
                                             fl[F_VEL_BODY:F_VEL_BODY + 3], fl[F_OMEGA:F_OMEGA + 3]),
            topics.WHEELS: L.wheels_named(wheel_names).pack(t_ns, fl[F_WHEEL:F_WHEEL + 3],
                                                            [float(c) for c in effort_Nm]),
            topics.TEMPERATURE: L.temperature.pack(t_ns, (fl[F_TEMP_C],)),
            topics.BATTERY: L.battery.pack(t_ns, (float(voltage_V),), (float(current_A), fl[F_CHARGE_AH]), (status,)),
            topics.SUN_VECTOR: L.sun.pack(t_ns, fl[F_SUN:F_SUN + 3])}


def state_cdr(x: Array, t_ns: int) -> bytes:
    """`state_msg` serialized (`CdrLayout`)."""
    return layouts().state.pack(t_ns, np.asarray(x, dtype=float).tolist())


def torque_cdr(tau_Nm: Array, t_ns: int) -> bytes:
    """`torque_msg` serialized (`CdrLayout`)."""
    return layouts().torque.pack(t_ns, [float(c) for c in tau_Nm])


def clock_cdr(t_ns: int) -> bytes:
    """`clock_msg` serialized (`CdrLayout`)."""
    return layouts().clock.pack(t_ns)


ODOMETRY_FIELDS = tuple(name for name in FIELD_MESSAGES if name.startswith("Odometry."))
"""The fields an Odometry carries (`odometry_fields` checks them)."""
_ODOMETRY_SPAN = slice(min(FIELD_MESSAGES[n][0] for n in ODOMETRY_FIELDS),
                       max(sum(FIELD_MESSAGES[n]) for n in ODOMETRY_FIELDS))
assert _ODOMETRY_SPAN.stop - _ODOMETRY_SPAN.start == sum(FIELD_MESSAGES[n][1] for n in ODOMETRY_FIELDS)


def odometry_fields(msg: Any, out: Array) -> None:
    """Attitude, rates, CW position and velocity of an Odometry (a message or its CDR bytes) into the fields
    out (`sensors.decode`'s layout); MessageError if its frames are not hill -> body."""
    got, msg = _read(layouts().odometry, msg)
    if got is not None:
        out[F_Q:F_Q + 4], out[F_POS:F_POS + 3], out[F_VEL_BODY:F_VEL_BODY + 3], out[F_OMEGA:F_OMEGA + 3] = got[1]
    else:
        _frame(msg, "odometry", topics.HILL_FRAME)
        if msg.child_frame_id != topics.BODY_FRAME:
            raise MessageError(f"odometry child_frame_id must be {topics.BODY_FRAME!r}, got {msg.child_frame_id!r}")
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
        out[F_Q:F_Q + 4] = (o.x, o.y, o.z, o.w)
        out[F_POS:F_POS + 3] = (p.x, p.y, p.z)
        out[F_VEL_BODY:F_VEL_BODY + 3] = (lin.x, lin.y, lin.z)
        out[F_OMEGA:F_OMEGA + 3] = (ang.x, ang.y, ang.z)
    if not np.isfinite(out[_ODOMETRY_SPAN]).all():  # one check on the loop's path; the name only on failure
        for name in ODOMETRY_FIELDS:
            i, k = FIELD_MESSAGES[name]
            if not np.all(np.isfinite(out[i:i + k])):
                raise MessageError(f"{name} is not finite")


def _read(layout: CdrLayout, msg: Any) -> tuple[tuple[int, list[tuple[Any, ...]]] | None, Any]:
    """((stamp, the slots' values), None) of CDR bytes in the layout (`CdrLayout.unpack`); else (None, the
    message: deserialized by rclpy if bytes of another layout, MessageError if not a message of that type)."""
    if not isinstance(msg, bytes):
        return None, msg
    got = layout.unpack(msg)
    return (got, None) if got is not None else (None, layout.message(msg))


_VIEWS: tuple[tuple[str, str, str, str, slice, Callable[[Any], Any], Callable[[Any], Any]], ...] = (
    (topics.TEMPERATURE, "temperature", "temperature", topics.BODY_FRAME, slice(F_TEMP_C, F_TEMP_C + 1),
     lambda v: v[0], lambda m: m.temperature),
    (topics.BATTERY, "battery", "battery", topics.BODY_FRAME, slice(F_CHARGE_AH, F_CHARGE_AH + 1),
     lambda v: v[1][1], lambda m: m.charge),
    (topics.SUN_VECTOR, "sun", "sun vector", topics.HILL_FRAME, slice(F_SUN, F_SUN + 3),
     lambda v: v[0], lambda m: (m.vector.x, m.vector.y, m.vector.z)),
)
"""The state views read by `state_fields` alike: (topic, its `Layouts` attribute, name in errors, frame_id,
where in the fields, the value from the layout's slots, the value from a message)."""


def state_fields(msgs: Mapping[str, Any], wheel_names: Sequence[str] = topics.WHEEL_JOINTS) -> Array:
    """The message fields (FIELD_SIZE,) of one state from its `topics.STATE_INPUTS` messages (by topic),
    for `sensors.decode`; the wheels' joints are wheel_names, in order. MessageError (one line) if a frame, a joint
    name or a size is wrong, or a value is not finite."""
    f = np.empty(FIELD_SIZE)
    odometry_fields(msgs[topics.ODOMETRY], f)
    L = layouts()
    got, wheels = _read(L.wheels_named(wheel_names), msgs[topics.WHEELS])
    if got is not None:
        f[F_WHEEL:F_WHEEL + 3] = got[1][0]
    else:
        _frame(wheels, "wheels", topics.BODY_FRAME)
        if list(wheels.name) != list(wheel_names) or len(wheels.velocity) != 3:
            raise MessageError(f"wheels must be joints {tuple(wheel_names)} with a velocity each, got "
                               f"{tuple(wheels.name)} with {len(wheels.velocity)} velocities")
        f[F_WHEEL:F_WHEEL + 3] = wheels.velocity
    for topic, layout, what, frame, at, from_bytes, from_msg in _VIEWS:
        got, msg = _read(getattr(L, layout), msgs[topic])
        if got is not None:
            f[at] = from_bytes(got[1])
        else:
            _frame(msg, what, frame)
            f[at] = from_msg(msg)
    if not np.all(np.isfinite(f)):
        names = [n for n, (i, k) in FIELD_MESSAGES.items() if not np.all(np.isfinite(f[i:i + k]))]
        raise MessageError(f"{names[0]} is not finite")
    return f


# ----------------------------------------------------------------------------- fixed layouts (the loop's bytes)

_STAMP = struct.Struct("<iI")


def _sentinels(fmt: str, first: int) -> tuple[float, ...]:
    """Values no real field holds, one per item of a struct format ('3d', 'f', ...), numbered from `first`:
    large float64 (or float32-exact) numbers that occur nowhere else in a serialized message."""
    n, code = int(fmt[:-1] or 1), fmt[-1]
    big = 1.0e300 if code == "d" else 3.0e38
    vals = tuple(big / (7 + first + i) for i in range(n))
    return vals if code == "d" else struct.unpack(f"<{n}f", struct.pack(f"<{n}f", *vals))


_CDR_SIZES = {"double": 8, "float": 4, "int64": 8, "uint64": 8, "int32": 4, "uint32": 4, "int16": 2, "uint16": 2,
              "int8": 1, "uint8": 1, "char": 1, "octet": 1, "boolean": 1}


def cdr_spans(msg: Any) -> tuple[int, list[tuple[int, int]], list[tuple[int, int]]]:
    """Where a message's items lie in its little-endian CDR (offsets from the start of the serialized bytes,
    the 4-byte encapsulation header included), walked from its type (rosidl SLOT_TYPES): (size, the spans that
    fix the layout: every string with its length and NUL, every sequence's count; the spans of the values).
    The bytes in neither are alignment padding, which rclpy's serializer leaves as it finds them."""
    from rosidl_parser.definition import AbstractSequence, AbstractString, Array, BasicType, NamespacedType

    layout: list[tuple[int, int]] = []
    values: list[tuple[int, int]] = []

    def align(off: int, n: int) -> int:
        return 4 + -(-(off - 4) // n) * n

    def item(t: Any, v: Any, off: int) -> int:
        if isinstance(t, NamespacedType):
            for name, st in zip(v.get_fields_and_field_types(), type(v).SLOT_TYPES, strict=True):
                off = item(st, getattr(v, name), off)
            return off
        if isinstance(t, BasicType):
            n = _CDR_SIZES[t.typename]
            off = align(off, n)
            values.append((off, off + n))
            return off + n
        if isinstance(t, AbstractString):
            off = align(off, 4)
            end = off + 4 + len(v.encode()) + 1
            layout.append((off, end))
            return end
        if isinstance(t, (AbstractSequence, Array)):
            if isinstance(t, AbstractSequence):
                off = align(off, 4)
                layout.append((off, off + 4))
                off += 4
            for e in v:
                off = item(t.value_type, e, off)
            return off
        raise TypeError(f"cdr_spans: {type(t).__name__} is not handled")

    size = item(NamespacedType([], type(msg).__name__), msg, 4)
    return size, layout, values


class CdrLayout:
    """One message type whose frame ids and sequence lengths are fixed (the plant's state views, the
    torque commands, /clock): serialized once by rclpy into a template, then written and read as bytes.

    The loop sends ~12 such messages a step, and through rclpy each is a Python object built field by field,
    then converted by rclpy's C layer, and each received one is converted back into an object: in the
    lockstep loop that Python work was most of the nodes' CPU beyond what DDS itself costs. `pack` copies the
    template and writes the stamp and the slots' values at offsets found once (by serializing sentinel
    values, cross-checked against the offsets `cdr_spans` walks from the type); `unpack` reads them back from
    bytes that have the template's layout (little-endian, the same length, every string and sequence length
    equal: frame ids, joint names; then every value sits where the template has it) and returns None for
    anything else (another writer's frame id or joints, big-endian data), which the callers then deserialize
    through rclpy and parse as before, with the same errors. Values no reader uses (covariances, constants)
    and the padding are not compared. Tests: rclpy and rosbags decode `pack`'s bytes as the builders'
    messages; `unpack` reads rclpy's bytes as the parsers read the messages.

    Args:
        make: a new message with the fixed fields set (frame ids, names, sequence lengths, constants).
        slots: name -> (struct format of its consecutive fields, e.g. '4d'; a setter writing values into a
            message), in the order `pack` takes and `unpack` returns them.
    """

    def __init__(self, make: Callable[[], Any], slots: Mapping[str, tuple[str, Callable[[Any, Sequence[Any]], None]]]
                 ) -> None:  # fmt: skip
        from rclpy.serialization import serialize_message  # here: this module is read without rclpy (bags)

        probe, plain = make(), make()
        self.msg_type = type(plain)
        marks: list[tuple[struct.Struct, bytes | None, Callable[[Any, Sequence[Any]], None]]] = []
        first = 0
        for fmt, setter in slots.values():
            if fmt[-1] in "df":
                vals = _sentinels(fmt, first)
                first += len(vals)
                setter(probe, vals)
                marks.append((struct.Struct("<" + fmt), struct.pack("<" + fmt, *vals), setter))
            else:  # an integer (one uint8 here): found as the bytes that change with its value
                setter(probe, (0xC3,))
                marks.append((struct.Struct("<" + fmt), None, setter))
        stamp_of = (lambda m: m.clock) if isinstance(probe, Clock) else (lambda m: m.header.stamp)
        stamp_of(probe).sec, stamp_of(probe).nanosec = 0x5CE7F00D, 0x0A0B0C0D
        probed = bytes(serialize_message(probe))
        size, fixed, values = cdr_spans(plain)
        serialized = bytes(serialize_message(plain))
        # serialize_message's buffer may run a few bytes past the last item (DDS sends `size` bytes)
        self.longest = len(serialized)
        template = bytearray(size)  # padding zeroed: rclpy leaves whatever its buffer held
        for a, b in [(0, 4), *fixed, *values]:
            template[a:b] = serialized[a:b]
        self.template = bytes(template)
        if (len(probed) != self.longest or size > self.longest or probed[:2] != b"\x00\x01"
                or probed[4:12] != _STAMP.pack(0x5CE7F00D, 0x0A0B0C0D) or cdr_spans(probe)[1] != fixed):  # fmt: skip
            raise RuntimeError(f"{self.msg_type.__name__}: not a fixed little-endian layout with a leading stamp")
        self.slots: list[tuple[struct.Struct, int]] = []
        for st, mark, setter in marks:
            if mark is None:
                setter(probe, (0x3C,))
                changed = [i for i, (a, b) in enumerate(zip(probed, serialize_message(probe), strict=True)) if a != b]
                setter(probe, (0xC3,))
                at = changed[0] if len(changed) == st.size else -1
            else:
                at = probed.find(mark)
                at = -1 if probed.find(mark, at + 1) >= 0 else at
            if at < 0:
                raise RuntimeError(f"{self.msg_type.__name__}: a slot was not found exactly once")
            self.slots.append((st, at))
            if not any(a <= at and at + st.size <= b for a, b in _merged(values)):
                raise RuntimeError(f"{self.msg_type.__name__}: a slot is not where its type puts values")
        self.fixed = _merged([(0, 2), *fixed])
        """What makes the layout: the byte order (little-endian CDR), every string (frame ids, joint names) and
        every sequence's length. Bytes equal there put every value where the template has it."""
        self.size = size

    def pack(self, t_ns: int, *values: Sequence[Any]) -> bytes:
        """The serialized message stamped t_ns [ns] with each slot's values (in slot order)."""
        buf = bytearray(self.template)
        _STAMP.pack_into(buf, 4, *divmod(t_ns, NS_PER_S))
        for (st, at), vals in zip(self.slots, values, strict=True):
            st.pack_into(buf, at, *vals)
        return bytes(buf)

    def unpack(self, data: bytes) -> tuple[int, list[tuple[Any, ...]]] | None:
        """(stamp [ns], each slot's values) of bytes with this layout, else None; MessageError if the stamp
        is not a time >= 0."""
        if not self.size <= len(data) <= self.longest:
            return None
        template = self.template
        for a, b in self.fixed:
            if data[a:b] != template[a:b]:
                return None
        sec, nanosec = _STAMP.unpack_from(data, 4)
        if sec < 0 or nanosec >= NS_PER_S:
            raise MessageError(f"stamp {sec}.{nanosec:09d} is not a time >= 0")
        return sec * NS_PER_S + nanosec, [st.unpack_from(data, at) for st, at in self.slots]

    def message(self, data: bytes) -> Any:
        """The rclpy message of bytes of this type in any layout (for the parsers of message objects);
        MessageError if rclpy cannot deserialize them."""
        from rclpy.serialization import deserialize_message

        try:
            return deserialize_message(data, self.msg_type)
        except Exception as exc:  # rclpy raises its own error types for malformed CDR
            raise MessageError(f"not a {self.msg_type.__name__} ({len(data)} bytes): "
                               f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None


def _merged(spans: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for a, b in sorted(spans):
        if out and a == out[-1][1]:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _set(path: str, fields: str) -> Callable[[Any, Sequence[Any]], None]:
    """A slot setter: msg.<path>.<field> = value for each of `fields` (space-separated; path '' for msg)."""
    names = fields.split()

    def setter(msg: Any, vals: Sequence[Any]) -> None:
        obj = msg
        for part in path.split(".") if path else ():
            obj = getattr(obj, part)
        for name, v in zip(names, vals, strict=True):
            setattr(obj, name, v)

    return setter


def _seq(field: str) -> Callable[[Any, Sequence[Any]], None]:
    def setter(msg: Any, vals: Sequence[Any]) -> None:
        setattr(msg, field, [float(v) for v in vals])

    return setter


class Layouts:
    """The CdrLayouts of the loop's per-step messages, made once per process (`layouts()`). Each template is
    the message its object builder makes (frame ids, names, constants written once, there)."""

    def __init__(self) -> None:
        f, zero = np.zeros(FIELD_SIZE), np.zeros(3)
        self._wheels: dict[tuple[str, ...], CdrLayout] = {}
        self.clock = CdrLayout(lambda: clock_msg(0), {})
        self.state = CdrLayout(lambda: state_msg(np.zeros(STATE_SIZE), 0),
                               {"position": (f"{STATE_SIZE}d", _seq("position"))})
        self.torque = CdrLayout(lambda: torque_msg(zero, 0), {"vector": ("3d", _set("vector", "x y z"))})
        self.sun = CdrLayout(lambda: sun_vector_msg(f, 0), {"vector": ("3d", _set("vector", "x y z"))})
        self.odometry = CdrLayout(lambda: odometry_msg(f, 0), {
            "orientation": ("4d", _set("pose.pose.orientation", "x y z w")),
            "position": ("3d", _set("pose.pose.position", "x y z")),
            "linear": ("3d", _set("twist.twist.linear", "x y z")),
            "angular": ("3d", _set("twist.twist.angular", "x y z"))})
        self.wheels = self.wheels_named(topics.WHEEL_JOINTS)
        self.temperature = CdrLayout(lambda: temperature_msg(f, 0), {"temperature": ("d", _set("", "temperature"))})

        def status(msg: Any, vals: Sequence[Any]) -> None:
            msg.power_supply_status = int(vals[0])

        # voltage, temperature (NaN), current, charge are consecutive float32: one slot of three read through
        # the middle one's NaN would not be unique, so voltage and current+charge are two slots
        self.battery = CdrLayout(lambda: battery_msg(f, 0, 0.0, 0.0), {
            "voltage": ("f", _set("", "voltage")), "current_charge": ("2f", _set("", "current charge")),
            "status": ("B", status)})
        self.by_topic = {topics.ODOMETRY: self.odometry, topics.WHEELS: self.wheels,
                         topics.TEMPERATURE: self.temperature, topics.BATTERY: self.battery,
                         topics.SUN_VECTOR: self.sun, topics.STATE: self.state, topics.TORQUE_DES: self.torque,
                         topics.TORQUE_CMD: self.torque, topics.TORQUE_APPLIED: self.torque, topics.CLOCK: self.clock}
        """The layout of each of the loop's fixed-layout topics (joint_states: the paper's wheel names)."""

    def wheels_named(self, names: Sequence[str]) -> CdrLayout:
        """The joint_states layout of wheels with these names (`Spacecraft.wheel_names`), made at first use."""
        key = tuple(names)
        if key not in self._wheels:
            f, zero = np.zeros(FIELD_SIZE), np.zeros(3)
            self._wheels[key] = CdrLayout(lambda: wheels_msg(f, 0, zero, key), {
                "velocity": ("3d", _seq("velocity")), "effort": ("3d", _seq("effort"))})
        return self._wheels[key]


_LAYOUTS: list[Layouts] = []


def layouts() -> Layouts:
    """This process's `Layouts` (made at the first call: it needs rclpy, which bag readers do without)."""
    if not _LAYOUTS:
        _LAYOUTS.append(Layouts())
    return _LAYOUTS[0]


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


_Entry = tuple[bytes, str, list[str]]
"""One DiagnosticStatus's level, message and values (texts)."""


class FilterStatusBuilder:
    """Builds filter_status messages: the `filter` entry (level OK pass, WARN solved, ERROR fallback),
    then one entry per constraint named like it (OK, WARN intervening, ERROR violated: h < 0).

    This runs at every step of the loop, with ~120 KeyValues a message. `build` returns the message object
    (its KeyValue objects made once and their values rewritten: constructing them each time cost ~0.6 ms);
    `build_cdr` writes the same message straight into CDR bytes (what the filter node publishes: rclpy's
    conversion of ~250 strings from Python objects cost more than making them). A test checks that rclpy
    deserializes `build_cdr`'s bytes into `build`'s message.
    """

    def __init__(self, names: Sequence[str], wheels: str = "") -> None:
        self.names = tuple(names)
        self.wheels = wheels
        """'' with every wheel working, else what the failed wheels take away (`Spacecraft.control_lost`)."""
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
        self._hid = _cdr_text(hid)
        self._qp_name = _cdr_text(topics.QP_STATUS_NAME)
        self._qp_keys = [_cdr_text(k) for k in topics.QP_KEYS]
        self._names = [_cdr_text(topics.CONSTRAINT_STATUS_PREFIX + n) for n in self.names]
        self._keys = [_cdr_text(k) for k in topics.CONSTRAINT_KEYS]

    def _texts(self, res: FilterResult, counters: FilterCounters, preset: str, slacked: Sequence[str],
               inputs: Mapping[str, int] | None, source: str,
               rejection: str) -> tuple[bytes, str, list[str], list[_Entry]]:
        """(level, message, values) of the QP entry, then of each constraint's."""
        inputs = inputs or {}
        r = res.record
        status, fallback = str(res.status), str(res.fallback)
        u_des, u, u_held, box = r["u_des"].tolist(), r["u"].tolist(), r["u_held"].tolist(), r["box_active"].tolist()
        texts = [
            status, str(res.solver_status), str(int(r["iterations"])), fallback or topics.NO_FALLBACK,
            repr(float(r["solve_time_s"])), preset, *map(repr, u_des), *map(repr, u), *map(repr, u_held),
            *map(_bool, box),
            str(counters.calls), str(counters.fast_path), str(counters.solved), str(counters.fallbacks),
            str(counters.solver_failures), str(counters.backup_solves), str(counters.invalid_states), source,
            *(str(inputs.get(k, 0)) for k in topics.INPUT_COUNTERS), str(res.gate), str(res.gave_way), rejection,
            self.wheels or "ok",
        ]  # fmt: skip
        h, psi0, psi1, bc, slack = (r[k].tolist() for k in ("h", "psi0", "psi1", "bc", "slack"))
        inter_all, unctl = r["intervening"].tolist(), r["uncontrollable"].tolist()
        per = []
        for i, name in enumerate(self.names):
            violated, inter = h[i] < 0, bool(inter_all[i])
            level = DiagnosticStatus.ERROR if violated else DiagnosticStatus.WARN if inter else DiagnosticStatus.OK
            per.append((level, "violated" if violated else "intervening" if inter else "ok",
                        [repr(h[i]), repr(psi0[i]), repr(psi1[i]), repr(bc[i]), repr(slack[i]), _bool(inter),
                         _bool(unctl[i]), _bool(name in slacked)]))
        message = status + (f" ({fallback})" if fallback else "")
        if self.wheels:  # a failed wheel: the filter holds what it still can, and says so
            return DiagnosticStatus.ERROR, f"{self.wheels}; {message}", texts, per
        return _level_text(status), message, texts, per

    def build(self, res: FilterResult, t_ns: int, counters: FilterCounters, preset: str, slacked: Sequence[str],
              inputs: Mapping[str, int] | None = None, source: str = "torque_des",
              rejection: str = "") -> DiagnosticArray:
        """The message of one filter result (the builder's message object, rewritten).

        Args:
            inputs: the node's input counters (topics.INPUT_COUNTERS; missing ones are 0).
            source: where u_des came from ('torque_des', or 'missing': u_des = 0 after a timeout).
            rejection: why the latest rejected torque_des was rejected (topics.REJECTION_KEY; '' if none was).
        """
        level, message, texts, per = self._texts(res, counters, preset, slacked, inputs, source, rejection)
        for kv, text in zip(self.qp.values, texts, strict=True):
            kv.value = text
        self.qp.level, self.qp.message = level, message
        for st, (lv, msg, vals) in zip(self.per, per, strict=True):
            st.level, st.message = lv, msg
            for kv, text in zip(st.values, vals, strict=True):
                kv.value = text
        self.msg.header.stamp = stamp(t_ns)
        return self.msg

    def build_cdr(self, res: FilterResult, t_ns: int, counters: FilterCounters, preset: str,
                  slacked: Sequence[str], inputs: Mapping[str, int] | None = None, source: str = "torque_des",
                  rejection: str = "") -> bytes:
        """`build`'s message as little-endian CDR bytes (what rclpy would serialize, with zero padding).

        Written as a str of byte values (latin-1) and encoded once: ~130 strings a message, each a length,
        its characters, a NUL and padding. Every text here is ASCII (numbers, names, words); should one not
        be, the message goes through rclpy's serializer instead."""
        level, message, texts, per = self._texts(res, counters, preset, slacked, inputs, source, rejection)
        if not (message + "".join(texts) + "".join(m + "".join(v) for _, m, v in per)).isascii():
            from rclpy.serialization import serialize_message

            return bytes(serialize_message(self.build(res, t_ns, counters, preset, slacked, inputs, source,
                                                      rejection)))
        prefix, tail = _PREFIX, _NUL_PAD_TEXT
        parts = ["\x00\x01\x00\x00", _STAMP.pack(*divmod(t_ns, NS_PER_S)).decode("latin-1"), _cdr_text(""),
                 _u32_text(1 + len(per))]
        end = 24  # bytes so far; every status starts with its level byte right after the previous string's NUL
        for lv, name, msg, keys, vals in ((level, self._qp_name, message, self._qp_keys, texts),
                                          *((lv, n, m, self._keys, v) for n, (lv, m, v) in zip(self._names, per))):
            pad = -(end + 1 - 4) % 4
            body = [_LEVEL_TEXT[lv], _PAD_TEXT[pad], name, _cdr_text(msg), self._hid, _u32_text(len(vals))]
            for key, val in zip(keys, vals, strict=True):
                n = len(val) + 1
                body += (key, prefix[n] if n < 256 else _u32_text(n), val, tail[n & 3])
            body[-1] = "\x00"  # the last string unpadded: the next status's level byte follows it
            chunk = "".join(body)
            parts.append(chunk)
            end += len(chunk)
        return "".join(parts).encode("latin-1")


_PREFIX = tuple(n.to_bytes(4, "little").decode("latin-1") for n in range(256))
_LEVEL_TEXT = {bytes([n]): chr(n) for n in range(256)}
_PAD_TEXT = tuple("\x00" * n for n in range(4))
"""A CDR string's length field (length with the NUL, < 256) as 4 latin-1 characters."""
_NUL_PAD_TEXT = tuple("\x00" * (1 + (-n) % 4) for n in range(4))


def _u32_text(n: int) -> str:
    """A little-endian uint32 as 4 latin-1 characters."""
    return n.to_bytes(4, "little").decode("latin-1")


def _cdr_text(text: str) -> str:
    """A CDR string as latin-1 characters (text ASCII), with the padding that brings the next item to a
    multiple of 4: uint32 length (with the NUL), the characters, NUL, zeros. Inside a DiagnosticStatus every
    item after the level byte is a string or a count (4-aligned), so each is written whole; its last string
    is cut after the NUL (the next status's level byte, a uint8, follows unaligned)."""
    n = len(text) + 1
    return _u32_text(n) + text + _NUL_PAD_TEXT[n % 4]


def filter_status_msg(res: FilterResult, t_ns: int, counters: FilterCounters, preset: str,
                      slacked: Sequence[str], inputs: Mapping[str, int] | None = None,
                      source: str = "torque_des", rejection: str = "") -> DiagnosticArray:
    """One filter_status message (a new object; the filter node reuses a `FilterStatusBuilder`)."""
    return FilterStatusBuilder(res.names).build(res, t_ns, counters, preset, slacked, inputs, source, rejection)


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


# ----------------------------------------------------------------------------- scene (a view)

SCENE_NS = "rta_attitude"
"""Marker namespace of the scene; markers are replaced by (namespace, id) at every message."""
SCENE_IDS: dict[str, int] = {"body": 0, "axis_x": 1, "axis_y": 2, "axis_z": 3, "panel": 4, "text": 5}
"""Marker id of each part of the scene that does not depend on the configuration (tests and viewers find a part
by its id); the cones' parts follow (`cone_marker_ids`)."""
CONE_ID_BASE = 10
CONE_ID_STRIDE = 3
"""Pointing constraint i (its place in `constraints.pointing`) draws its boresight with id CONE_ID_BASE +
CONE_ID_STRIDE i, its cone with the next id, and, if it is the first cone aimed at its target, the target's
arrow with the one after (`cone_marker_ids`): ids that stay put while the cones' list keeps its order."""
SCENE_LENGTHS: dict[str, float] = {"axis": 0.8, "panel": 1.2, "boresight": 1.6, "target": 2.4, "cone": 2.0}
"""Drawn lengths in scene units (directions matter, lengths do not; the body box is not to scale)."""
BORESIGHT_STEP = 0.1
"""Boresight i is drawn BORESIGHT_STEP (i % 3) shorter, so that boresights along one axis stay apart."""
BODY_BOX = (0.5, 0.35, 0.2)
CONE_GENERATORS = 8
CONE_RIM_POINTS = 24
LEVEL_RGBA = ((0.2, 0.8, 0.2, 1.0), (1.0, 0.6, 0.0, 1.0), (0.9, 0.1, 0.1, 1.0))
"""Colour of a margin level (recording.scene.margin_level): ok, within the warning band, violated."""
INACTIVE_RGBA = (0.6, 0.6, 0.6, 1.0)
"""A boresight outside its cone's windows (the constraint does not apply there)."""
KIND_RGBA = {"keep_out": (1.0, 0.3, 0.1, 0.8), "keep_in": (0.3, 0.55, 1.0, 0.8)}
"""A cone by kind: keep_out red-ish, keep_in blue-ish."""
INACTIVE_CONE_ALPHA = 0.2
"""A cone's opacity outside its windows."""
TARGET_RGBA = {"sun": (1.0, 0.85, 0.1, 1.0), "earth": (0.2, 0.45, 1.0, 1.0)}
OTHER_TARGET_RGBA = (0.65, 0.35, 0.85, 1.0)
TEXT_RGBA = (1.0, 1.0, 1.0, 1.0)
TEXT_SENTINEL_CHARS = 16
"""Length of the sentinel texts the templates are serialized with (bytes 0x01: found once)."""


def cone_marker_ids(index: int) -> tuple[int, int, int]:
    """(boresight, cone, target arrow) marker ids of pointing constraint `index` (CONE_ID_BASE)."""
    first = CONE_ID_BASE + CONE_ID_STRIDE * index
    return first, first + 1, first + 2


def scene_marker_ids(cones: Sequence[PointingConstraint]) -> dict[str, int]:
    """Every marker id of the scene of these pointing constraints by part: SCENE_IDS, then for each cone
    '<name>/boresight', '<name>/cone' and, for the first cone aimed at a target, '<name>/target'."""
    ids = dict(SCENE_IDS)
    owners = target_owners(cones)
    for i, cone in enumerate(cones):
        bore, cone_id, target = cone_marker_ids(i)
        ids[f"{cone.name}/boresight"], ids[f"{cone.name}/cone"] = bore, cone_id
        if owners[i] == i:
            ids[f"{cone.name}/target"] = target
    return ids


def cone_points(half_angle_rad: float, length: float) -> Array:
    """A cone about +x as LINE_LIST vertices (2 (generators + rim points), 3): CONE_GENERATORS segments
    from the apex, then the rim as CONE_RIM_POINTS segments; every far end lies at half_angle_rad from
    +x, `length` from the apex."""
    phi = np.linspace(0.0, 2.0 * np.pi, CONE_RIM_POINTS + 1)
    rim = length * np.stack([np.full_like(phi, math.cos(half_angle_rad)), math.sin(half_angle_rad) * np.cos(phi),
                             math.sin(half_angle_rad) * np.sin(phi)], axis=1)
    gen = rim[np.linspace(0, CONE_RIM_POINTS, CONE_GENERATORS, endpoint=False).astype(int)]
    apex = np.zeros_like(gen)
    return np.concatenate([np.stack([apex, gen], axis=1).reshape(-1, 3),
                           np.stack([rim[:-1], rim[1:]], axis=1).reshape(-1, 3)])


def x_to(d: Array) -> Array:
    """The unit quaternion (x y z w) of the shortest rotation that takes +x to the unit vector d (the pose
    of a cone drawn about +x): vector part +x cross d = (0, -d_z, d_y), scalar part 1 + d_x, normalised;
    a half turn about z for d = -x. Plain floats: the scene node calls it for every cone at every step."""
    dx, dy, dz = float(d[0]), float(d[1]), float(d[2])
    w = 1.0 + dx
    n = math.sqrt(w * w + dy * dy + dz * dz)
    if n < 1e-12:
        return np.array([0.0, 0.0, 1.0, 0.0])
    return np.array([0.0, -dz / n, dy / n, w / n])


def _cdr_string_tail(data: bytes | bytearray, start: int) -> int:
    """The offset just past a CDR string whose uint32 length field is at `start`."""
    return start + 4 + struct.unpack_from("<I", data, start)[0]


class SceneBuilder:
    """The scene's two messages for one state, serialized: a geometry_msgs/TransformStamped hill -> body
    (rotation = q: it maps body vectors to Hill, A(q)^T) and a visualization_msgs/MarkerArray in the hill
    frame: the body box (pose q) and its axes, the panel normal, and for each configured pointing constraint
    (`cone_marker_ids`) an arrow along its boresight, coloured by its margin (LEVEL_RGBA; grey outside its
    windows), and a cone of its half-angle about its target (KIND_RGBA: keep_out red-ish, keep_in
    blue-ish; faint outside its windows); one arrow per distinct target (TARGET_RGBA), drawn with the first
    cone aimed at it; and a text (SCENE_IDS["text"]). Arrows are two points (tail at the origin, head along
    the direction); cones are LINE_LISTs about +x (`cone_points`) posed by `x_to` their target.

    Speed: the scene node may draw every step of the lockstep loop, and building and serializing ~15
    markers with ~200 points through rclpy took ~0.4 ms a step. So both messages are built once as
    message objects, serialized by rclpy into templates, and each `build` writes only what changes (stamps,
    arrow heads, poses, colours: all fixed-size) into the templates' bytes at offsets found once by
    serializing marker values; a test decodes the result with rosbags.

    The text is the one field whose size changes. The text marker is the array's last element, so the bytes
    after its text are only the rest of that marker (empty mesh fields), whose CDR bytes depend on nothing but
    where they start modulo 4 (their alignment): `build` writes the template up to the text's length field,
    then the text's own length, its bytes and NUL, then the rest for that alignment (the four variants are
    taken from rclpy at construction). A text is thus sent at its own length, without padding, up to
    TEXT_BYTES (longer texts are cut).

    Args:
        cones: the configuration's pointing constraints (`Config.pointing`), in order.
        warn_rad: margins below this are drawn as warnings.
    """

    TEXT_BYTES = 1024
    """The longest text sent, in bytes (ASCII; longer texts are cut)."""

    def __init__(self, cones: Sequence[PointingConstraint], warn_rad: float) -> None:
        from rclpy.serialization import serialize_message  # here: this module is read without rclpy (bags)

        self.warn_rad = warn_rad
        self.cones = tuple(cones)
        self.ids = scene_marker_ids(self.cones)
        self.owners = target_owners(self.cones)
        transform = TransformStamped()
        transform.header.frame_id = topics.HILL_FRAME
        transform.child_frame_id = topics.BODY_FRAME
        markers, text_marker = self._markers()
        by_id = {mk.id: mk for mk in (*markers, text_marker)}
        m = {name: by_id[i] for name, i in self.ids.items()}
        # sentinels: values that occur nowhere else in the serialized messages, one per field written later
        sentinel = iter(range(1, 1_000_000))

        def mark(obj: Any, fields: str, single: bool = False) -> tuple[float, ...]:
            """Distinct values no real field holds, set into obj's fields (float32-exact for the colours)."""
            vals = tuple(float(np.float32(1.0e30 / (7 + next(sentinel)))) if single else 1.0e300 / (7 + next(sentinel))
                         for _ in fields)
            for f, v in zip(fields, vals, strict=True):
                setattr(obj, f, v)
            return vals

        stamps = []
        for i, mk in enumerate((*markers, text_marker)):
            mk.header.stamp = Time(sec=0x5CE70000 + i, nanosec=0x0A0B0C00 + i)
            stamps.append(struct.pack("<iI", mk.header.stamp.sec, mk.header.stamp.nanosec))
        transform.header.stamp = Time(sec=0x5CE7FFFF, nanosec=0x0A0B0CFF)
        head_names = ["axis_x", "axis_y", "axis_z", "panel", *(f"{c.name}/boresight" for c in self.cones),
                      *(n for n in self.ids if n.endswith("/target"))]
        heads = {name: mark(m[name].points[1], "xyz") for name in head_names}
        poses = {name: mark(m[name].pose.orientation, "xyzw")
                 for name in ("body", *(f"{c.name}/cone" for c in self.cones))}
        rotation = mark(transform.transform.rotation, "xyzw")
        colours = {name: mark(m[name].color, "rgba", single=True)
                   for name in ("text", *(f"{c.name}/{part}" for c in self.cones for part in ("boresight", "cone")))}
        self._tf = bytearray(serialize_message(transform))
        texts = ["\x01" * (TEXT_SENTINEL_CHARS + extra) for extra in range(4)]  # every alignment of the text's end
        variants = []
        for t in texts:
            text_marker.text = t
            variants.append(bytes(serialize_message(MarkerArray(markers=[*markers, text_marker]))))
        if self._tf[:2] != b"\x00\x01" or variants[0][:2] != b"\x00\x01":
            raise RuntimeError("scene templates: expected little-endian CDR")

        def at(buf: bytes | bytearray, pattern: bytes) -> int:
            i = buf.find(pattern)
            if i < 0 or buf.find(pattern, i + 1) >= 0:
                raise RuntimeError("scene templates: a field was not found exactly once")
            return i

        self._text_length = at(variants[0], texts[0].encode()) - 4
        if struct.unpack_from("<I", variants[0], self._text_length)[0] != TEXT_SENTINEL_CHARS + 1:
            raise RuntimeError("scene templates: the text's length field is not where it was expected")
        self._mk = bytearray(variants[0][:self._text_length])
        self._tails: list[bytes] = [b""] * 4
        for extra, buf in enumerate(variants):  # (rclpy leaves its padding bytes as they were: not compared)
            if struct.unpack_from("<I", buf, self._text_length)[0] != TEXT_SENTINEL_CHARS + extra + 1:
                raise RuntimeError("scene templates: the text moved with its length")
            end = _cdr_string_tail(buf, self._text_length)
            self._tails[(end - 4) % 4] = buf[end:]
        d8, f4 = struct.Struct("<d"), struct.Struct("<f")
        self._mk_stamps = [at(self._mk, p) for p in stamps]
        self._tf_stamp = at(self._tf, struct.pack("<iI", transform.header.stamp.sec, transform.header.stamp.nanosec))
        self._tf_rotation = at(self._tf, b"".join(d8.pack(v) for v in rotation))
        self._heads = {n: at(self._mk, b"".join(d8.pack(v) for v in vals)) for n, vals in heads.items()}
        self._poses = {n: at(self._mk, b"".join(d8.pack(v) for v in vals)) for n, vals in poses.items()}
        self._colors = {n: at(self._mk, b"".join(f4.pack(v) for v in vals)) for n, vals in colours.items()}
        struct.pack_into("<4f", self._mk, self._colors["text"], *TEXT_RGBA)
        for cone in self.cones:
            struct.pack_into("<4f", self._mk, self._colors[f"{cone.name}/boresight"], *LEVEL_RGBA[0])
            struct.pack_into("<4f", self._mk, self._colors[f"{cone.name}/cone"], *KIND_RGBA[cone.kind])

    def _markers(self) -> tuple[list[Marker], Marker]:
        """The markers in id order, and the text marker (the array's last: see the class docstring)."""
        L = SCENE_LENGTHS
        axis_rgba = ((0.9, 0.2, 0.2, 1.0), (0.2, 0.8, 0.2, 1.0), (0.3, 0.5, 1.0, 1.0))
        out: list[Marker] = []

        def shape(marker_id: int, kind: int, scale: tuple[float, float, float], rgba: tuple[float, ...]) -> Marker:
            mk = Marker()
            mk.header.frame_id = topics.HILL_FRAME
            mk.ns, mk.id, mk.action, mk.type = SCENE_NS, marker_id, Marker.ADD, kind
            mk.pose.orientation.w = 1.0
            mk.scale.x, mk.scale.y, mk.scale.z = scale
            mk.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
            out.append(mk)
            return mk

        def arrow(marker_id: int, rgba: tuple[float, ...], shaft: float) -> None:
            shape(marker_id, Marker.ARROW, (shaft, 2.0 * shaft, 3.0 * shaft), rgba).points = [Point(), Point(x=1.0)]

        shape(SCENE_IDS["body"], Marker.CUBE, BODY_BOX, (0.75, 0.75, 0.8, 0.9))
        for i, a in enumerate("xyz"):
            arrow(SCENE_IDS[f"axis_{a}"], axis_rgba[i], 0.03)
        arrow(SCENE_IDS["panel"], (0.6, 0.6, 0.6, 1.0), 0.04)
        for i, cone in enumerate(self.cones):
            bore, cone_id, target = cone_marker_ids(i)
            arrow(bore, LEVEL_RGBA[0], 0.05)
            shape(cone_id, Marker.LINE_LIST, (0.01, 0.0, 0.0), KIND_RGBA[cone.kind]).points = [
                Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in cone_points(cone.half_angle_rad, L["cone"])]
            if self.owners[i] == i:
                arrow(target, TARGET_RGBA.get(cone.target, OTHER_TARGET_RGBA), 0.06)
        text = Marker()
        text.header.frame_id = topics.HILL_FRAME
        text.ns, text.id, text.action, text.type = SCENE_NS, SCENE_IDS["text"], Marker.ADD, Marker.TEXT_VIEW_FACING
        text.pose.orientation.w = 1.0
        text.pose.position.z = 2.3  # (its lines drawn about it: kept inside the layout's 3D view)
        text.scale.z = 0.15
        text.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        return out, text

    def _boresight_rgba(self, margin_rad: float) -> tuple[float, ...]:
        if math.isinf(margin_rad) and margin_rad > 0:
            return INACTIVE_RGBA
        return LEVEL_RGBA[int(margin_level(margin_rad, self.warn_rad))]

    def build(self, q: Array, sc: Scene, k: int, t_ns: int, text: str, text_level: int = 0) -> tuple[bytes, bytes]:
        """The serialized transform and markers of the state with attitude q (4,) (body in Hill, x y z w),
        sample k of its scene `sc` (`recording.scene.scene_of_states`, of the same pointing constraints),
        stamped t_ns; `text` (ASCII; NULs dropped, cut at TEXT_BYTES) drawn in the colour of `text_level`
        (0 ok: white, 1 warning, 2 error)."""
        L = SCENE_LENGTHS
        sec, nanosec = divmod(int(t_ns), NS_PER_S)
        mk, tf = self._mk, self._tf
        for off in self._mk_stamps:
            struct.pack_into("<iI", mk, off, sec, nanosec)
        struct.pack_into("<iI", tf, self._tf_stamp, sec, nanosec)
        qx, qy, qz, qw = (float(c) for c in q)
        struct.pack_into("<4d", tf, self._tf_rotation, qx, qy, qz, qw)
        struct.pack_into("<4d", mk, self._poses["body"], qx, qy, qz, qw)
        axes = sc.body_axes[k] * L["axis"]
        for i, a in enumerate("xyz"):
            struct.pack_into("<3d", mk, self._heads[f"axis_{a}"], *axes[i].tolist())
        struct.pack_into("<3d", mk, self._heads["panel"], *(sc.panel[k] * L["panel"]).tolist())
        for i, (view, owner) in enumerate(zip(sc.cones, self.owners, strict=True)):
            name = view.name
            length = L["boresight"] - BORESIGHT_STEP * (i % 3)
            struct.pack_into("<3d", mk, self._heads[f"{name}/boresight"], *(view.boresight[k] * length).tolist())
            target = view.target_hill[k]
            struct.pack_into("<4d", mk, self._poses[f"{name}/cone"], *x_to(target).tolist())
            if owner == i:
                struct.pack_into("<3d", mk, self._heads[f"{name}/target"], *(target * L["target"]).tolist())
            margin = float(view.margin_rad[k])
            struct.pack_into("<4f", mk, self._colors[f"{name}/boresight"], *self._boresight_rgba(margin))
            r, g, b, a = KIND_RGBA[view.kind]
            struct.pack_into("<4f", mk, self._colors[f"{name}/cone"], r, g, b,
                             INACTIVE_CONE_ALPHA if math.isinf(margin) and margin > 0 else a)
        struct.pack_into("<4f", mk, self._colors["text"], *(LEVEL_RGBA[text_level] if text_level else TEXT_RGBA))
        raw = text.replace("\x00", "").encode("ascii", "replace")[: self.TEXT_BYTES]
        end = self._text_length + 4 + len(raw) + 1
        return bytes(tf), b"".join((mk, struct.pack("<I", len(raw) + 1), raw, b"\x00", self._tails[(end - 4) % 4]))


__all__ = [
    "CONE_ID_BASE", "CONE_ID_STRIDE", "NS_PER_S", "SCENE_IDS", "SCENE_NS", "STAMP_OFFSETS", "UNIT_NORM_EPS",
    "CdrLayout", "FilterStatusBuilder", "FrameError", "Layouts", "SceneBuilder", "clock_cdr", "cone_marker_ids",
    "cone_points",
    "layouts", "scene_marker_ids", "state_cdr", "state_messages_cdr", "torque_cdr",
    "x_to", "battery_msg", "cdr_stamp_ns", "clock_msg",
    "diagnostic_values", "filter_record", "filter_status_msg", "odometry_fields", "odometry_msg",
    "quaternion_from_msg", "state_fields", "state_messages", "wheels_msg",
    "run_status_from_msg", "run_status_msg",
    "seconds_to_ns", "stamp", "stamp_ns", "state_from_msg", "state_msg", "sun_vector_msg", "temperature_msg",
    "torque_from_msg", "torque_msg", "unit_attitude", "unit_quaternion", "vector_msg",
]  # fmt: skip
