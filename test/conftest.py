"""Session-wide test setup.

Before any test module imports rclpy, every test session gets its own DDS domain and stays on
this machine: ROS_DOMAIN_ID is a random value in 40..100 (the range whose ports are safe on Linux
and clear of the usual defaults; set RTA_TEST_DOMAIN_ID to choose one), and
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST. Child processes (the launcher's nodes, colcon) inherit
both, and the launcher keeps them (its --domain-id defaults to $ROS_DOMAIN_ID); under pytest-xdist
each worker is a session with a domain of its own. AMENT_PREFIX_PATH
defaults to sys.prefix, where the pip-installed Jazzy wheels put share/ (message definitions, the
ament index).

Property-based tests (hypothesis) are derandomized: each draws the same examples at every run.

Also: the in-process reference runs of `paper-example` (ClosedLoop.run, with and without RTA),
computed once per session for the tests that compare DDS runs against them.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import random
import sys
import tempfile
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("reproducible", derandomize=True)
settings.load_profile("reproducible")  # property tests draw the same examples every run: never flaky

DOMAIN_RANGE = (40, 100)


def _session_domain() -> int:
    """This session's ROS domain: RTA_TEST_DOMAIN_ID if set, else random in DOMAIN_RANGE. Under
    pytest-xdist every worker gets its own domain (the run's shared random base + the worker's index),
    so that the workers' DDS tests never see each other."""
    chosen = os.environ.get("RTA_TEST_DOMAIN_ID")
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if not worker:
        return int(chosen) if chosen else random.SystemRandom().randint(*DOMAIN_RANGE)
    index, count = int(worker.removeprefix("gw")), int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if chosen:
        base = int(chosen)
    else:  # one base for the whole run: every worker hashes the run's id alike
        run = os.environ.get("PYTEST_XDIST_TESTRUNUID", "")
        span = DOMAIN_RANGE[1] - DOMAIN_RANGE[0] + 1 - count
        base = DOMAIN_RANGE[0] + int(hashlib.sha256(run.encode()).hexdigest(), 16) % max(span, 1)
    return base + index


os.environ["ROS_DOMAIN_ID"] = str(_session_domain())
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

    # pytest-xdist workers take turns: the first compiles and writes numba's cache, the others load it
    lock = os.path.join(tempfile.gettempdir(), f"rta_attitude_kernels_{os.getuid()}.lock")
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            return compile_kernels(config.load())
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def paper_reference() -> dict[bool, Any]:
    """{rta: Trajectory} of `paper-example` run in process (ClosedLoop.run), RTA on and off."""
    from rta_attitude import config
    from rta_attitude.simulation.closed_loop import simulate

    cfg = config.load()
    return {rta: simulate(cfg, "paper-example", rta=rta) for rta in (True, False)}
