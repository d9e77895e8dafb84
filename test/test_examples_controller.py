"""examples/my_controller_node.py, the template of a controller node of one's own.

- It follows the run's vocabulary (rta_attitude.topics: QoS, frame) although it imports nothing of the
  package, and its law is a PD on the package's attitude error (`dynamics.quaternion.error_vectors`);
- over real Fast DDS: `rta-attitude launch --controller none` (plant, filter, recorder) and the template as
  a process of its own give a SAFE run whose bag holds the template's torque_des, one per state, in the
  body frame, stamped like its state, with the values of its law for the recorded state; the filter
  rejected none and the template exits when the run has ended.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from rta_attitude import topics
from rta_attitude.dynamics.quaternion import error_vectors
from rta_attitude.recording.bag import read_bag
from rta_attitude.ros import interface

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "my_controller_node.py"
NS = topics.DEFAULT_NAMESPACE
RUN_TIMEOUT_S = 400
"""The launcher's deadline: room for a first start that compiles numba's kernels (a source edited under a running
suite makes the nodes compile again), which its default (from the scenario length) does not leave."""


def _template() -> ModuleType:
    spec = importlib.util.spec_from_file_location("my_controller_node", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_template_speaks_the_runs_vocabulary_and_its_law_is_a_pd_on_the_attitude_error() -> None:
    m = _template()
    assert 60 <= len(EXAMPLE.read_text().splitlines()) <= 120  # a page a user reads and copies
    assert "rta_attitude" not in {line.split()[1].split(".")[0] for line in EXAMPLE.read_text().splitlines()
                                  if line.startswith(("import ", "from "))}  # plain rclpy and numpy
    assert m.BODY_FRAME == topics.BODY_FRAME
    for mine, spec in ((m.STREAM_QOS, topics.STREAM_QOS), (m.STATUS_QOS, topics.STATUS_QOS)):
        run = interface.qos_profile(spec)
        assert (mine.reliability, mine.durability, mine.history) == (run.reliability, run.durability, run.history)
    rng = np.random.default_rng(3)
    kp, kd = 2e-3, 1.5e-2
    for _ in range(200):
        q, qt = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 4)))
        omega = rng.normal(scale=0.01, size=3)
        tau = m.control_law(q, omega, qt, kp, kd)
        shorter = 1.0 if q @ qt >= 0.0 else -1.0  # the sign of the error's scalar part
        expected = -kp * shorter * error_vectors(q, qt) - kd * omega
        np.testing.assert_allclose(tau, np.clip(expected, -m.TORQUE_MAX_NM, m.TORQUE_MAX_NM), rtol=1e-12,
                                   atol=1e-18)
    assert np.array_equal(m.control_law(qt, np.zeros(3), qt, kp, kd), np.zeros(3))  # at the target: no torque


@pytest.mark.dds
@pytest.mark.slow
def test_launch_without_controller_and_the_template_node_is_a_safe_run_of_its_commands(tmp_path: Path) -> None:
    m = _template()
    steps = 40
    bag, out = tmp_path / "run.mcap", tmp_path / "out"
    launcher = subprocess.Popen([sys.executable, "-m", "rta_attitude.cli.launch", "--controller", "none",
                                 "--duration", str(steps), "--bag", str(bag), "--out", str(out),
                                 "--timeout", str(RUN_TIMEOUT_S)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with open(tmp_path / "controller.log", "wb") as log:
        node = subprocess.Popen([sys.executable, str(EXAMPLE), "--ros-args", "-r", f"__ns:={NS}"], stdout=log,
                                stderr=subprocess.STDOUT, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        printed, errors = launcher.communicate(timeout=RUN_TIMEOUT_S + 60)
        node.wait(timeout=60)  # the template exits once the run has ended
    finally:
        for proc in (launcher, node):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    said = (tmp_path / "controller.log").read_text()
    assert launcher.returncode == 0, printed[-2000:] + errors[-2000:] + said
    assert node.returncode == 0 and "the run ended: done" in said, said
    assert "SAFE: no non-slacked constraint violated" in printed.splitlines()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["safe"] and summary["launch"]["run_state"] == topics.RUN_DONE
    assert set(summary["launch"]["exit_codes"]) == {topics.EXECUTABLES[r] for r in
                                                    (topics.RECORDER, topics.FILTER, topics.PLANT)}
    assert summary["bag"]["commands"] == {"received": steps + 1, "rejected": 0, "reason": "", "missing": 0,
                                          "answered": steps + 1}
    assert summary["bag"]["verdict"] == {"data_ends_s": None, "caveats": []}

    contents = read_bag(bag, topics=[f"{NS}/{topics.ODOMETRY}", f"{NS}/{topics.TORQUE_DES}"])
    odometry = {_stamp(x.message): x.message for x in contents.messages if x.topic.endswith(topics.ODOMETRY)}
    answers = [x.message for x in contents.messages if x.topic.endswith(topics.TORQUE_DES)]
    assert len(answers) == len(odometry) == steps + 1
    assert {_stamp(a) for a in answers} == set(odometry)  # one answer per state, stamped like it
    assert {a.header.frame_id for a in answers} == {topics.BODY_FRAME}
    for a in answers:
        state = odometry[_stamp(a)]
        o, w = state.pose.pose.orientation, state.twist.twist.angular
        tau = m.control_law(np.array([o.x, o.y, o.z, o.w]), np.array([w.x, w.y, w.z]), np.array([0.0, 0, 0, 1]),
                            2e-3, 1.5e-2)
        assert [a.vector.x, a.vector.y, a.vector.z] == tau.tolist()  # its own law, to the bit
    assert any(abs(a.vector.x) > 0 for a in answers)


def _stamp(msg: object) -> int:
    stamp = msg.header.stamp  # type: ignore[attr-defined]
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
