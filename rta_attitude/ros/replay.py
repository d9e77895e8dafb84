"""Bag replay over DDS: republish a recorded MCAP bag's messages on their topics, with /clock.

    rta-attitude replay BAG [--rate R] [--loop] [--topics T ...] [--no-clock] [--delay S]   (cli/replay.py)

The pip-only stand-in for `ros2 bag play --clock`: live tools (`rta-attitude echo`, `ros2 topic
echo`, Foxglove, PlotJuggler, nodes with use_sim_time) see the run again.

- Messages are published as the raw CDR bytes of the bag (rclpy `Publisher.publish(bytes)`), with a
  publisher of the recorded type (the generated Python class, looked up by `pkg/msg/Type`): no
  decode/encode round trip, so subscribers receive exactly what was recorded.
- Timing: messages go out in log-time order (as `ros2 bag play`; the file holds them in arrival
  order), one recorded at log time t at wall time start + (t - t_first) / R.
- `/clock` (rosgraph_msgs/Clock) carries the bag time: before the messages of each new log time the
  clock is published at that time; recorded `/clock` messages are then not republished (they would
  duplicate it). `--no-clock` republishes the recorded `/clock` instead, if the bag has one.
- QoS: reliability and durability as recorded in each channel's `offered_qos_profiles` (so the
  replay matches the same readers as the original run); history keep_last with depth
  max(recorded depth, `REPLAY_DEPTH`): a replay never blocks on a slow reader.
- `--loop` restarts at the beginning (the clock jumps back, as with `ros2 bag play --loop`).
- Stops cleanly on SIGINT/SIGTERM (exit 0) so that Fast DDS removes its shared-memory files.
"""

from __future__ import annotations

import importlib
import logging
import math
import signal
import struct
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from rta_attitude.errors import BagError, RtaError

log = logging.getLogger(__name__)

CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
REPLAY_DEPTH = 100
"""Smallest keep_last depth of a replay publisher."""
NODE_NAME = "rta_attitude_replay"
NS_PER_S = 1_000_000_000
_POLL_S = 0.05
"""Longest sleep between checks for a shutdown request, s."""


def message_class(type_name: str) -> Any:
    """The generated Python class of `pkg/msg/Type` (or `pkg/Type`), e.g. sensor_msgs.msg.JointState.

    Raises:
        RtaError: the name is malformed or its package is not installed.
    """
    parts = type_name.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg") or not all(parts):
        raise RtaError(f"{type_name!r}: not a message type name like 'pkg/msg/Type'")
    pkg, name = parts[0], parts[-1]
    try:
        module = importlib.import_module(f"{pkg}.msg")
        cls = getattr(module, name)
    except (ImportError, AttributeError):
        raise RtaError(f"message type {type_name} is not installed (no Python module {pkg}.msg.{name})") from None
    return cls


def _raise_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


@contextmanager
def ros_node(name: str) -> Iterator[Any]:
    """An rclpy node in its own context; SIGTERM is turned into KeyboardInterrupt first, so rclpy's
    handler chains to it and the process ends cleanly (Fast DDS removes its /dev/shm files).

    Yields:
        The node; destroyed and its context shut down on exit.
    """
    # SIGINT and SIGTERM both end the command cleanly (KeyboardInterrupt), whatever the disposition this
    # process inherited: a shell's background job starts with SIGINT ignored, and would ignore Ctrl-C
    # (measured: an `echo` started from a background test run printed on for 20 s after SIGINT)
    if signal.getsignal(signal.SIGINT) in (signal.SIG_DFL, signal.SIG_IGN, None):
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, signal.SIG_IGN, None):
        signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        import rclpy
        from rclpy.context import Context
        from rclpy.node import Node
    except ImportError as exc:
        raise RtaError(f"this command needs rclpy (pip install ros-jazzy-rclpy ros-jazzy-rmw-fastrtps-cpp): {exc}") \
            from None
    context = Context()
    rclpy.init(context=context)
    node = None
    try:
        node = Node(name, context=context)
        yield node
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def offered_qos(path: Path) -> dict[str, dict[str, Any]]:
    """Topic -> the first offered QoS profile recorded in its channel metadata ({} where absent).

    Read from the MCAP summary when the file is complete, else from the channel records in order.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap.records import Channel
    from mcap.stream_reader import StreamReader

    channels: list[Any] = []
    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
            if summary is not None:
                channels = list(summary.channels.values())
    except (McapError, ValueError, OSError, EOFError):
        summary = None
    if summary is None:
        try:
            with path.open("rb") as f:
                for record in StreamReader(f, skip_magic=False).records:
                    if isinstance(record, Channel):
                        channels.append(record)
        except (McapError, ValueError, OSError, EOFError, RuntimeError, struct.error):
            pass  # a truncated tail ends the scan; read_bag reports real damage
    out: dict[str, dict[str, Any]] = {}
    for ch in channels:
        try:
            profiles = yaml.safe_load(ch.metadata.get("offered_qos_profiles", "") or "[]")
        except yaml.YAMLError:
            profiles = None
        out[ch.topic] = profiles[0] if isinstance(profiles, list) and profiles and isinstance(profiles[0], dict) \
            else {}
    return out


def replay_qos(recorded: dict[str, Any]) -> Any:
    """The rclpy QoSProfile of a replay publisher: recorded reliability/durability, keep_last depth."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    depth = recorded.get("depth", 0)
    depth = max(depth if isinstance(depth, int) else 0, REPLAY_DEPTH)
    reliability = ReliabilityPolicy.BEST_EFFORT if recorded.get("reliability") == "best_effort" \
        else ReliabilityPolicy.RELIABLE
    durability = DurabilityPolicy.TRANSIENT_LOCAL if recorded.get("durability") == "transient_local" \
        else DurabilityPolicy.VOLATILE
    profile = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability, durability=durability)
    lease = recorded.get("liveliness_lease_duration")
    if recorded.get("liveliness") == "automatic" and isinstance(lease, dict):
        ns = int(lease.get("sec", 0)) * NS_PER_S + int(lease.get("nsec", 0))
        if ns > 0:  # offer the recorded lease, so readers that request one (the run's nodes) match
            from rclpy.duration import Duration
            from rclpy.qos import LivelinessPolicy

            profile.liveliness = LivelinessPolicy.AUTOMATIC
            profile.liveliness_lease_duration = Duration(nanoseconds=ns)
    return profile


def _clock_message(t_ns: int) -> Any:
    clock_cls = message_class(CLOCK_TYPE)
    msg = clock_cls()
    msg.clock.sec, msg.clock.nanosec = t_ns // NS_PER_S, t_ns % NS_PER_S
    return msg


def _sleep_until(deadline: float, context: Any) -> bool:
    """Sleep until time.monotonic() >= deadline; False if the context was shut down meanwhile."""
    while context.ok():
        left = deadline - time.monotonic()
        if left <= 0:
            return True
        time.sleep(min(left, _POLL_S))
    return False


def replay(bag: Path, rate: float = 1.0, loop: bool = False, topics: list[str] | None = None,
           no_clock: bool = False, delay_s: float = 0.5) -> int:
    """Republish a bag's messages over DDS (see the module docstring); returns 0 when done or interrupted.

    Raises:
        RtaError: a bad rate or delay; BagError: no such bag, topic or message.
    """
    from rta_attitude.recording.analysis import resolve_bag_path
    from rta_attitude.recording.bag import read_bag

    if not (math.isfinite(rate) and rate > 0):
        raise RtaError(f"--rate must be a finite number > 0, got {rate}")
    if not (math.isfinite(delay_s) and delay_s >= 0):
        raise RtaError(f"--delay must be >= 0 s, got {delay_s}")
    file = resolve_bag_path(bag)
    contents = read_bag(file, topics=topics, decode=False)
    if topics:
        unknown = sorted(set(topics) - set(contents.topics))
        if unknown:
            raise BagError(f"{file}: no topic {unknown[0]} (topics: {', '.join(sorted(contents.topics))})")
    if not contents.messages:
        raise BagError(f"{file}: no messages to replay")
    generate_clock = not no_clock
    classes: dict[str, Any] = {}
    for topic, type_name in sorted(contents.topics.items()):
        if generate_clock and topic == CLOCK_TOPIC:
            continue
        try:
            classes[topic] = message_class(type_name)
        except RtaError as exc:
            print(f"WARNING: skipping {topic}: {exc}", file=sys.stderr)
    ordered = sorted(contents.messages, key=lambda m: m.log_time_ns)  # file order is arrival order
    messages = [m for m in ordered if m.topic in classes]
    if not messages and not generate_clock:
        raise BagError(f"{file}: none of its message types is installed; nothing to replay")
    qos = offered_qos(file)
    t_first, t_last = ordered[0].log_time_ns, ordered[-1].log_time_ns
    span_s = (t_last - t_first) / NS_PER_S
    if contents.truncated:
        print(f"bag truncated: data ends at t = {t_last / NS_PER_S:.3f} s; replaying what was read", file=sys.stderr)
    print(f"replaying {file}: {len(messages)} messages on {len(classes)} topics"
          f"{' + /clock' if generate_clock else ''}, {span_s:.1f} s of bag time at {rate:g}x"
          f"{', looping' if loop else ''} (Ctrl-C to stop)", flush=True)
    sent = loops = 0
    t_wall0 = time.monotonic()
    try:
        with ros_node(NODE_NAME) as node:
            from rclpy.qos import QoSProfile, ReliabilityPolicy

            pubs = {t: node.create_publisher(cls, t, replay_qos(qos.get(t, {}))) for t, cls in classes.items()}
            clock_pub = None
            if generate_clock:
                clock_qos = QoSProfile(depth=REPLAY_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
                clock_pub = node.create_publisher(message_class(CLOCK_TYPE), CLOCK_TOPIC, clock_qos)
            context = node.context
            if not _sleep_until(time.monotonic() + delay_s, context):
                return 0
            t_wall0 = time.monotonic()
            while context.ok():
                start = time.monotonic()
                last_clock: int | None = None
                for m in ordered:
                    pub = pubs.get(m.topic)
                    if pub is None and not (clock_pub is not None and m.topic == CLOCK_TOPIC):
                        continue
                    if not _sleep_until(start + (m.log_time_ns - t_first) / NS_PER_S / rate, context):
                        break
                    if clock_pub is not None and (last_clock is None or m.log_time_ns > last_clock):
                        clock_pub.publish(_clock_message(m.log_time_ns))
                        last_clock = m.log_time_ns
                    if pub is not None:
                        pub.publish(m.data)
                        sent += 1
                else:
                    loops += 1
                    if not loop:
                        break
                    continue
                break
    except KeyboardInterrupt:
        pass
    wall = time.monotonic() - t_wall0
    print(f"replay done: {sent} messages in {wall:.1f} s ({loops} complete pass{'es' if loops != 1 else ''})",
          flush=True)
    return 0



__all__ = ["message_class", "offered_qos", "replay", "replay_qos", "ros_node"]
