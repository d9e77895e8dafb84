"""`rta-attitude foxglove`: serve the run's live ROS topics to Foxglove and Lichtblick over the Foxglove
WebSocket protocol (raw CDR with ros2msg schemas, as foxglove_bridge does), for pip-only installs where
foxglove_bridge is not available (`ros.foxglove_bridge`, docs/foxglove.md)."""

from __future__ import annotations

import argparse
import re

from rta_attitude.errors import RtaError

DEFAULT_PORT = 8765


def _regex(text: str) -> re.Pattern[str]:
    try:
        return re.compile(text)
    except re.error as exc:
        raise argparse.ArgumentTypeError(f"not a regular expression: {text!r} ({exc})") from None


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port {port} is not in 0..65535")
    return port


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude foxglove`."""
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=_port, default=DEFAULT_PORT,
                        help=f"WebSocket port (default {DEFAULT_PORT}; 0 = any free port, printed at start)")
    parser.add_argument("--topics", type=_regex, nargs="+", action="extend", default=None, metavar="REGEX",
                        help="serve only topics whose full name matches one of these (default: every topic)")
    parser.add_argument("--exclude", type=_regex, nargs="+", action="extend", default=[], metavar="REGEX",
                        help="leave out topics whose full name matches one of these")
    parser.add_argument("--sim-time", action="store_true",
                        help="follow /clock: use_sim_time, and /clock sent as the server time (Foxglove 'time')")
    parser.add_argument("--legacy-port", type=_port, default=None,
                        help="also accept clients that offer only the subprotocol foxglove.websocket.v1 (Lichtblick "
                             "before foxglove.sdk.v1 support) on this port, through a relay (0 = any free port)")
    parser.add_argument("--rescan-period", type=float, default=1.0,
                        help="seconds between scans of the graph for new or vanished topics (default 1)")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude foxglove`: returns 0 when interrupted (SIGINT/SIGTERM)."""
    if args.rescan_period <= 0:
        raise RtaError(f"--rescan-period must be > 0, got {args.rescan_period}")
    try:
        import foxglove  # noqa: F401  (only this command needs foxglove-sdk)
    except ImportError as exc:
        raise RtaError(f"this command needs foxglove-sdk (pip install foxglove-sdk==0.30.3): {exc}") from None
    try:
        from rta_attitude.ros.foxglove_bridge import BridgeConfig, serve
    except ImportError as exc:
        raise RtaError(f"this command needs rclpy (pip install ros-jazzy-rclpy ros-jazzy-rmw-fastrtps-cpp): {exc}") \
            from None
    config = BridgeConfig(
        include=tuple(args.topics or [re.compile(".*")]),
        exclude=tuple(args.exclude),
        sim_time=args.sim_time,
        rescan_period=args.rescan_period,
    )
    return serve(args.host, args.port, config, legacy_port=args.legacy_port)


__all__ = ["DEFAULT_PORT", "add_arguments", "run"]
