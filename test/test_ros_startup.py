"""No node's start-up timeout expires while another node of the run is alive and still starting.

A first start compiles numba's kernels for 40-70 s; with rta:=false nothing made the controller wait for the
filter, so its torque_des gate gave up after its 30 s `startup_timeout_s` (and the plant, with no writer of
torque_cmd yet, after its own). Here the filter is made slow to start instead of cold: a `sitecustomize` on the
children's PYTHONPATH holds the filter process's AsifFilter construction (where it compiles) for SLOW_S, four
times the run's `startup_timeout_s`, with every kernel already in numba's cache.

- `rta-attitude launch --no-rta`: the controller's gate and the plant's first command wait for the filter
  (alive, no endpoints yet) and the run completes; both say in their logs that they waited for it;
- in one process over DDS: a controller whose torque_des has no filter reader waits while a node named like
  the filter is in the graph without endpoints on the run's topics, and fails with one line naming the topic
  once that node has gone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import rclpy
from helpers import starting_peer
from rclpy.parameter import Parameter

from rta_attitude import topics
from rta_attitude.recording.bag import read_bag
from rta_attitude.ros import convert, interface
from rta_attitude.ros.controller_node import ControllerNode
from rta_attitude.ros.spin import make_executor

pytestmark = pytest.mark.dds
NS = topics.DEFAULT_NAMESPACE
STARTUP_TIMEOUT_S = 5.0
"""The run's start-up budget here: long enough for the other readers to be discovered and matched on a loaded
machine (a fresh clone's CI, 2 xdist workers: the plant saw 1 of 2 odometry readers 1.9 s after both reader
nodes were up, and gave up at 2 s), far shorter than the filter's hold (SLOW_S)."""
SLOW_S = 4 * STARTUP_TIMEOUT_S
SLOW_FILTER = f'''
import time
from pathlib import Path

if "rta_attitude.ros.filter_node" in Path("/proc/self/cmdline").read_bytes().decode(errors="replace"):
    from rta_attitude.filter import asif

    _init = asif.AsifFilter.__init__

    def _slow_init(self, *args, **kwargs):
        time.sleep({SLOW_S})  # as a cold numba cache would
        _init(self, *args, **kwargs)

    asif.AsifFilter.__init__ = _slow_init
'''


@pytest.mark.slow
def test_launch_without_rta_waits_for_a_filter_that_is_still_starting(tmp_path: Path) -> None:
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SLOW_FILTER)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(Path(__file__).resolve().parents[1]),
                                                        os.environ.get("PYTHONPATH", "")])}
    bag, out = tmp_path / "plain.mcap", tmp_path / "out"
    steps = 20
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "rta_attitude.cli.launch", "--no-rta", "--no-scene", "--duration",
                           str(steps), "-p", f"startup_timeout_s={STARTUP_TIMEOUT_S}", "--bag", str(bag), "--out",
                           str(out), "--timeout", "400"], capture_output=True, text=True, timeout=460, env=env)
    took = time.monotonic() - t0
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert took > SLOW_S  # the filter really was slow
    summary = json.loads((out / "summary.json").read_text())
    assert summary["launch"]["run_state"] == topics.RUN_DONE and summary["launch"]["problems"] == []
    assert summary["launch"]["deadline_misses"] == 0 and summary["launch"]["step"] == steps
    logs = {role: (out / "logs" / f"{topics.EXECUTABLES[role]}.log").read_text()
            for role in (topics.CONTROLLER, topics.PLANT, topics.FILTER)}
    waiting = f"waiting for {topics.NODE_NAMES[topics.FILTER]} to finish starting"
    assert waiting in logs[topics.CONTROLLER], logs[topics.CONTROLLER][-2000:]  # the torque_des gate
    assert waiting in logs[topics.PLANT], logs[topics.PLANT][-2000:]  # the first command
    assert "filter ready in" in logs[topics.FILTER]
    counts = read_bag(bag, decode=False).counts
    assert counts[f"{NS}/torque_des"] == counts[f"{NS}/torque_cmd"] == counts[f"{NS}/state"] == steps + 1


def test_a_gate_waits_while_a_reader_is_starting_and_fails_once_it_is_gone() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor("single", context=context)
    ctl = ControllerNode(context=context, namespace=NS, parameter_overrides=[Parameter(k, value=v) for k, v in {
        "rta": False, "record": False, "startup_timeout_s": 0.5, "stop_timeout_s": 0.5}.items()])
    starting = starting_peer(topics.FILTER, NS, context)  # a node named like the filter, no endpoints of the run yet
    plant = rclpy.create_node("state_source", namespace=NS, context=context)
    spec = topics.TOPICS[topics.ODOMETRY]
    odometry = plant.create_publisher(interface.msg_class(spec.type_name), spec.name, ctl.qos(topics.ODOMETRY))
    for node in (ctl, starting, plant):
        executor.add_node(node)
    gate = ctl.gates[topics.TORQUE_DES]

    def spin_until(cond: Any, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not cond():
            assert time.monotonic() < deadline
            executor.spin_once(timeout_sec=0.02)

    try:
        spin_until(lambda: odometry.get_subscription_count() >= 1)
        odometry.publish(convert.odometry_msg(_fields(ctl), ctl.epoch_ns))
        spin_until(lambda: gate.extensions >= 2)  # its timeout ran out twice: it waited on
        assert not ctl.finished.done() and gate.sent == 0 and not gate.is_open
        executor.remove_node(starting)
        starting.destroy_node()
        spin_until(lambda: ctl.finished.done())
    finally:
        executor.shutdown()
        for node in (ctl, plant):
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert ctl.exit_code == 1 and gate.sent == 0


def _fields(node: ControllerNode) -> Any:
    """The message fields of the scenario's initial state (dynamics.sensors.message_fields)."""
    from rta_attitude.dynamics.sensors import message_fields, sensors_record

    return message_fields(node.scenario.x0, sensors_record(node.cfg))
