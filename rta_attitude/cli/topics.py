"""`rta-attitude topics` and `rta-attitude echo TOPIC`: live inspection for pip-only installs (no
ros2cli), on `ros.topic_tools`."""

from __future__ import annotations

import argparse
import math

from rta_attitude.errors import RtaError
from rta_attitude.ros.replay import message_class, ros_node
from rta_attitude.ros.topic_tools import (
    DEFAULT_SETTLE_S,
    DEFAULT_SPIN_TIME_S,
    DEFAULT_TRUNCATE_LENGTH,
    echo,
    format_topics,
    list_topics,
    node_name,
    resolve_topic,
)


def _check_seconds(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise RtaError(f"{name} must be a number of seconds > 0, got {value}")


def _run_topics(args: argparse.Namespace) -> int:
    _check_seconds("--window", args.window)
    _check_seconds("--spin-time", args.spin_time)
    _check_seconds("--settle", args.settle)
    wait_for = tuple(resolve_topic(t) for t in args.wait_for)
    try:
        with ros_node(node_name()) as node:
            rows = list_topics(node, args.window, args.spin_time, not args.no_rates, args.settle, wait_for)
    except KeyboardInterrupt:
        return 0
    print(format_topics(rows, None if args.no_rates else args.window), flush=True)
    return 0



def _run_echo(args: argparse.Namespace) -> int:
    _check_seconds("--spin-time", args.spin_time)
    _check_seconds("--timeout", args.timeout)
    topic = resolve_topic(args.topic)
    if args.message_type is not None:
        message_class(args.message_type)  # check the type before starting ROS
    count = 1 if args.once else args.count
    if count is not None and count < 1:
        raise RtaError(f"--count must be >= 1, got {count}")
    truncate = None if args.full_length else args.truncate_length
    try:
        with ros_node(node_name()) as node:
            echo(node, topic, args.message_type, count, args.spin_time, args.timeout, truncate, args.no_arr)
    except (KeyboardInterrupt, BrokenPipeError):
        pass
    return 0



def add_arguments(parser: argparse.ArgumentParser, command: str) -> None:
    """Arguments of `rta-attitude topics` and `rta-attitude echo`."""
    if command == "topics":
        parser.add_argument("--window", type=float, default=2.0, help="rate measurement window, s (default 2)")
        parser.add_argument("--wait-for", action="append", default=[], metavar="TOPIC",
                            help="wait until this topic has a publisher (repeatable); error if it has none "
                                 "within --spin-time")
        parser.add_argument("--spin-time", type=float, default=DEFAULT_SPIN_TIME_S,
                            help=f"longest wait for discovery, s (default {DEFAULT_SPIN_TIME_S:g})")
        parser.add_argument("--settle", type=float, default=DEFAULT_SETTLE_S,
                            help="without --wait-for: list once the graph has not changed for this long, s "
                                 f"(default {DEFAULT_SETTLE_S:g})")
        parser.add_argument("--no-rates", action="store_true", help="list types and counts only (faster)")
        return
    parser.add_argument("topic", help="topic name, e.g. /rta/state")
    parser.add_argument("message_type", nargs="?", default=None,
                        help="message type, e.g. sensor_msgs/msg/JointState (default: from the publishers)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--once", action="store_true", help="print one message and exit")
    group.add_argument("--count", type=int, default=None, help="print this many messages and exit")
    parser.add_argument("--spin-time", type=float, default=10.0,
                        help="longest wait for the topic to have a publisher, s (default 10)")
    parser.add_argument("--timeout", type=float, default=10.0,
                        help="with --once/--count: longest wait for the messages once the topic is found, s "
                             "(default 10)")
    parser.add_argument("--truncate-length", type=int, default=DEFAULT_TRUNCATE_LENGTH,
                        help=f"cut strings and arrays longer than this (default {DEFAULT_TRUNCATE_LENGTH})")
    parser.add_argument("--full-length", action="store_true", help="never cut strings and arrays")
    parser.add_argument("--no-arr", action="store_true", help="print array lengths instead of their contents")



def run(args: argparse.Namespace) -> int:
    """`rta-attitude topics` / `rta-attitude echo`."""
    return _run_topics(args) if args.command == "topics" else _run_echo(args)




__all__ = ["add_arguments", "run"]
