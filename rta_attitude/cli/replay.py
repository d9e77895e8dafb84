"""`rta-attitude replay BAG`: republish a recorded bag over DDS with /clock (`ros.replay`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude replay`."""
    parser.add_argument("bag", type=Path, help="MCAP file (or rosbag2 directory) to republish")
    parser.add_argument("--rate", type=float, default=1.0, help="speed relative to the recording (default 1)")
    parser.add_argument("--loop", action="store_true", help="start over at the end, until interrupted")
    parser.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="replay only these topics")
    parser.add_argument("--no-clock", action="store_true",
                        help="do not publish /clock from the bag time (republish the recorded /clock instead)")
    parser.add_argument("--delay", type=float, default=0.5,
                        help="wait this long (s) after creating the publishers, for readers to match (default 0.5)")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude replay`: returns 0 when done or interrupted."""
    from rta_attitude.ros.replay import replay

    return replay(args.bag, args.rate, args.loop, args.topics, args.no_clock, args.delay)


__all__ = ["add_arguments", "run"]
