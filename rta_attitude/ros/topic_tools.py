"""Live topic inspection for pip-only installs (no ros2cli): list topics, echo one as YAML.

    rta-attitude topics [--wait-for TOPIC ...] [--spin-time S] [--settle S] [--window S] [--no-rates]
    rta-attitude echo TOPIC [TYPE] [--once | --count N] [--spin-time S] [--timeout S] [--no-arr]
    (the command line: cli/topics.py)

Discovery. DDS discovery is asynchronous: another participant's endpoints arrive over 0.05-2.5 s
(measured here; longer on a loaded machine), one topic at a time. `topics` therefore waits before it
answers, never for a fixed time:
- with `--wait-for TOPIC` (repeatable), until every named topic has a publisher, then lists the graph
  (at most `--spin-time`; a topic still missing then is one `ERROR:` line, exit 1);
- otherwise until the graph has been unchanged for `--settle` seconds after another participant's own
  topics (beyond /rosout and /parameter_events) appeared, at most `--spin-time`.
`echo` waits (at most `--spin-time`) until the topic has a publisher, then subscribes.

`topics` prints every topic in the ROS graph (this ROS_DOMAIN_ID) with its type, the number of
publishers and subscribers (this tool's own endpoints left out) and the rate at which messages
arrive, measured over a window of wall-clock time with raw (undecoded) best-effort subscriptions:
best effort never pushes back on a reliable keep-all writer, so inspecting a lockstep run does not
slow it down.

`echo` prints each message as YAML followed by `---`, in the layout of `ros2 topic echo`
(rosidl_runtime_py's message_to_yaml, which is not on PyPI, rewritten here from
`get_fields_and_field_types()`): fields in declaration order, nested messages as mappings, arrays
as block lists, `byte`/`char` values as one-character strings, strings and arrays longer than
`--truncate-length` (default 128) cut with `...`. Topic names without a leading `/` are taken from
the root namespace, as ros2 does (`echo rta/state`, or `echo /rta/state`). The subscription's QoS
adapts to the publishers as ros2cli's does: reliable if every publisher is, transient-local if every
publisher is (then the latched history is shown too).

Both stop cleanly on SIGINT/SIGTERM; a topic that does not appear within `--spin-time` is one
`ERROR:` line.
"""

from __future__ import annotations

import array
import os
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from rta_attitude.errors import RtaError
from rta_attitude.ros.replay import message_class

DEFAULT_TRUNCATE_LENGTH = 128
"""Longest string or array printed in full by `echo` (ros2 topic echo's default)."""
DEFAULT_SETTLE_S = 1.0
"""`topics`: without --wait-for, the graph counts as discovered when it has not changed for this long.
Measured here: another participant's endpoints appear 0.05-2.5 s after start, and those of several
participants up to 0.7 s apart."""
DEFAULT_SPIN_TIME_S = 5.0
"""`topics`: longest wait for discovery, s (ros2cli's --spin-time)."""
RATE_QOS_DEPTH = 100
INFRASTRUCTURE_TOPICS = frozenset({"/parameter_events", "/rosout"})
"""Topics every rclpy node has; Fast DDS often reports them before a participant's own topics, so a
graph of only these is not yet settled (seen in CI: `topics` listed only /parameter_events)."""


# ----------------------------------------------------------------------------- message -> YAML


def _convert(value: Any, truncate_length: int | None, no_arr: bool) -> Any:
    if isinstance(value, bytes):  # `byte` fields and uint8[]/byte[] arrays arrive as bytes
        text = "".join(chr(c) for c in value)
        if truncate_length is not None and len(value) > truncate_length:
            text = "".join(chr(c) for c in value[:truncate_length]) + "..."
        return text
    if isinstance(value, str):
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + "..."
        return value
    if hasattr(value, "get_fields_and_field_types"):
        return message_to_dict(value, truncate_length, no_arr)
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        if no_arr:
            return f"<sequence, length: {len(value)}>"
        items = list(value)
        cut = truncate_length is not None and len(items) > truncate_length
        if cut:
            items = items[:truncate_length]
        out = [_convert(v, truncate_length, no_arr) for v in items]
        return [*out, "..."] if cut else out
    if isinstance(value, np.generic):
        return value.item()
    return value


def message_to_dict(msg: Any, truncate_length: int | None = None, no_arr: bool = False) -> dict[str, Any]:
    """A generated ROS message as nested dicts/lists of plain Python values, fields in order.

    Args:
        msg: an instance of a generated message class (has get_fields_and_field_types()).
        truncate_length: cut longer strings and arrays (None: never).
        no_arr: replace arrays by '<sequence, length: n>'.
    """
    return {name: _convert(getattr(msg, name), truncate_length, no_arr) for name in msg.get_fields_and_field_types()}


def message_to_yaml(msg: Any, truncate_length: int | None = None, no_arr: bool = False) -> str:
    """YAML text of a message as `ros2 topic echo` prints it (without the `---` separator)."""
    import yaml

    return yaml.safe_dump(message_to_dict(msg, truncate_length, no_arr), allow_unicode=True, width=sys.maxsize,
                          sort_keys=False, default_flow_style=False)


# ----------------------------------------------------------------------------- graph helpers


def node_name() -> str:
    """The inspection node's name (unique per process)."""
    return f"_rta_attitude_inspect_{os.getpid()}"


def _spin_for(executor: Any, context: Any, seconds: float, done: Callable[[], bool] = lambda: False) -> bool:
    """Spin until `seconds` pass, `done()` is true or the context ends; True unless the context ended."""
    deadline = time.monotonic() + seconds
    while context.ok() and not done():
        left = deadline - time.monotonic()
        if left <= 0:
            break
        executor.spin_once(timeout_sec=min(left, 0.05))
    return context.ok()


def _foreign(infos: list[Any], node: Any) -> list[Any]:
    """Endpoints that are not this tool's own node."""
    return [i for i in infos if not (i.node_name == node.get_name() and i.node_namespace == node.get_namespace())]


def _graph(node: Any) -> dict[str, tuple[str, int, int]]:
    """topic -> (type, publishers, subscribers), this node's endpoints left out."""
    out = {}
    for topic, types in node.get_topic_names_and_types():
        pubs = _foreign(node.get_publishers_info_by_topic(topic), node)
        subs = _foreign(node.get_subscriptions_info_by_topic(topic), node)
        if pubs or subs:
            out[topic] = (", ".join(types), len(pubs), len(subs))
    return out


def _publisher_topics(graph: dict[str, tuple[str, int, int]]) -> set[str]:
    return {topic for topic, (_type, pubs, _subs) in graph.items() if pubs > 0}


def discover(node: Any, executor: Any, spin_time_s: float, settle_s: float = DEFAULT_SETTLE_S,
             wait_for: tuple[str, ...] = ()) -> dict[str, tuple[str, int, int]]:
    """The ROS graph once discovery has settled: topic -> (type, publishers, subscribers).

    With `wait_for`, as soon as every named topic has a publisher; otherwise once another
    participant's own topics (beyond INFRASTRUCTURE_TOPICS) are seen and the graph has not changed
    for `settle_s`. Waits at most `spin_time_s` in either case.

    Raises:
        RtaError: a `wait_for` topic has no publisher after `spin_time_s`.
        KeyboardInterrupt: the context was shut down (a signal) while waiting.
    """
    start = time.monotonic()
    graph, changed = _graph(node), start
    wanted = set(wait_for)
    while True:
        if wanted:
            if wanted <= _publisher_topics(graph):
                return graph
        elif set(graph) - INFRASTRUCTURE_TOPICS and time.monotonic() - changed >= settle_s:
            return graph
        if time.monotonic() - start >= spin_time_s:
            break
        if not _spin_for(executor, node.context, 0.05):
            raise KeyboardInterrupt
        now = _graph(node)
        if now != graph:
            graph, changed = now, time.monotonic()
    missing = sorted(wanted - _publisher_topics(graph))
    if missing:
        raise RtaError(f"no publisher of {', '.join(missing)} within {spin_time_s:g} s "
                       f"(live topics: {', '.join(sorted(graph)) or 'none'})")
    return graph


def measured_rate_hz(arrivals_s: list[float], window_end_s: float) -> float | None:
    """Messages per second from arrival times: (n - 1) / (window end - first arrival).

    Measured to the end of the window rather than to the last arrival: arrival times are taken when
    callbacks run, so a backlog the executor works off at once would make first-to-last too short.
    None with fewer than two messages.
    """
    if len(arrivals_s) < 2 or window_end_s <= arrivals_s[0]:
        return None
    return (len(arrivals_s) - 1) / (window_end_s - arrivals_s[0])


def _executor(node: Any) -> Any:
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    return executor


def list_topics(node: Any, window_s: float, spin_time_s: float, rates: bool, settle_s: float = DEFAULT_SETTLE_S,
                wait_for: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """Rows {topic, type, publishers, subscribers, rate_hz, messages} for every topic in the graph,
    once discovery settled (`discover`).

    rate_hz: messages per wall-clock second received over `window_s` (`measured_rate_hz`; None: no
    message, or the type is not installed, then `messages` is None too).

    Raises:
        RtaError: a `wait_for` topic has no publisher within `spin_time_s`.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    executor = _executor(node)
    try:
        graph = discover(node, executor, spin_time_s, settle_s, wait_for)
        stamps: dict[str, list[float]] = {}
        if rates:
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RATE_QOS_DEPTH,
                             reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
            for topic, (type_name, pubs, _) in graph.items():
                if pubs == 0 or ", " in type_name:
                    continue
                try:
                    cls = message_class(type_name)
                except RtaError:
                    continue
                received: list[float] = []
                stamps[topic] = received
                node.create_subscription(cls, topic, lambda _data, r=received: r.append(time.monotonic()), qos,
                                         raw=True)
            _spin_for(executor, node.context, window_s)
        window_end = time.monotonic()
    finally:
        executor.shutdown(timeout_sec=0.5)
    rows = []
    for topic, (type_name, pubs, subs) in sorted(graph.items()):
        got = stamps.get(topic)
        rate = None if got is None else measured_rate_hz(got, window_end)
        rows.append({"topic": topic, "type": type_name, "publishers": pubs, "subscribers": subs,
                     "rate_hz": rate, "messages": None if got is None else len(got)})
    return rows


def format_topics(rows: list[dict[str, Any]], window_s: float | None) -> str:
    """Fixed-width table of `list_topics` rows."""
    tw = max([len("topic"), *(len(r["topic"]) for r in rows)]) + 2
    yw = max([len("type"), *(len(r["type"]) for r in rows)]) + 2
    head = f"{'topic':<{tw}}{'type':<{yw}}{'pubs':>5}{'subs':>6}"
    if window_s is not None:
        head += f"{'rate':>12}"
    lines = [head]
    for r in rows:
        line = f"{r['topic']:<{tw}}{r['type']:<{yw}}{r['publishers']:>5}{r['subscribers']:>6}"
        if window_s is not None:
            if r["rate_hz"] is not None:
                rate = f"{r['rate_hz']:.3g} Hz"
            elif r["messages"] is None:
                rate = "?" if r["publishers"] else "-"
            else:
                rate = f"{r['messages']} msg" if r["messages"] else "0 Hz"
            line += f"{rate:>12}"
        lines.append(line)
    if window_s is not None:
        lines.append(f"(rates: messages per wall-clock second over {window_s:g} s; ? = type not installed)")
    if not rows:
        lines.append(f"no topics found (ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')})")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- echo


def resolve_topic(name: str) -> str:
    """A user's topic name as an absolute name (relative names resolve from '/', as in ros2 topic echo).

    Raises:
        RtaError: an empty or malformed name.
    """
    text = name.strip()
    full = text if text.startswith("/") else "/" + text
    parts = full[1:].split("/")
    if not text or not all(p and (p[0].isalpha() or p[0] == "_") and all(c.isalnum() or c == "_" for c in p)
                           for p in parts):
        raise RtaError(f"{name!r}: not a valid topic name")
    return full


def _echo_qos(node: Any, topic: str) -> Any:
    """QoS adapted to the topic's publishers (ros2cli's rule)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    infos = _foreign(node.get_publishers_info_by_topic(topic), node)
    reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RATE_QOS_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def _topic_type(node: Any, executor: Any, topic: str, spin_time_s: float) -> str:
    """The type of `topic` once it has a publisher (waits at most spin_time_s)."""
    found: list[str] = []

    def known() -> bool:
        types = dict(node.get_topic_names_and_types()).get(topic)
        if types and _foreign(node.get_publishers_info_by_topic(topic), node):
            found[:] = types
        return bool(found)

    _spin_for(executor, node.context, spin_time_s, known)
    if not found:
        if not node.context.ok():
            raise KeyboardInterrupt
        live = sorted(t for t, _ in node.get_topic_names_and_types())
        raise RtaError(f"topic {topic}: no publisher found within {spin_time_s:g} s "
                       f"(live topics: {', '.join(live) or 'none'})")
    if len(found) > 1:
        raise RtaError(f"topic {topic} has several types ({', '.join(found)}); pass the type to use")
    return found[0]


def echo(node: Any, topic: str, type_name: str | None, count: int | None, spin_time_s: float, timeout_s: float,
         truncate_length: int | None, no_arr: bool, out: Any = None) -> int:
    """Print messages of `topic` as YAML + '---' until `count` are printed (None: until interrupted).

    Waits (at most spin_time_s) until the topic has a publisher, then subscribes with a QoS adapted
    to its publishers; with a count, waits at most timeout_s more for the messages.

    Returns:
        The number of messages printed.

    Raises:
        RtaError: the topic has no publisher within spin_time_s, or (with a count) fewer than count
            messages arrive within timeout_s after it was found.
    """
    stream = out if out is not None else sys.stdout
    executor = _executor(node)
    printed = 0
    try:
        found_type = _topic_type(node, executor, topic, spin_time_s)
        cls = message_class(type_name or found_type)

        def show(msg: Any) -> None:
            nonlocal printed
            if count is not None and printed >= count:
                return
            stream.write(message_to_yaml(msg, truncate_length, no_arr) + "---\n")
            stream.flush()
            printed += 1

        node.create_subscription(cls, topic, show, _echo_qos(node, topic))
        if count is None:
            while node.context.ok():
                executor.spin_once(timeout_sec=0.1)
        else:
            _spin_for(executor, node.context, timeout_s, lambda: printed >= count)
            if printed < count and node.context.ok():
                raise RtaError(f"topic {topic}: {printed} of {count} messages within {timeout_s:g} s")
    finally:
        executor.shutdown(timeout_sec=0.5)
    return printed


# ----------------------------------------------------------------------------- CLI


__all__ = [
    "DEFAULT_SETTLE_S", "DEFAULT_SPIN_TIME_S", "DEFAULT_TRUNCATE_LENGTH", "discover", "echo", "format_topics",
    "list_topics", "measured_rate_hz", "message_to_dict", "message_to_yaml", "node_name", "resolve_topic",
]  # fmt: skip
