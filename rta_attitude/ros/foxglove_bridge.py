"""Live Foxglove WebSocket server for pip-only installs: the run's ROS topics as raw CDR.

    rta-attitude foxglove [--port 8765] [--topics REGEX ...] [--exclude REGEX ...] [--sim-time]   (cli/foxglove.py)

`foxglove_bridge` (C++) has no PyPI wheel, so this does its core job with the `foxglove-sdk` package and rclpy:

- topics are discovered from the graph and re-discovered every `rescan_period` s (topics that appear later are
  advertised too, topics whose publishers are gone are unadvertised), filtered by include/exclude regular
  expressions (full match);
- every topic is a Foxglove channel with message encoding `cdr` and a schema named `pkg/msg/Type` whose data is
  the rosbag2 `ros2msg` complete definition (the type's `.msg` text, then every nested type depth first, each
  after a line of 80 `=` and `MSG: pkg/Type`; `ros2idl` where a type has no `.msg`), as foxglove_bridge and
  rosbag2 write it;
- ROS subscriptions exist only while a client is subscribed to the channel; they are `raw=True`, so the CDR
  bytes go out untouched (nothing is deserialized in Python). Topics are read best-effort, so a slow client
  never pushes back on the run's reliable keep-all writers; latched (transient-local) topics such as
  run_status are read reliable and transient-local, so they reach a late client (`subscription_qos`);
- the log time of a message is its `header.stamp` when the type starts with a `std_msgs/Header` and the stamp
  is non-zero, else the receive time on the node's clock;
- `--sim-time`: use_sim_time on the node, the Foxglove `time` capability, and every `/clock` broadcast as the
  server time, so the apps follow the simulation clock.

Threads: the main thread spins a single-threaded executor (rescan timer, raw subscriptions, a guard condition
that reconciles subscriptions). The SDK server runs on its own threads; its subscribe/unsubscribe callbacks only
count under a lock and trigger the guard condition, so every rclpy entity is made and destroyed on the executor
thread. SIGINT/SIGTERM set a flag: the loop ends, the server stops, and the command returns 0.

Ports: the SDK's server listens on a free loopback port, behind `WebSocketFront`, which serves `port` (and
`legacy_port`) and forwards the frames unchanged. The front completes the WebSocket closing handshake, which
the SDK leaves undone (a client that closes gets a Close frame with its code, 1000, not a dropped connection:
code 1006; clients still connected when the server stops get 1001). foxglove-sdk servers accept the
subprotocol `foxglove.sdk.v1`, the current name of `foxglove.websocket.v1` (the same protocol); clients that
offer only the old name (Lichtblick before its `foxglove.sdk.v1` support) are served through `legacy_port`,
where the front accepts the old name.

Message definitions are read from the interface files under the prefixes the bag writer searches
(`$AMENT_PREFIX_PATH`, then `sys.prefix`: a plain pip install into a venv sets no AMENT_PREFIX_PATH).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import importlib
import logging
import re
import signal
import struct
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from types import FrameType
from typing import Any

import foxglove
import rclpy
from foxglove.websocket import Capability, ChannelView, Client, ServerListener, WebSocketServer
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.guard_condition import GuardCondition
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from rta_attitude.errors import RtaError
from rta_attitude.recording.bag import _share_dirs as interface_share_dirs

LOG = logging.getLogger(__name__)

#: Line that separates the definitions of a complete ``ros2msg``/``ros2idl`` definition.
SEPARATOR = "=" * 80

#: Primitive .msg field types (no definition to append).
PRIMITIVE_TYPES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    }
)

HEADER_TYPE = "std_msgs/msg/Header"
CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"

#: CDR encapsulation kinds for which the first struct member starts right after the 4-byte
#: encapsulation header (plain CDR and final XCDR2), mapped to their struct byte order.
_PLAIN_ENCAPSULATION_BYTE_ORDER = {0x00: ">", 0x01: "<", 0x06: ">", 0x07: "<"}

_ARRAY_SUFFIX = re.compile(r"\[[^\]]*\]$")
_IDL_INCLUDE = re.compile(r'^\s*#include\s+[<"]([A-Za-z0-9_/]+)\.idl[>"]', re.MULTILINE)


class DefinitionNotFoundError(LookupError):
    """No ``.msg``/``.idl`` file was found for a type under any of the searched prefixes."""


def split_type_name(ros_type: str) -> tuple[str, str, str]:
    """Split ``pkg/Type`` or ``pkg/msg/Type`` into ``(pkg, namespace, Type)``."""
    parts = ros_type.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise ValueError(f"not a ROS interface type name: {ros_type!r}")


def normalize_type_name(ros_type: str) -> str:
    """Return the ``pkg/msg/Type`` form of a type name."""
    pkg, namespace, name = split_type_name(ros_type)
    return f"{pkg}/{namespace}/{name}"


def _msg_field_lines(text: str) -> list[tuple[str, bool]]:
    """Return ``(type_token, is_constant)`` for every field/constant line of a .msg text."""
    result: list[tuple[str, bool]] = []
    for raw_line in text.splitlines():
        line = raw_line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 1)
        if len(parts) < 2:
            continue
        type_token, rest = parts
        name, _, after = rest.partition(" ")
        result.append((type_token, "=" in name or after.lstrip().startswith("=")))
    return result


def _base_type(type_token: str) -> str:
    """Strip array (``[]``, ``[3]``, ``[<=3]``) and string bound (``<=N``) suffixes."""
    base = _ARRAY_SUFFIX.sub("", type_token)
    return base.split("<=", 1)[0]


class MessageDefinitionCache:
    """Builds rosbag2-style complete message definitions from the installed interface files."""

    def __init__(self, prefixes: Sequence[Path] | None = None) -> None:
        """Search the given install prefixes for definitions; default: those the bag writer searches
        (`recording.bag`: ``$AMENT_PREFIX_PATH``, then ``sys.prefix``, where the pip wheels of Jazzy put
        ``share/``, so a plain venv without ``AMENT_PREFIX_PATH`` finds them)."""
        if prefixes is None:
            prefixes = [share.parent for share in interface_share_dirs()]
        self._prefixes = list(prefixes)
        self._texts: dict[tuple[str, str], str] = {}
        self._complete: dict[str, tuple[str, str]] = {}

    def _find_file(self, ros_type: str, extension: str) -> Path:
        pkg, namespace, name = split_type_name(ros_type)
        for prefix in self._prefixes:
            candidate = prefix / "share" / pkg / namespace / f"{name}{extension}"
            if candidate.is_file():
                return candidate
        raise DefinitionNotFoundError(f"{pkg}/{namespace}/{name}{extension}")

    def _text(self, ros_type: str, extension: str) -> str:
        key = (normalize_type_name(ros_type), extension)
        if key not in self._texts:
            self._texts[key] = self._find_file(ros_type, extension).read_text(encoding="utf-8")
        return self._texts[key]

    def _resolve_msg_dependency(self, type_token: str, package: str) -> str | None:
        """Map a .msg field type to ``pkg/Type`` (None for primitives)."""
        base = _base_type(type_token)
        if base in PRIMITIVE_TYPES:
            return None
        if "/" in base:
            return base
        if base == "Header":
            # ROS 1 style shorthand, still accepted by rosidl for std_msgs/Header.
            try:
                self._find_file(f"{package}/{base}", ".msg")
            except DefinitionNotFoundError:
                return "std_msgs/Header"
        return f"{package}/{base}"

    def msg_dependencies(self, ros_type: str) -> list[str]:
        """Direct non-primitive field types of a message, in field order, as ``pkg/Type``."""
        package = split_type_name(ros_type)[0]
        deps: list[str] = []
        for type_token, _is_constant in _msg_field_lines(self._text(ros_type, ".msg")):
            dep = self._resolve_msg_dependency(type_token, package)
            if dep is not None and dep not in deps:
                deps.append(dep)
        return deps

    def starts_with_header(self, ros_type: str) -> bool:
        """True if the first (non-constant) field of the message is a ``std_msgs/Header``."""
        package = split_type_name(ros_type)[0]
        try:
            lines = _msg_field_lines(self._text(ros_type, ".msg"))
        except DefinitionNotFoundError:
            return False
        for type_token, is_constant in lines:
            if is_constant:
                continue
            if "[" in type_token:
                return False
            dep = self._resolve_msg_dependency(type_token, package)
            return dep is not None and normalize_type_name(dep) == HEADER_TYPE
        return False

    def _complete_msg(self, ros_type: str) -> str:
        seen: set[str] = {normalize_type_name(ros_type)}
        chunks: list[str] = []

        def append(type_name: str) -> None:
            text = self._text(type_name, ".msg")
            chunks.append(text if text.endswith("\n") else text + "\n")
            for dep in self.msg_dependencies(type_name):
                key = normalize_type_name(dep)
                if key in seen:
                    continue
                seen.add(key)
                pkg, _namespace, name = split_type_name(dep)
                chunks.append(f"{SEPARATOR}\nMSG: {pkg}/{name}\n")
                append(dep)

        append(ros_type)
        return "".join(chunks)

    def _complete_idl(self, ros_type: str) -> str:
        seen: set[str] = set()
        chunks: list[str] = []

        def append(type_name: str) -> None:
            key = normalize_type_name(type_name)
            if key in seen:
                return
            seen.add(key)
            text = self._text(key, ".idl")
            chunks.append(f"{SEPARATOR}\nIDL: {key}\n")
            chunks.append(text if text.endswith("\n") else text + "\n")
            for dep in _IDL_INCLUDE.findall(text):
                append(dep)

        append(ros_type)
        return "".join(chunks)

    def complete_definition(self, ros_type: str) -> tuple[str, str]:
        """Return ``(schema_encoding, text)``: ``ros2msg``, or the ``ros2idl`` fallback."""
        key = normalize_type_name(ros_type)
        if key not in self._complete:
            try:
                self._complete[key] = ("ros2msg", self._complete_msg(key))
            except DefinitionNotFoundError as err:
                LOG.warning("no .msg definition for %s (%s), falling back to IDL", key, err)
                self._complete[key] = ("ros2idl", self._complete_idl(key))
        return self._complete[key]


def import_message_class(ros_type: str) -> type:
    """Import the generated Python class of a ROS interface type (``pkg/msg/Type``)."""
    pkg, namespace, name = split_type_name(ros_type)
    module = importlib.import_module(f"{pkg}.{namespace}")
    return getattr(module, name)


def cdr_leading_time_ns(data: bytes, *, allow_zero: bool = False) -> int | None:
    """Read a ``builtin_interfaces/Time`` that is the first member of a serialized CDR message.

    That is ``header.stamp`` for types starting with ``std_msgs/Header`` and ``clock`` for
    ``rosgraph_msgs/Clock``. Returns nanoseconds, or None if the encapsulation is not plain
    CDR/final XCDR2, the buffer is too short, or the time is zero and ``allow_zero`` is False.
    """
    if len(data) < 12 or data[0] != 0:
        return None
    order = _PLAIN_ENCAPSULATION_BYTE_ORDER.get(data[1])
    if order is None:
        return None
    sec, nanosec = struct.unpack_from(f"{order}iI", data, 4)
    if sec == 0 and nanosec == 0 and not allow_zero:
        return None
    return sec * 1_000_000_000 + nanosec


def subscription_qos(node: Node, topic: str) -> QoSProfile:
    """QoS compatible with all current publishers of `topic`, that never holds a publisher back.

    Transient-local (and reliable) only if every publisher is transient-local and reliable, so latched messages
    such as the run's `run_status` reach a late client. Every other topic is read best-effort: the run's stream
    topics are reliable keep-all, and a reliable reader that falls behind (a slow client) would push back on
    the writers of the closed loop; a best-effort reader never does, so the viewer stays off the control path
    (foxglove_bridge would follow the publishers and read them reliably).
    """
    infos = node.get_publishers_info_by_topic(topic)
    latched = bool(infos) and all(
        i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        and i.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        for i in infos
    )
    depth = max(10, sum(max(0, i.qos_profile.depth) for i in infos))
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=min(depth, 1000),
        reliability=ReliabilityPolicy.RELIABLE if latched else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class ClientSubscriptionTracker(ServerListener):
    """foxglove-sdk ``ServerListener``: counts client subscriptions per channel id.

    The callbacks run on the SDK's threads; they only update counters and call ``on_change``
    (which must be thread-safe, e.g. a guard-condition trigger).
    """

    def __init__(self) -> None:
        """Create an empty tracker; ``on_change`` is attached later by the bridge."""
        self._lock = threading.Lock()
        self._counts: dict[int, int] = {}
        self.on_change: Callable[[], None] | None = None

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        """A client subscribed to a channel."""
        with self._lock:
            self._counts[channel.id] = self._counts.get(channel.id, 0) + 1
        LOG.debug("client %s subscribed to %s", client.id, channel.topic)
        self._notify()

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        """A client unsubscribed from a channel (or disconnected, or the channel closed)."""
        with self._lock:
            remaining = self._counts.get(channel.id, 0) - 1
            if remaining > 0:
                self._counts[channel.id] = remaining
            else:
                self._counts.pop(channel.id, None)
        LOG.debug("client %s unsubscribed from %s", client.id, channel.topic)
        self._notify()

    def subscribed_channel_ids(self) -> set[int]:
        """Ids of channels with at least one subscribed client."""
        with self._lock:
            return set(self._counts)

    def _notify(self) -> None:
        callback = self.on_change
        if callback is not None:
            callback()


@dataclass
class BridgedTopic:
    """State of one ROS topic exposed as a Foxglove channel."""

    topic: str
    ros_type: str
    channel: foxglove.Channel
    msg_class: type
    has_header: bool
    subscription: Subscription | None = None
    missing_scans: int = 0
    messages: int = 0


@dataclass(frozen=True)
class BridgeConfig:
    """Options of :class:`RosFoxgloveBridge`."""

    include: tuple[re.Pattern[str], ...] = (re.compile(".*"),)
    exclude: tuple[re.Pattern[str], ...] = ()
    log_time: str = "header"
    sim_time: bool = False
    rescan_period: float = 1.0
    remove_after_scans: int = 2


class RosFoxgloveBridge:
    """Mirrors ROS 2 topics to Foxglove channels; all methods run on the executor thread."""

    def __init__(
        self,
        node: Node,
        server: WebSocketServer,
        tracker: ClientSubscriptionTracker,
        config: BridgeConfig,
        definitions: MessageDefinitionCache | None = None,
    ) -> None:
        """Attach to ``node`` (timers, guard condition) and ``server`` (time, status)."""
        self._node = node
        self._server = server
        self._tracker = tracker
        self._config = config
        self._definitions = definitions or MessageDefinitionCache()
        self._topics: dict[str, BridgedTopic] = {}
        self._unsupported: dict[str, str] = {}
        self._clock_subscription: Subscription | None = None
        self._reconcile_gc: GuardCondition = node.create_guard_condition(self.reconcile)
        tracker.on_change = self._reconcile_gc.trigger
        self._timer = node.create_timer(config.rescan_period, self.rescan)
        if config.sim_time:
            self._clock_subscription = node.create_subscription(
                import_message_class(CLOCK_TYPE),
                CLOCK_TOPIC,
                self._on_clock,
                QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT),
                raw=True,
            )
        self.rescan()

    def topic_selected(self, topic: str) -> bool:
        """Apply the include/exclude regular expressions (full match)."""
        if not any(p.fullmatch(topic) for p in self._config.include):
            return False
        return not any(p.fullmatch(topic) for p in self._config.exclude)

    def rescan(self) -> None:
        """Advertise new topics, drop topics without publishers, then reconcile subscriptions."""
        graph = dict(self._node.get_topic_names_and_types())
        for topic, types in sorted(graph.items()):
            if not self.topic_selected(topic):
                continue
            if self._node.count_publishers(topic) == 0:
                continue
            if len(types) != 1:
                self._mark_unsupported(topic, f"{topic} has several types {types}; skipped")
                continue
            ros_type = normalize_type_name(types[0])
            current = self._topics.get(topic)
            if current is not None:
                current.missing_scans = 0
                if current.ros_type == ros_type:
                    continue
                self._remove(topic)
            self._add(topic, ros_type)
        for topic, bridged in list(self._topics.items()):
            if topic in graph and self._node.count_publishers(topic) > 0:
                continue
            bridged.missing_scans += 1
            if bridged.missing_scans >= self._config.remove_after_scans:
                LOG.info("topic %s disappeared; unadvertising", topic)
                self._remove(topic)
        self.reconcile()

    def _mark_unsupported(self, topic: str, reason: str) -> None:
        if self._unsupported.get(topic) == reason:
            return
        self._unsupported[topic] = reason
        LOG.warning(reason)
        self._server.publish_status(reason, foxglove.StatusLevel.Warning, id=f"topic:{topic}")

    def _add(self, topic: str, ros_type: str) -> None:
        try:
            msg_class = import_message_class(ros_type)
            encoding, definition = self._definitions.complete_definition(ros_type)
        except (ImportError, AttributeError, ValueError, DefinitionNotFoundError, OSError) as err:
            self._mark_unsupported(topic, f"cannot bridge {topic} [{ros_type}]: {err}")
            return
        self._unsupported.pop(topic, None)
        channel = foxglove.Channel(
            topic,
            schema=foxglove.Schema(
                name=ros_type, encoding=encoding, data=definition.encode("utf-8")
            ),
            message_encoding="cdr",
        )
        self._topics[topic] = BridgedTopic(
            topic=topic,
            ros_type=ros_type,
            channel=channel,
            msg_class=msg_class,
            has_header=self._definitions.starts_with_header(ros_type),
        )
        LOG.info("advertised %s [%s] as channel %d", topic, ros_type, channel.id())

    def _remove(self, topic: str) -> None:
        bridged = self._topics.pop(topic)
        if bridged.subscription is not None:
            self._node.destroy_subscription(bridged.subscription)
            bridged.subscription = None
        bridged.channel.close()

    def reconcile(self) -> None:
        """Create/destroy ROS subscriptions so exactly the client-subscribed channels are fed."""
        wanted = self._tracker.subscribed_channel_ids()
        for bridged in self._topics.values():
            want = bridged.channel.id() in wanted
            if want and bridged.subscription is None:
                qos = subscription_qos(self._node, bridged.topic)
                bridged.subscription = self._node.create_subscription(
                    bridged.msg_class,
                    bridged.topic,
                    self._make_callback(bridged),
                    qos,
                    raw=True,
                )
                LOG.info(
                    "subscribed %s (%s, %s)",
                    bridged.topic,
                    qos.reliability.name,
                    qos.durability.name,
                )
            elif not want and bridged.subscription is not None:
                self._node.destroy_subscription(bridged.subscription)
                bridged.subscription = None
                LOG.info("unsubscribed %s", bridged.topic)

    def _make_callback(self, bridged: BridgedTopic) -> Callable[[bytes], None]:
        use_header = self._config.log_time == "header" and bridged.has_header
        channel = bridged.channel
        clock = self._node.get_clock()

        def on_message(data: bytes) -> None:
            log_time = cdr_leading_time_ns(data) if use_header else None
            if log_time is None:
                log_time = clock.now().nanoseconds
            channel.log(data, log_time=log_time)
            bridged.messages += 1

        return on_message

    def _on_clock(self, data: bytes) -> None:
        """Forward ``/clock`` (rosgraph_msgs/Clock: a builtin_interfaces/Time) as server time."""
        stamp = cdr_leading_time_ns(data, allow_zero=True)
        if stamp is not None:
            self._server.broadcast_time(stamp)

    def close(self) -> None:
        """Destroy subscriptions and close every channel."""
        self._tracker.on_change = None
        self._timer.cancel()
        for topic in list(self._topics):
            self._remove(topic)
        if self._clock_subscription is not None:
            self._node.destroy_subscription(self._clock_subscription)
            self._clock_subscription = None

    @property
    def topics(self) -> dict[str, BridgedTopic]:
        """Currently advertised topics (read-only use)."""
        return self._topics


SDK_SUBPROTOCOL = "foxglove.sdk.v1"
"""The subprotocol foxglove-sdk servers accept (and foxglove_bridge >= 3)."""
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
"""The former name of the same protocol, the only one @foxglove/ws-protocol clients offer (older Lichtblick)."""
_PROTOCOL_HEADER = re.compile(rb"(?im)^sec-websocket-protocol:[^\r\n]*\r\n")
_MAX_HEAD = 65536


async def _read_head(reader: asyncio.StreamReader) -> bytes:
    """An HTTP head (request or response line and headers, through the blank line)."""
    head = await reader.readuntil(b"\r\n\r\n")
    if len(head) > _MAX_HEAD:
        raise ValueError("HTTP head too long")
    return head


def _with_protocol(head: bytes, protocol: str) -> bytes:
    """The head with its Sec-WebSocket-Protocol header(s) replaced by one naming `protocol`."""
    lines = _PROTOCOL_HEADER.sub(b"", head)
    return lines[:-2] + f"Sec-WebSocket-Protocol: {protocol}\r\n\r\n".encode()


OP_CLOSE = 0x8
NORMAL_CLOSURE, GOING_AWAY = struct.pack(">H", 1000), struct.pack(">H", 1001)
"""Close frame payloads: status code 1000 (normal closure), 1001 (the server goes away)."""


class FrameTracker:
    """Follows the frame boundaries of one direction of a WebSocket stream (RFC 6455 sec. 5.2) as its bytes
    pass, without holding them: `feed` takes each chunk; `close_payload` is the (unmasked) payload of the first
    Close frame seen (None before), `at_boundary` whether the bytes so far end with a whole frame."""

    def __init__(self) -> None:
        self._head = bytearray()
        self._remaining = 0
        self._close: bytearray | None = None
        self._key = b""
        self.close_payload: bytes | None = None

    @property
    def at_boundary(self) -> bool:
        return not self._head and self._remaining == 0

    def feed(self, data: bytes) -> None:
        i, n = 0, len(data)
        while i < n:
            if self._remaining:  # inside a payload: skip it (a Close frame's is kept)
                take = min(self._remaining, n - i)
                if self._close is not None:
                    self._close += data[i:i + take]
                self._remaining -= take
                i += take
                if not self._remaining:
                    self._end_frame()
                continue
            self._head.append(data[i])
            i += 1
            if len(self._head) < 2:
                continue
            b1 = self._head[1]
            ext = {126: 2, 127: 8}.get(b1 & 0x7F, 0)
            mask = 4 if b1 & 0x80 else 0
            if len(self._head) < 2 + ext + mask:
                continue
            self._remaining = int.from_bytes(self._head[2:2 + ext], "big") if ext else b1 & 0x7F
            closing = self._head[0] & 0x0F == OP_CLOSE and self.close_payload is None
            self._close = bytearray() if closing else None
            self._key = bytes(self._head[2 + ext:2 + ext + mask])
            self._head.clear()
            if not self._remaining:
                self._end_frame()

    def _end_frame(self) -> None:
        if self._close is not None:
            key = self._key or b"\0\0\0\0"
            self.close_payload = bytes(b ^ key[j % 4] for j, b in enumerate(self._close))
            self._close = None


def close_frame(client_payload: bytes) -> bytes:
    """The server's Close frame (unmasked) answering a client's Close: its status code echoed (RFC 6455 sec.
    5.5.1), 1000 when the client gave none."""
    code = client_payload[:2] if len(client_payload) >= 2 else NORMAL_CLOSURE
    return bytes([0x80 | OP_CLOSE, len(code)]) + code


class WebSocketFront:
    """The server's listening ports: a TCP relay (an asyncio loop on a daemon thread) in front of the SDK's
    WebSocket server, which listens on a loopback port of its own. It copies the bytes both ways unchanged,
    and adds two things the SDK does not do:

    - the closing handshake: foxglove-sdk stops reading at a client's Close frame and drops the connection
      without a Close of its own, which clients report as an abnormal closure (code 1006). The relay follows
      the frames of both directions (`FrameTracker`); when the SDK closes the connection after a client's
      Close without having sent one, the relay sends the client a Close with its status code (1000), then
      closes the connection, as RFC 6455 sec. 7.1.2 asks of a server;
    - on a port opened with `legacy`: clients that offer only the subprotocol `foxglove.websocket.v1` (the
      protocol's former name, which the SDK answers with HTTP 400): the upgrade request's subprotocol header is
      rewritten to `foxglove.sdk.v1` and the 101 answer's back (frames carry no subprotocol).
    """

    def __init__(self, upstream_port: int, upstream_host: str = "127.0.0.1") -> None:
        self._upstream = (upstream_host, upstream_port)
        self._loop = asyncio.new_event_loop()
        self._servers: list[asyncio.Server] = []
        self._writers: set[asyncio.StreamWriter] = set()
        self._open: dict[asyncio.StreamWriter, FrameTracker] = {}
        """Upgraded connections: the client's writer -> the tracker of what the SDK sent it."""
        self._thread = threading.Thread(target=self._loop.run_forever, name="foxglove-front", daemon=True)
        self._thread.start()

    def listen(self, host: str, port: int, legacy: bool = False, option: str = "--port") -> int:
        """Listen on host:port (0: any free port); returns the bound port.

        Raises:
            RtaError: the port cannot be bound, in one line naming `option`.
        """
        try:
            return asyncio.run_coroutine_threadsafe(self._listen(host, port, legacy), self._loop).result(timeout=10.0)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise RtaError(f"port {port} on {host} is in use (choose another with {option})") from None
            raise RtaError(f"cannot listen on {host}:{port} ({exc.strerror or exc}; choose another with "
                           f"{option})") from None

    async def _listen(self, host: str, port: int, legacy: bool) -> int:
        server = await asyncio.start_server(partial(self._handle, legacy=legacy), host, port)
        self._servers.append(server)
        return int(server.sockets[0].getsockname()[1])

    async def _handle(self, down_r: asyncio.StreamReader, down_w: asyncio.StreamWriter, legacy: bool) -> None:
        up_w: asyncio.StreamWriter | None = None
        self._writers.add(down_w)
        try:
            request = await _read_head(down_r)
            m = _PROTOCOL_HEADER.search(request)
            offered = m.group(0) if m is not None else b""
            rename = legacy and LEGACY_SUBPROTOCOL.encode() in offered and SDK_SUBPROTOCOL.encode() not in offered
            up_r, up_w = await asyncio.open_connection(*self._upstream)
            self._writers.add(up_w)
            up_w.write(_with_protocol(request, SDK_SUBPROTOCOL) if rename else request)
            await up_w.drain()
            response = await _read_head(up_r)
            upgraded = response.startswith(b"HTTP/1.1 101")
            if rename and upgraded:
                response = _with_protocol(response, LEGACY_SUBPROTOCOL)
            down_w.write(response)
            await down_w.drain()
            if not upgraded:  # a refused handshake (HTTP 400 ...): its body, then the end
                await asyncio.gather(self._pump(down_r, up_w), self._pump(up_r, down_w))
                return
            from_client, from_server = FrameTracker(), FrameTracker()
            self._open[down_w] = from_server
            await asyncio.gather(self._pump(down_r, up_w, from_client),
                                 self._pump(up_r, down_w, from_server, partial(self._finish, from_client)))
        except Exception as exc:  # a connection's end (reset, EOF mid-handshake, bad head): never the relay's
            LOG.debug("foxglove front: connection ended: %s", exc)
        finally:
            self._open.pop(down_w, None)
            for writer in (down_w, up_w):
                if writer is not None:
                    self._writers.discard(writer)
                    writer.close()

    @staticmethod
    def _finish(from_client: FrameTracker, from_server: FrameTracker, client: asyncio.StreamWriter) -> bool:
        """The SDK closed the connection: complete the closing handshake it left undone (see the class); True if
        this sent the client a Close."""
        if from_client.close_payload is None or from_server.close_payload is not None or not from_server.at_boundary:
            return False
        client.write(close_frame(from_client.close_payload))
        return True

    @staticmethod
    async def _pump(source: asyncio.StreamReader, sink: asyncio.StreamWriter, tracker: FrameTracker | None = None,
                    on_end: Callable[[FrameTracker, asyncio.StreamWriter], bool] | None = None) -> None:
        try:
            while data := await source.read(65536):
                if tracker is not None:
                    tracker.feed(data)
                sink.write(data)
                await sink.drain()
            if on_end is not None and tracker is not None and on_end(tracker, sink):
                await sink.drain()
                sink.close()  # the server closes the TCP connection after the closing handshake
        finally:
            if not sink.is_closing() and sink.can_write_eof():
                with contextlib.suppress(OSError):
                    sink.write_eof()

    def stop(self) -> None:
        """Close the listening sockets and every relayed connection, then stop the loop."""

        async def _close() -> None:
            for server in self._servers:
                server.close()
            for client, from_server in list(self._open.items()):  # the server goes away: say so (1001)
                if from_server.close_payload is None and from_server.at_boundary and not client.is_closing():
                    client.write(close_frame(GOING_AWAY))
            for writer in list(self._writers):  # the handlers then end on their own (EOF or a reset)
                writer.close()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            if tasks:
                await asyncio.wait(tasks, timeout=2.0)

        if self._thread.is_alive():
            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(_close(), self._loop).result(timeout=5.0)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5.0)


SERVER_NAME = "rta_attitude foxglove"
NODE_NAME = "rta_attitude_foxglove"
UPSTREAM_HOST = "127.0.0.1"
"""Where the SDK's server listens (a free port), behind the `WebSocketFront` that serves the chosen ports."""


def start_websocket_server(host: str, port: int, sim_time: bool, listener: ServerListener) -> WebSocketServer:
    """The foxglove-sdk server on host:port (0: any free port).

    Raises:
        RtaError: the port cannot be bound (in use, or not allowed), in one line.
    """
    try:
        return foxglove.start_server(
            name=SERVER_NAME,
            host=host,
            port=port,
            capabilities=[Capability.Time] if sim_time else [],
            server_listener=listener,
        )
    except Exception as exc:  # the SDK raises its own (Rust) error types: report any as one line
        text = " ".join(str(exc).split()) or type(exc).__name__
        if "in use" in text.lower():
            raise RtaError(f"port {port} on {host} is in use (choose another with --port): {text}") from None
        raise RtaError(f"cannot start the Foxglove server on {host}:{port}: {text}") from None


def serve(
    host: str = "127.0.0.1",
    port: int = 8765,
    config: BridgeConfig | None = None,
    legacy_port: int | None = None,
    announce: Callable[[str], None] | None = None,
) -> int:
    """Serve the ROS topics over the Foxglove WebSocket protocol until SIGINT/SIGTERM; returns 0.

    Args:
        announce: called with one line per listening URL (default: printed to stdout).

    Raises:
        RtaError: the server cannot start (port in use).
    """
    config = config or BridgeConfig()
    say = announce or (lambda line: print(line, flush=True))
    stop = threading.Event()
    wake: list[GuardCondition] = []

    def request_stop(signum: int, _frame: FrameType | None) -> None:
        LOG.info("received %s, shutting down", signal.Signals(signum).name)
        stop.set()
        for guard in wake:
            guard.trigger()

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node: Node | None = None
    server: WebSocketServer | None = None
    bridge: RosFoxgloveBridge | None = None
    relay: Any = None
    executor: SingleThreadedExecutor | None = None
    try:
        node = Node(
            NODE_NAME,
            context=context,
            enable_rosout=False,
            start_parameter_services=False,
            parameter_overrides=[Parameter("use_sim_time", value=config.sim_time)],
        )
        wake.append(node.create_guard_condition(lambda: None))
        tracker = ClientSubscriptionTracker()
        server = start_websocket_server(UPSTREAM_HOST, 0, config.sim_time, tracker)  # behind the front
        relay = WebSocketFront(server.port)
        url = f"ws://{host}:{relay.listen(host, port)}"
        bridge = RosFoxgloveBridge(node, server, tracker, config)
        say(f"foxglove server listening on {url}")
        if legacy_port is not None:
            legacy = relay.listen(host, legacy_port, legacy=True, option="--legacy-port")
            say(f"foxglove server (foxglove.websocket.v1 relay) listening on ws://{host}:{legacy}")
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.25)
    finally:
        if relay is not None:
            relay.stop()
        if server is not None:
            server.stop()
        if bridge is not None:
            bridge.close()
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    LOG.info("stopped")
    return 0
