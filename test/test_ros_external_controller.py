"""`rta-attitude launch --controller none` over real Fast DDS: plant, filter and recorder without the PD
controller node, the run driven by a controller node of the user's (here one in the test process, plain
rclpy), and what the filter makes of commands it cannot use.

The user's node answers the first WRONG states with torque_des in frame `base_link`, the next RIGHT in `body`,
then goes away. The run still ends: the filter filters the rejected commands as u_des = 0 (its counted
non-finite-u_des fallback) and answers the states after the controller left with u_des = 0 (counted as
missing). filter_status counts both and says why the commands were rejected, /diagnostics names the trouble
while it lasts, and the launcher's verdict from the bag is not a plain SAFE. Without any controller node the
plant ends the run after `startup_timeout_s` with one line saying what it waited for.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import rclpy
from rclpy.duration import Duration

from rta_attitude import topics
from rta_attitude.recording.bag import read_bag
from rta_attitude.ros import convert, interface
from rta_attitude.ros.spin import make_executor

pytestmark = pytest.mark.dds
NS = topics.DEFAULT_NAMESPACE
WRONG, RIGHT, STEPS = 15, 10, 40
FILTER_STATUS_NAME = f"{NS}/{topics.NODE_NAMES[topics.FILTER]}: filter"
RUN_TIMEOUT_S = 400
"""The launcher's deadline: room for a first start that compiles numba's kernels (a source edited under a running
suite makes the nodes compile again), which its default (from the scenario length) does not leave."""


def _launch(tmp_path: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "rta_attitude.cli.launch", "--controller", "none", "--bag",
                             str(tmp_path / "run.mcap"), "--out", str(tmp_path / "out"), "--timeout",
                             str(RUN_TIMEOUT_S), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_external_controller_readers_are_counted_by_the_plant_not_by_role() -> None:
    for topic in (topics.ODOMETRY, topics.ATTITUDE_COMMAND):
        assert topics.CONTROLLER in topics.reader_roles(topic, rta=True, record=True)
        assert topics.CONTROLLER not in topics.reader_roles(topic, rta=True, record=True, external_controller=True)
    assert topics.expected_readers(topics.ODOMETRY, rta=True, record=True, external_controller=True) == 2
    assert topics.expected_readers(topics.ODOMETRY, rta=False, record=False, external_controller=True) == 0


@pytest.mark.slow
def test_a_users_controller_that_sends_a_wrong_frame_then_leaves_still_ends_the_run_and_the_verdict_says_so(
        tmp_path: Path) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    launcher = _launch(tmp_path, "--duration", str(STEPS))
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("flaky_controller", namespace=NS, context=context)
    executor = make_executor("single", context=context)
    executor.add_node(node)
    spec = topics.TOPICS[topics.TORQUE_DES]
    pub = node.create_publisher(interface.msg_class(spec.type_name), spec.name, interface.qos_profile(spec.qos))
    statuses: list[Any] = []
    diag = node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, lambda m: statuses.extend(
        s for s in m.status if s.name == FILTER_STATUS_NAME), interface.qos_profile(topics.DIAGNOSTICS_QOS))
    answered: list[int] = []

    def on_state(msg: Any) -> None:
        if len(answered) == WRONG + RIGHT:
            return  # gone (its publisher is destroyed below)
        t_ns = convert.stamp_ns(msg.header.stamp)
        out = convert.torque_msg([1e-4, -2e-4, 5e-5], t_ns)
        out.header.frame_id = "base_link" if len(answered) < WRONG else topics.BODY_FRAME
        pub.publish(out)
        answered.append(t_ns)

    def spin_until(cond: Any, what: str, timeout_s: float = 120.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not cond():
            assert time.monotonic() < deadline and launcher.poll() is None, f"{what}: {launcher.poll()}"
            executor.spin_once(timeout_sec=0.05)

    try:
        # as the template does: the readers of torque_des (filter, recorder) first, then the state; and the
        # filter's and the plant's /diagnostics before the run starts
        spin_until(lambda: pub.get_subscription_count() >= 2 and diag.get_publisher_count() >= 2, "readers",
                   RUN_TIMEOUT_S)
        odometry = topics.TOPICS[topics.ODOMETRY]
        node.create_subscription(interface.msg_class(odometry.type_name), odometry.name, on_state,
                                 interface.qos_profile(topics.STREAM_QOS))
        spin_until(lambda: len(answered) == WRONG + RIGHT, "answers")
        assert pub.wait_for_all_acked(Duration(seconds=10))
        node.destroy_publisher(pub)
        deadline = time.monotonic() + RUN_TIMEOUT_S
        while launcher.poll() is None:
            assert time.monotonic() < deadline, "the run did not end"
            executor.spin_once(timeout_sec=0.05)
        printed, errors = launcher.communicate(timeout=60)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert launcher.returncode == 0, printed[-2000:] + errors[-2000:]
    n = STEPS + 1  # states, the final one answered too
    verdict = (f"SAFE, but {WRONG} of {WRONG + RIGHT} commands were rejected (frame 'base_link'); "
               f"{n - WRONG - RIGHT} of {n} states were answered without a command (u_des = 0): "
               "no non-slacked constraint violated")
    assert verdict in printed.splitlines(), printed[-3000:]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["safe"] and summary["launch"]["run_state"] == topics.RUN_DONE
    assert summary["bag"]["commands"] == {"received": WRONG + RIGHT, "rejected": WRONG, "reason": "frame 'base_link'",
                                          "missing": n - WRONG - RIGHT, "answered": n}
    assert summary["fallbacks"] == WRONG  # the rejected ones: the core's counted non-finite-u_des fallback

    # filter_status, as recorded: the counters and the reason, and the source of every u_des
    contents = read_bag(tmp_path / "run.mcap", topics=[f"{NS}/{topics.FILTER_STATUS}"])
    qp = [convert.diagnostic_values(m.message)[topics.QP_STATUS_NAME] for m in contents.messages]
    assert len(qp) == n
    assert [q["torque_des_rejected"] for q in qp] == [min(k + 1, WRONG) for k in range(n)]
    assert [q[topics.REJECTION_KEY] for q in qp] == ["frame 'base_link'"] * n
    assert [q[topics.INPUT_SOURCE_KEY] for q in qp] == ["torque_des"] * (WRONG + RIGHT) + ["missing"] * (
        n - WRONG - RIGHT)
    assert [q["fallback"] for q in qp] == ["non_finite_u_des"] * WRONG + ["none"] * (n - WRONG)

    # /diagnostics: the filter's status names the trouble while it lasts, with its counters
    messages = [s.message for s in statuses]
    rejected = [s for s in statuses if "torque_des rejected (frame 'base_link')" in s.message]
    assert rejected and all(s.level >= b"\x01" for s in rejected), messages
    values = {kv.key: kv.value for kv in rejected[0].values}
    assert int(values["torque_des_rejected"]) >= 1 and values[topics.REJECTION_KEY] == "frame 'base_link'"
    assert any(m.endswith("torque_des missing (u_des = 0)") for m in messages), messages
    assert messages.index(rejected[0].message) < max(i for i, m in enumerate(messages) if "missing" in m)


def test_without_a_controller_node_the_run_ends_with_one_line_saying_what_it_waited_for(tmp_path: Path) -> None:
    launcher = _launch(tmp_path, "--duration", "10", "-p", "startup_timeout_s=3")
    printed, errors = launcher.communicate(timeout=RUN_TIMEOUT_S + 60)
    assert launcher.returncode == 1
    line = f"no node publishes {NS}/{topics.TORQUE_DES} and reads the state after 3 s"
    assert errors.startswith("ERROR: ") and line in errors.splitlines()[0], errors
    assert "Traceback" not in printed + errors
