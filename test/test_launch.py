"""`rta-attitude launch` (rta_attitude.cli.launcher): the four nodes as separate OS processes over
Fast DDS, the bag, the summary, clean shutdown (no stray process, nothing left in /dev/shm)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from rta_attitude import config, topics
from rta_attitude.recording.bag import read_bag
from rta_attitude.simulation.closed_loop import ClosedLoop
from rta_attitude.simulation.metrics import format_summary, summarize_trajectory

pytestmark = pytest.mark.dds
CFG = config.load()
TIMING_KEYS = {"filter_time_us", "wall_time_s", "launch", "bag"}
"""Summary keys that differ between runs by nature (wall-clock timing, provenance)."""


def _launch(*args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rta_attitude.cli.launch", *args], capture_output=True, text=True,
                          timeout=timeout)


def _reference_summary(traj: Any) -> dict[str, Any]:
    cfg = CFG.for_scenario(CFG.scenario(traj.scenario))
    return summarize_trajectory(traj, cfg)


def _survivors(marker: str) -> list[int]:
    """PIDs of live processes whose command line contains `marker`."""
    pids = []
    for pid in os.listdir("/proc"):
        if pid.isdigit() and int(pid) != os.getpid():
            try:
                if marker in Path(f"/proc/{pid}/cmdline").read_text(errors="replace"):
                    pids.append(int(pid))
            except OSError:
                continue
    return pids


def _check_clean(summary: dict[str, Any], bag: Path) -> None:
    run = summary["launch"]
    assert run["problems"] == []
    assert run["shm_clean"] is True
    assert set(run["exit_codes"].values()) == {0}
    # the plant and the recorder exit on their own; controller, filter and the scene stop at the first SIGINT
    stopped = (topics.CONTROLLER, topics.FILTER, topics.SCENE)
    assert run["signals"] == {topics.EXECUTABLES[r]: ["SIGINT"] for r in stopped
                              if topics.EXECUTABLES[r] in run["exit_codes"]}
    assert _survivors(str(bag)) == []


@pytest.mark.slow
def test_launch_paper_example_as_four_processes_prints_the_simulate_summary(
        tmp_path: Path, paper_reference: dict) -> None:
    bag, out = tmp_path / "run.mcap", tmp_path / "out"
    proc = _launch("--scenario", "paper-example", "--bag", str(bag), "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    expected = _reference_summary(paper_reference[True])
    assert {k: v for k, v in summary.items() if k not in TIMING_KEYS} == \
        {k: v for k, v in expected.items() if k not in TIMING_KEYS}
    table = [line for line in format_summary(expected).splitlines() if not line.startswith("filter call")]
    printed = proc.stdout.splitlines()
    assert all(line in printed for line in table)
    _check_clean(summary, bag)
    assert summary["launch"]["run_state"] == topics.RUN_DONE
    assert summary["launch"]["deadline_misses"] == 0
    assert summary["bag"]["reintegration_residual"] == 0.0
    counts = read_bag(bag, decode=False).counts
    assert counts["/rta/state"] == 2001 and counts["/rta/filter_status"] == 2001 and counts["/clock"] == 2001
    assert (out / "logs" / "plant_node.log").exists()


def test_launch_without_rta_short_run(tmp_path: Path) -> None:
    steps = 150
    bag, out = tmp_path / "plain.mcap", tmp_path / "out"
    proc = _launch("--no-rta", "--duration", str(steps), "--bag", str(bag), "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    scenario = replace(CFG.scenario("paper_example"), duration_s=float(steps))
    expected = _reference_summary(ClosedLoop(CFG, scenario, rta=False).run())
    assert {k: v for k, v in summary.items() if k not in TIMING_KEYS} == \
        {k: v for k, v in expected.items() if k not in TIMING_KEYS}
    _check_clean(summary, bag)
    counts = read_bag(bag, decode=False).counts
    assert "/rta/filter_status" not in counts and counts["/rta/torque_cmd"] == steps + 1


@pytest.mark.parametrize(("args", "message"), [
    (["--scenario", "nope"], "unknown scenario 'nope'"),
    (["-p", "filter.fallback=pray"], "fallback must be one of"),
    (["--realtime", "0"], "--realtime must be > 0"),
    (["-p", "novalue"], "expected KEY=VALUE"),
])
def test_launch_checks_inputs_before_starting_anything(args: list[str], message: str, tmp_path: Path) -> None:
    proc = _launch(*args, "--bag", str(tmp_path / "x.mcap"), timeout=300)
    assert proc.returncode == 1
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_launch_without_bag_or_out_leaves_no_temporary_files(tmp_path: Path) -> None:
    """The temporary bag, its directory and the temporary node logs go when the run ends well."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.run([sys.executable, "-m", "rta_attitude.cli.launch", "--duration", "5"], capture_output=True,
                          text=True, timeout=300, env={**os.environ, "TMPDIR": str(tmp)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "SAFE" in proc.stdout
    assert sorted(p.name for p in tmp.iterdir()) == []


def test_launch_refuses_to_overwrite_a_bag(tmp_path: Path) -> None:
    bag = tmp_path / "old.mcap"
    bag.write_bytes(b"keep me")
    proc = _launch("--bag", str(bag), timeout=300)
    assert proc.returncode == 1 and "exists" in proc.stderr
    assert bag.read_bytes() == b"keep me"


def test_ctrl_c_stops_every_node_and_finalizes_the_bag(tmp_path: Path) -> None:
    bag = tmp_path / "cut.mcap"
    launcher = subprocess.Popen([sys.executable, "-m", "rta_attitude.cli.launch", "--bag", str(bag), "--out",
                                 str(tmp_path / "out")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (bag.exists() and bag.stat().st_size > 300_000):  # a few hundred steps recorded
        assert launcher.poll() is None and time.monotonic() < deadline, launcher.communicate()[1][-2000:]
        time.sleep(0.1)
    launcher.send_signal(signal.SIGINT)
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 1 and "interrupted" in err
    assert "left in /dev/shm" not in err and "SIGKILL" not in err
    assert _survivors(str(bag)) == []
    contents = read_bag(bag, topics=["/rta/state"], decode=False)
    assert not contents.truncated  # the recorder closed the file on SIGINT: footer and summary present
    assert 0 < contents.counts["/rta/state"] < 2001


def test_recorder_finalizes_the_bag_on_sigterm(tmp_path: Path) -> None:
    bag = tmp_path / "term.mcap"
    node = subprocess.Popen([sys.executable, "-m", topics.MODULES[topics.RECORDER], "--ros-args", "-p",
                             f"bag_path:={bag}"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 30
    while not bag.exists():  # the recorder creates the file when its node is up
        assert node.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    node.send_signal(signal.SIGTERM)
    out, _ = node.communicate(timeout=30)
    assert node.returncode == 0, out
    assert "bag closed" in out and "Traceback" not in out
    contents = read_bag(bag)
    assert not contents.truncated and contents.counts["/state"] == 0  # no __ns given: the root namespace
    assert "rta_attitude" in contents.metadata and "rosbag2" in contents.metadata


def test_launch_realtime_steps_on_the_wall_clock(tmp_path: Path) -> None:
    steps, rtf = 30, 15.0
    bag, out = tmp_path / "rt.mcap", tmp_path / "out"
    proc = _launch("--realtime", str(rtf), "--duration", str(steps), "--bag", str(bag), "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    run = summary["launch"]
    assert run["stepping"] == "realtime" and run["run_state"] == topics.RUN_DONE and run["step"] == steps
    assert steps / rtf * 0.9 <= run["wall_time_s"] <= steps / rtf + 5.0  # paced by the timer, no stall
    assert isinstance(run["deadline_misses"], int)
    _check_clean(summary, bag)
    counts = read_bag(bag, decode=False).counts
    assert counts["/rta/state"] == steps + 1 and counts["/rta/torque_applied"] == steps
