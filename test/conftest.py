"""Session-wide test setup.

Before any test module imports rclpy, every test session gets its own DDS domain and stays on
this machine: ROS_DOMAIN_ID is a random value in 40..100 (the range whose ports are safe on Linux
and clear of the usual defaults; set RTA_TEST_DOMAIN_ID to choose one), and
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST. Child processes (the launcher's nodes, colcon) inherit
both, and the launcher keeps them (its --domain-id defaults to $ROS_DOMAIN_ID). AMENT_PREFIX_PATH
defaults to sys.prefix, where the pip-installed Jazzy wheels put share/ (message definitions, the
ament index).

Also: the in-process reference runs of `paper-example` (ClosedLoop.run, with and without RTA),
computed once per session for the tests that compare DDS runs against them.
"""

from __future__ import annotations

import os
import random
import sys
from typing import Any

import pytest

DOMAIN_RANGE = (40, 100)
os.environ["ROS_DOMAIN_ID"] = (os.environ.get("RTA_TEST_DOMAIN_ID")
                               or str(random.SystemRandom().randint(*DOMAIN_RANGE)))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)
os.environ.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")


def pytest_configure(config: Any) -> None:
    config.addinivalue_line("markers", "slow: a whole scenario over DDS, or a colcon build (seconds to a minute)")
    config.addinivalue_line("markers", "dds: real rclpy over real Fast DDS (nodes, processes); bench/flake_hunt.py "
                            "runs these under load")


def pytest_report_header(config: Any) -> str:
    return f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} (localhost only)"


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels() -> float:
    """Every numba kernel, compiled (or loaded from numba's cache, after dropping stale caches) once
    before any test, so the node processes the tests start find them in the cache; returns the seconds
    it took."""
    from rta_attitude import config
    from rta_attitude.simulation.closed_loop import compile_kernels

    return compile_kernels(config.load())


@pytest.fixture(scope="session")
def paper_reference() -> dict[bool, Any]:
    """{rta: Trajectory} of `paper-example` run in process (ClosedLoop.run), RTA on and off."""
    from rta_attitude import config
    from rta_attitude.simulation.closed_loop import simulate

    cfg = config.load()
    return {rta: simulate(cfg, "paper-example", rta=rta) for rta in (True, False)}
