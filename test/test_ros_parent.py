"""A launcher that goes away takes its nodes with it, and the bag is closed.

Stock `ros2 launch` leaves its processes running when it gets SIGTERM (what `docker stop` sends). The nodes
`rta-attitude launch` and the launch file start have the knob `exit_with_parent`: when the process that
started them exits they stop as on SIGTERM (the plant ends the run `interrupted`, the recorder drains and
closes the bag). Over real Fast DDS, each run in a namespace of its own so that its processes can be found:

- SIGTERM to `rta-attitude launch`: it stops its nodes itself; none is left, the bag is complete;
- SIGKILL to `rta-attitude launch` (nothing of it runs any more, as after stock launch's SIGTERM): the nodes
  notice that their parent is gone and stop on their own; none is left, the bag is complete and says
  `interrupted`;
- a node started with the knob by a parent of its own stops cleanly when that parent exits.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from rta_attitude import topics
from rta_attitude.recording.bag import read_bag
from rta_attitude.ros.convert import run_status_from_msg

pytestmark = pytest.mark.dds
DEADLINE_S = 120.0


def _processes(marker: str) -> list[int]:
    """PIDs of live processes (not zombies) whose command line contains `marker`."""
    pids = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            if marker in Path(f"/proc/{pid}/cmdline").read_text(errors="replace") and \
                    Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                pids.append(int(pid))
        except OSError:
            continue
    return pids


def _start(tmp_path: Path) -> tuple[subprocess.Popen[bytes], Path, str]:
    """`rta-attitude launch` of the whole scenario in a namespace of its own, its stdout in a file; returns once
    the bag holds a few hundred steps (the run is under way)."""
    ns = f"/rta_{uuid.uuid4().hex[:8]}"
    bag = tmp_path / "run.mcap"
    with open(tmp_path / "launcher.log", "wb") as log:
        launcher = subprocess.Popen([sys.executable, "-m", "rta_attitude.cli.launch", "--namespace", ns, "--bag",
                                     str(bag), "--out", str(tmp_path / "out"), "--timeout", "600"], stdout=log,
                                    stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 2 * DEADLINE_S  # a first start may compile numba's kernels
    while not (bag.exists() and bag.stat().st_size > 300_000):
        assert launcher.poll() is None and time.monotonic() < deadline, (tmp_path / "launcher.log").read_text()
        time.sleep(0.1)
    assert len(_processes(f"__ns:={ns}")) == 4  # recorder (and its scene), filter, controller, plant
    return launcher, bag, ns


def _wait_gone(marker: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while _processes(marker):
        assert time.monotonic() < deadline, f"still running: {_processes(marker)}"
        time.sleep(0.1)


def _final_state(bag: Path, ns: str) -> str:
    contents = read_bag(bag, topics=[f"{ns}/{topics.RUN_STATUS}", f"{ns}/{topics.STATE}"])
    assert not contents.truncated  # footer, summary: the recorder closed the file
    assert 0 < contents.counts[f"{ns}/{topics.STATE}"] < 2001
    status = [m for m in contents.messages if m.topic.endswith(topics.RUN_STATUS)]
    return run_status_from_msg(status[-1].message)[0]


@pytest.mark.slow
def test_sigterm_to_the_launcher_leaves_no_node_and_a_complete_bag(tmp_path: Path) -> None:
    launcher, bag, ns = _start(tmp_path)
    launcher.send_signal(signal.SIGTERM)
    assert launcher.wait(timeout=DEADLINE_S) == 1  # interrupted: not a complete run
    assert _processes(f"__ns:={ns}") == []
    assert _final_state(bag, ns) == f"{topics.RUN_INTERRUPTED}: SIGINT"  # the launcher stops them with SIGINT
    log = (tmp_path / "launcher.log").read_text()
    assert "interrupted" in log and "SIGKILL" not in log and "Traceback" not in log


@pytest.mark.slow
def test_nodes_stop_cleanly_when_their_launcher_is_killed(tmp_path: Path) -> None:
    launcher, bag, ns = _start(tmp_path)
    launcher.kill()  # SIGKILL: nothing of the launcher runs, nobody stops the nodes but themselves
    launcher.wait(timeout=DEADLINE_S)
    _wait_gone(f"__ns:={ns}")
    assert _final_state(bag, ns) == f"{topics.RUN_INTERRUPTED}: SIGHUP"  # their parent's exit


def test_a_node_started_by_any_parent_stops_cleanly_when_that_parent_exits(tmp_path: Path) -> None:
    """A parent of its own (a Python process, as `ros2 launch` is one) starts the recorder with the knob and
    exits once the node is up: the node stops as on SIGTERM and closes its bag."""
    bag, log = tmp_path / "orphan.mcap", tmp_path / "node.log"
    node = [sys.executable, "-m", topics.MODULES[topics.RECORDER], "--ros-args", "-p", f"bag_path:={bag}",
            "-p", "exit_with_parent:=true"]
    parent = (f"import subprocess, pathlib, time\n"
              f"log = open({str(log)!r}, 'wb')\n"
              f"subprocess.Popen({node!r}, stdout=log, stderr=subprocess.STDOUT)\n"
              f"deadline = time.monotonic() + {DEADLINE_S}\n"
              f"while not pathlib.Path({str(bag)!r}).exists() and time.monotonic() < deadline:\n"
              f"    time.sleep(0.05)\n")
    assert subprocess.run([sys.executable, "-c", parent], timeout=DEADLINE_S).returncode == 0
    assert bag.exists()  # the node was up when its parent exited
    _wait_gone(f"bag_path:={bag}")
    text = log.read_text()
    assert "SIGHUP: stopping" in text and "bag closed" in text and "Traceback" not in text, text
    assert not read_bag(bag).truncated
