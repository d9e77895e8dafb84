"""rta_attitude.ros.replay and rta_attitude.ros.topic_tools over real rclpy and Fast DDS (no mocks).

A short in-process run is written as a bag with the nodes' own message builders; `rta-attitude
replay` republishes it from a subprocess while this process (its own rclpy context) and the CLI
(`topics`, `echo`, in subprocesses) watch. The conftest gives the session its own ROS_DOMAIN_ID,
localhost only. Every process started here is stopped with SIGINT/SIGTERM and must exit 0.
"""

from __future__ import annotations

import dataclasses
import io
import itertools
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from helpers import to_torque

from rta_attitude import config
from rta_attitude.cli.main import main as cli_main
from rta_attitude.recording.bag import BagWriter, read_bag
from rta_attitude.ros.replay import ros_node
from rta_attitude.ros.topic_tools import (
    echo,
    list_topics,
    measured_rate_hz,
    message_to_dict,
    message_to_yaml,
    resolve_topic,
)
from rta_attitude.simulation.closed_loop import ClosedLoop

pytestmark = pytest.mark.dds
REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}
STEPS = 30
RATE = 20.0
"""Replay speed: 20 samples per wall second (dt = 1 s)."""
WAIT_FOR = ("--wait-for", "/rta/state", "--wait-for", "/rta/filter_status", "--wait-for", "/rta/torque_cmd",
            "--wait-for", "/clock")
"""`topics` waits for these (discovery is asynchronous; under load it takes seconds)."""


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 30-step RTA run of paper-example as the recorder writes it (state, /clock, torques, status),
    in the recorder's (arrival) order."""
    from rta_attitude.ros import convert

    cfg = config.load()
    loop = ClosedLoop(cfg, dataclasses.replace(cfg.scenario("paper-example"), duration_s=float(STEPS)))
    traj = loop.run()
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    with BagWriter(path) as w:
        for topic, type_name in (("/clock", "rosgraph_msgs/msg/Clock"), ("/rta/state", "sensor_msgs/msg/JointState"),
                                 ("/rta/torque_cmd", "geometry_msgs/msg/Vector3Stamped"),
                                 ("/rta/torque_applied", "geometry_msgs/msg/Vector3Stamped"),
                                 ("/rta/filter_status", "diagnostic_msgs/msg/DiagnosticArray")):
            w.add_topic(topic, type_name)
        for k in range(STEPS):
            t = k * 1_000_000_000
            res = loop.filter.filter(traj.x[k], traj.u_des[k])
            w.write_message("/rta/state", convert.state_msg(traj.x[k], t), t)
            w.write_message("/clock", convert.clock_msg(t), t)
            if k:  # the plant publishes the torque it held over the previous step after the new state
                tau = to_torque(traj.u[k - 1], cfg)
                w.write_message("/rta/torque_applied", convert.torque_msg(tau, t - 1_000_000_000), t - 1_000_000_000)
            w.write_message("/rta/torque_cmd", convert.torque_msg(to_torque(res.u, cfg), t), t)
            w.write_message("/rta/filter_status", convert.filter_status_msg(
                res, t, loop.filter.counters, "robust", ("communication",)), t)
    return path


@pytest.fixture(scope="module")
def recorded(bag: Path) -> dict[str, dict[int, Any]]:
    """topic -> {stamp [ns]: decoded message} of the bag."""
    out: dict[str, dict[int, Any]] = {}
    for m in read_bag(bag).messages:
        out.setdefault(m.topic, {})[m.log_time_ns] = m.message
    return out


def _cli(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "rta_attitude.cli", *args], cwd=REPO, env=ENV, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _read_until(proc: subprocess.Popen[str], marker: str, timeout_s: float) -> str:
    """Lines of proc's stdout up to and including the first that contains `marker` (fails the test if
    none does within timeout_s)."""
    lines: list[str] = []
    found = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if marker in line:
                found.set()
                return

    threading.Thread(target=read, daemon=True).start()
    if not found.wait(timeout_s):
        pytest.fail(f"no {marker!r} in the output within {timeout_s:g} s: {''.join(lines)!r}")
    return "".join(lines)


def _stop(proc: subprocess.Popen[str], sig: int) -> tuple[int, str, str]:
    """Stop a child with `sig` (never SIGKILL unless it hangs, which fails the test)."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        stacks = subprocess.run(["py-spy", "dump", "--pid", str(proc.pid)], capture_output=True, text=True).stdout \
            if shutil.which("py-spy") else ""
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"process did not stop on signal {sig}: {err}\n{stacks}")
    return proc.returncode, out, err


# ----------------------------------------------------------------------------- YAML (no DDS)


def test_message_to_yaml_has_ros2_topic_echo_layout() -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from sensor_msgs.msg import JointState

    msg = JointState(name=["q1", "q2"], position=[0.5, -1e-9])
    msg.header.stamp.sec, msg.header.frame_id = 3, "hill"
    assert message_to_yaml(msg) == (
        "header:\n  stamp:\n    sec: 3\n    nanosec: 0\n  frame_id: hill\nname:\n- q1\n- q2\n"
        "position:\n- 0.5\n- -1.0e-09\nvelocity: []\neffort: []\n")
    diag = DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.WARN, name="filter",
                                                    values=[KeyValue(key="status", value="solved")])])
    d = message_to_dict(diag)
    assert d["status"][0]["level"] == "\x01"  # a `byte` prints as one character, as rosidl_runtime_py does
    assert d["status"][0]["values"] == [{"key": "status", "value": "solved"}]
    assert list(d) == ["header", "status"] and list(d["status"][0]) == ["level", "name", "message", "hardware_id",
                                                                        "values"]
    long = JointState(name=["a" * 5], position=list(range(6)))
    assert message_to_dict(long, truncate_length=4)["name"] == ["aaaa..."]
    assert message_to_dict(long, truncate_length=4)["position"] == [0.0, 1.0, 2.0, 3.0, "..."]
    assert message_to_dict(long, no_arr=True)["position"] == "<sequence, length: 6>"
    assert yaml.safe_load(message_to_yaml(diag))["status"][0]["name"] == "filter"


def test_topic_names_and_bad_arguments(bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert resolve_topic("rta/state") == "/rta/state" and resolve_topic("/clock") == "/clock"
    for bad in ("", "/rta//state", "/1abc", "/rta/st-ate"):
        with pytest.raises(Exception, match="not a valid topic name"):
            resolve_topic(bad)
    cases = {
        ("replay", str(bag.parent / "nope.mcap")): f"{bag.parent / 'nope.mcap'}: no such file",
        ("replay", str(bag), "--rate", "0"): "--rate must be a finite number > 0, got 0.0",
        ("replay", str(bag), "--topics", "/chatter"): f"{bag}: no topic /chatter",
        ("echo", "/rta/state", "no_such_msgs/msg/Thing"): "message type no_such_msgs/msg/Thing is not installed",
        ("topics", "--window", "-1"): "--window must be a number of seconds > 0, got -1.0",
        ("topics", "--spin-time", "nan"): "--spin-time must be a number of seconds > 0, got nan",
        ("topics", "--wait-for", "/a//b"): "'/a//b': not a valid topic name",
        ("echo", "/x", "--spin-time", "0"): "--spin-time must be a number of seconds > 0, got 0.0",
    }
    for argv, message in cases.items():
        assert cli_main(list(argv)) == 1, argv
        err = capsys.readouterr().err
        assert err.startswith(f"ERROR: {message}") and err.count("\n") == 1, (argv, err)


def test_measured_rate_is_messages_per_second() -> None:
    assert measured_rate_hz([], 1.0) is None and measured_rate_hz([0.5], 1.0) is None
    assert measured_rate_hz([1.0, 1.1], 1.0) is None  # window ended before the messages: no rate
    # 11 messages from t = 2 s, window ends at 4.5 s: 10 intervals over 2.5 s
    assert measured_rate_hz([2.0 + 0.25 * k for k in range(11)], 4.5) == pytest.approx(4.0)
    # a backlog delivered at once late in the window still counts over the whole span
    assert measured_rate_hz([2.0, 4.4, 4.4, 4.4, 4.4], 4.5) == pytest.approx(4 / 2.5)


def test_topics_waits_for_a_named_topic_and_fails_with_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    """No publisher of the named topic: `topics --wait-for` waits --spin-time, then one ERROR line."""
    t0 = time.monotonic()
    assert cli_main(["topics", "--wait-for", "/rta/nobody_publishes_this", "--spin-time", "1", "--no-rates"]) == 1
    assert time.monotonic() - t0 >= 1.0
    err = capsys.readouterr().err
    assert err.startswith("ERROR: no publisher of /rta/nobody_publishes_this within 1 s") and err.count("\n") == 1


# ----------------------------------------------------------------------------- live


def test_replay_topics_and_echo_over_dds(bag: Path, recorded: dict[str, dict[int, Any]]) -> None:
    """One looping replay; this process checks what arrives, lists the graph and echoes a topic;
    the CLI does the same from subprocesses, in parallel; then everything stops by signal, exit 0."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    replay = _cli("replay", str(bag), "--rate", str(RATE), "--loop", "--delay", "0")
    once = _cli("replay", str(bag), "--rate", "1000", "--delay", "0.2", "--topics", "/rta/torque_cmd", "--no-clock")
    children: dict[str, subprocess.Popen[str]] = {}
    try:
        with ros_node("_test_inspect") as node:
            states: dict[int, np.ndarray] = {}
            clocks: list[int] = []
            qos = QoSProfile(depth=100)
            node.create_subscription(JointState, "/rta/state", lambda m: states.setdefault(
                m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, np.array(m.position)), qos)
            node.create_subscription(Clock, "/clock", lambda m: clocks.append(
                m.clock.sec * 1_000_000_000 + m.clock.nanosec), qos)
            executor = SingleThreadedExecutor(context=node.context)
            executor.add_node(node)
            deadline = time.monotonic() + 30
            while (len(states) < 10 or len(clocks) < 10) and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            assert len(states) >= 10 and len(clocks) >= 10, (len(states), len(clocks))
            # CLI inspection while the replay runs (subprocesses, in parallel with the checks below)
            children = {
                "topics": _cli("topics", "--window", "1.5", "--spin-time", "60", *WAIT_FOR),
                "echo_once": _cli("echo", "rta/state", "--once", "--spin-time", "60"),
                "echo_missing": _cli("echo", "/rta/nothing", "--once", "--spin-time", "2"),
                "echo_forever": _cli("echo", "/clock", "--spin-time", "60"),
            }
            executor.shutdown()
            for stamp, x in states.items():  # bit-exact: the bag's bytes were republished
                np.testing.assert_array_equal(x, np.array(recorded["/rta/state"][stamp].position))
            assert set(clocks) <= set(recorded["/clock"])
            # in log-time order although torque_applied(t_k-1) follows state(t_k) in the file: the clock
            # only advances, by one step (or starts over with --loop)
            assert all(b - a == 1_000_000_000 or b == 0 for a, b in itertools.pairwise(clocks)), [
                (a, b) for a, b in itertools.pairwise(clocks) if not (b - a == 1_000_000_000 or b == 0)]
            rows = {r["topic"]: r for r in list_topics(node, window_s=1.5, spin_time_s=60.0, rates=True,
                                                       wait_for=WAIT_FOR[1::2])}
            state_row = rows["/rta/state"]
            assert state_row["type"] == "sensor_msgs/msg/JointState" and state_row["publishers"] == 1
            # rates are wall-clock measurements (their arithmetic: test_measured_rate_is_messages_per_second);
            # here only that messages were counted on the live topics
            assert state_row["messages"] >= 2 and state_row["rate_hz"] > 0, state_row
            assert rows["/clock"]["messages"] >= 2 and rows["/clock"]["rate_hz"] > 0, rows["/clock"]
            assert rows["/rta/filter_status"]["type"] == "diagnostic_msgs/msg/DiagnosticArray"
            buf = io.StringIO()
            assert echo(node, "/rta/torque_cmd", None, 2, 60.0, 60.0, 128, False, out=buf) == 2
            docs = [d for d in yaml.safe_load_all(buf.getvalue()) if d is not None]
            assert len(docs) == 2
            for d in docs:
                t = d["header"]["stamp"]["sec"] * 1_000_000_000 + d["header"]["stamp"]["nanosec"]
                want = recorded["/rta/torque_cmd"][t].vector
                assert d["vector"] == {"x": want.x, "y": want.y, "z": want.z}
                assert d["header"]["frame_id"] == "body"
        results = {name: p.wait(timeout=300) for name, p in children.items() if name != "echo_forever"}
        assert results["topics"] == 0, children["topics"].communicate()
        listing = children["topics"].communicate()[0]
        assert "/rta/state" in listing and "sensor_msgs/msg/JointState" in listing and "Hz" in listing
        assert results["echo_once"] == 0
        once_doc = yaml.safe_load(children["echo_once"].communicate()[0].split("---")[0])
        assert once_doc["name"] == list(recorded["/rta/state"][0].name) and len(once_doc["position"]) == 19
        assert results["echo_missing"] == 1
        err = children["echo_missing"].communicate()[1]
        assert err.startswith("ERROR: topic /rta/nothing: no publisher found within 2 s") and err.count("\n") == 1
        forever = children.pop("echo_forever")
        first = _read_until(forever, "---", timeout_s=60)  # it printed a message before it is stopped
        code, out, err = _stop(forever, signal.SIGINT)
        out = first + out
        assert code == 0 and "Traceback" not in err and out.count("---") >= 1 and "clock:" in out
    finally:
        for p in children.values():
            _stop(p, signal.SIGINT)
        code, out, err = _stop(replay, signal.SIGTERM)
        o_code, o_out, o_err = _stop(once, signal.SIGTERM)  # long done by now
    assert code == 0 and "Traceback" not in err, err
    assert out.startswith(f"replaying {bag}: {STEPS * 4 - 1} messages on 4 topics + /clock") and "replay done:" in out
    assert o_code == 0 and "replay done: 30 messages" in o_out and "(1 complete pass)" in o_out, o_out + o_err
