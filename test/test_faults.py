"""Fault tolerance: bad, late and missing input never makes a node emit an invalid command, stall or
lose data; configuration errors are one line and a non-zero exit.

- the filter node, driven through its real callbacks with random and extreme messages (hypothesis):
  every torque_cmd is finite and inside U, every answer is counted and stamped once;
- validation in the nodes: log once per episode, counters in filter_status / run_status, quaternion
  tolerance, stale states against /clock, plant command checks and the lockstep command timeout;
- /clock jumping backwards in a running loop (test_faults_processes.py has the processes killed, hung
  and restarted mid-run);
- configuration errors of nodes, the launcher and the CLI: one line naming parameter, value and
  what is allowed, exit 1, no traceback;
- isolation defaults (localhost discovery, domain id).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from helpers import integrate, starting_peer, to_torque, to_wheel_accel
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message

from rta_attitude import config, topics
from rta_attitude.cli import launch, launcher
from rta_attitude.dynamics.sensors import message_fields, sensors_record
from rta_attitude.errors import MessageError
from rta_attitude.ros import convert, interface
from rta_attitude.ros.faults import FaultLog, StampOrder
from rta_attitude.ros.filter_node import FilterNode
from rta_attitude.ros.plant_node import FIRST_COMMAND_EXTENSIONS, PlantNode
from rta_attitude.ros.spin import make_executor

pytestmark = pytest.mark.dds
CFG = config.load()
U_MAX = CFG.u_max_rad_s2  # the filter's box U (rad/s^2, per axis)
NS = topics.DEFAULT_NAMESPACE
X0 = CFG.scenario("paper_example").x0
S = convert.NS_PER_S
REC = sensors_record(CFG)


# ----------------------------------------------------------------------------- helpers


class Collector:
    """Stands in for a PublishGate: keeps what the node publishes as rclpy messages of the topic's type,
    deserialised by rclpy from the bytes the node sends (a message object is serialised at publish, as rclpy
    does: a node may reuse it once published)."""

    def __init__(self, topic: str) -> None:
        self.msgs: list[Any] = []
        self.sent = 0
        self.msg_type = interface.msg_class(topics.TOPICS[topic].type_name)

    def publish(self, msg: Any) -> None:
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        self.msgs.append(deserialize_message(data, self.msg_type))
        self.sent += 1


class Lines:
    """A logger that keeps its lines (for FaultLog)."""

    def __init__(self) -> None:
        self.warnings: list[str] = []
        self.infos: list[str] = []

    def warning(self, message: str) -> None:
        self.warnings.append(message)

    def info(self, message: str) -> None:
        self.infos.append(message)


@pytest.fixture
def filter_node() -> Any:
    """A FilterNode in its own context, its outputs collected (nothing is spun unless a test does).
    Function-scoped: no DDS participant of the test process outlives its test (the process tests
    below check what the nodes leave in /dev/shm)."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = FilterNode(context=context, namespace=NS, parameter_overrides=[Parameter("record", value=False)])
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _reset(node: FilterNode, gone: bool = False, **knobs: Any) -> dict[str, Collector]:
    """Fresh pairing state, counters and collectors (hypothesis reuses the node across examples). No controller runs
    here: `gone` says whether the node is to take it as gone (after it was heard) or as alive."""
    node.states.clear()
    node.inputs.clear()
    node.refused.clear()
    node.desired.clear()
    node.state_order, node.desired_order = StampOrder(), StampOrder()
    node.answered_ns = -1
    node.heard_controller = False
    node.rejection = ""
    for k in list(node.counts):
        node.counts[k] = 0
    node.faults.active.clear()
    node.faults.episodes.clear()
    node.knobs.update(knobs)
    node._controller_gone = lambda: gone and node.heard_controller  # type: ignore[method-assign]
    node.out = {topics.TORQUE_CMD: Collector(topics.TORQUE_CMD), topics.FILTER_STATUS: Collector(topics.FILTER_STATUS)}
    return node.out


def _state(t_ns: int, x: np.ndarray | list[float] = X0, kind: str = "good") -> list[tuple[str, Any]]:
    """The STATE_INPUTS messages (topic, message) of state x at stamp t_ns (< 0: an invalid stamp), as the
    plant builds them; kind spoils them: `names` (wheel joints reversed), `short` (two wheel velocities),
    `frame` (odometry in the body frame), `partial` (the battery missing)."""
    x = np.asarray(x, dtype=float)
    msgs = convert.state_messages(message_fields(x, REC), 0, CFG.power.bus_voltage_V, 0.0, np.zeros(3))
    for msg in msgs.values():
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, S) if t_ns >= 0 else (-1, 0)
    if kind == "names":
        msgs[topics.WHEELS].name = list(reversed(topics.WHEEL_JOINTS))
    elif kind == "short":
        msgs[topics.WHEELS].velocity = msgs[topics.WHEELS].velocity[:2]
    elif kind == "frame":
        msgs[topics.ODOMETRY].header.frame_id = topics.BODY_FRAME
    elif kind == "partial":
        del msgs[topics.BATTERY]
    return list(msgs.items())


def _feed(node: FilterNode, msgs: list[tuple[str, Any]]) -> None:
    """Hand the messages to the node as its raw subscriptions do: serialised by rclpy (spoiled ones too)."""
    for topic, msg in msgs:
        node._on_input(topic, serialize_message(msg))


def _desired(node: FilterNode, msg: Any) -> None:
    node._on_desired(serialize_message(msg))


def _torque(t_ns: int, tau: np.ndarray | list[float], frame: str = topics.BODY_FRAME) -> Any:
    msg = convert.torque_msg(np.zeros(3), 0)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, S) if t_ns >= 0 else (-1, 0)
    msg.header.frame_id = frame
    msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in tau)
    return msg


def _check_outputs(out: dict[str, Collector]) -> list[int]:
    """Every torque_cmd finite and inside U, one filter_status each, stamps strictly increasing."""
    cmds, statuses = out[topics.TORQUE_CMD].msgs, out[topics.FILTER_STATUS].msgs
    assert len(cmds) == len(statuses)
    stamps = []
    for cmd, status in zip(cmds, statuses):
        t_ns, tau = convert.torque_from_msg(cmd)  # raises if not finite or not in the body frame
        u = to_wheel_accel(tau, CFG)
        assert np.all(np.abs(u) <= U_MAX * (1 + 1e-12)), u
        assert convert.stamp_ns(status.header.stamp) == t_ns
        stamps.append(t_ns)
    assert all(b > a for a, b in itertools.pairwise(stamps)), stamps
    return stamps


# ----------------------------------------------------------------------------- the filter node, property-based

FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.floats(-1e6, 1e6),
                   st.sampled_from([0.0, 1e300, -1e300, 576.0, 181.3]))
STAMPS = st.one_of(st.integers(-1, 40).map(lambda k: k * S if k >= 0 else -1), st.integers(0, 40 * S))


@st.composite
def _state_messages(draw: Any) -> list[tuple[str, Any]]:
    t_ns = draw(STAMPS)
    kind = draw(st.sampled_from(["good", "values", "quaternion", "short", "names", "frame", "partial"]))
    x = X0.copy()
    if kind == "values":
        x = np.array(draw(st.lists(FLOATS, min_size=19, max_size=19)))
    elif kind == "quaternion":
        x[0:4] *= draw(st.floats(0.0, 3.0))
    msgs = _state(t_ns, x, kind)
    return draw(st.permutations(msgs))  # any arrival order


@st.composite
def _torque_messages(draw: Any) -> Any:
    t_ns = draw(STAMPS)
    tau = draw(st.lists(FLOATS, min_size=3, max_size=3))
    frame = draw(st.sampled_from([topics.BODY_FRAME, topics.BODY_FRAME, "hill"]))
    return _torque(t_ns, tau, frame)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(stream=st.lists(st.one_of(_state_messages().map(lambda m: ("state", m)),
                                 _torque_messages().map(lambda m: ("torque_des", m))), max_size=25),
       gone=st.booleans())
def test_filter_node_answers_any_input_with_a_finite_command_inside_U(filter_node: Any, stream: list,
                                                                       gone: bool) -> None:
    node = filter_node
    out = _reset(node, gone=gone)
    fed: dict[str, set[int]] = {"state": set(), "torque_des": set()}
    for topic, item in stream:
        if topic == "state":
            _feed(node, item)
            msg = item[0][1]
            whole = len(item) == len(topics.STATE_INPUTS)
        else:
            _desired(node, item)
            msg, whole = item, True
        if msg.header.stamp.sec >= 0 and whole:
            fed[topic].add(msg.header.stamp.sec * S + msg.header.stamp.nanosec)
    stamps = _check_outputs(out)
    # every answer pairs a state and a torque_des (or, with the controller gone, answers a state alone)
    assert set(stamps) <= (fed["state"] if gone else fed["state"] & fed["torque_des"])
    # the counters in filter_status are running totals: never decreasing, never ahead of the node's
    seen = [[convert.diagnostic_values(m)[topics.QP_STATUS_NAME][k] for k in topics.INPUT_COUNTERS]
            for m in out[topics.FILTER_STATUS].msgs] + [[node.counts[k] for k in topics.INPUT_COUNTERS]]
    assert all(a <= b for row, nxt in itertools.pairwise(seen) for a, b in zip(row, nxt))
    assert len(node.states) <= 64 and len(node.desired) <= 64 and len(node.inputs) <= 64


def test_filter_node_counts_and_logs_each_fault_once_per_episode(filter_node: Any) -> None:
    node = filter_node
    out = _reset(node)
    nan = X0.copy()
    nan[5] = math.nan
    for k in range(50):  # 50 NaN states, each answered with the invalid-state fallback
        _feed(node, _state(k * S, nan))
        _desired(node, _torque(k * S, [1e-4, 0.0, 0.0]))
    _feed(node, _state(50 * S))  # a good one ends the episode
    _desired(node, _torque(50 * S, [1e-4, 0.0, 0.0]))
    for k in range(51, 61):  # a second episode
        _feed(node, _state(k * S, nan))
        _desired(node, _torque(k * S, [0.0, 0.0, 0.0]))
    stamps = _check_outputs(out)
    assert stamps == [k * S for k in range(61)]
    assert node.counts["state_rejected"] == 60 and node.faults.episodes["state_rejected"] == 2
    recs = [convert.filter_record(m, node.filter.names) for m in out[topics.FILTER_STATUS].msgs]
    assert [r["fallback"] for r in recs].count("invalid_state") == 60
    assert all(np.array_equal(r["u"], np.zeros(3)) for r in recs if r["fallback"] == "invalid_state")
    last = convert.diagnostic_values(out[topics.FILTER_STATUS].msgs[-1])[topics.QP_STATUS_NAME]
    assert last["state_rejected"] == 60 and last["invalid_states"] >= 60

    # duplicates, out-of-order and late messages are dropped, counted, logged once
    _feed(node, _state(60 * S))
    _feed(node, _state(59 * S))
    _desired(node, _torque(60 * S, [0.0, 0.0, 0.0]))
    _desired(node, _torque(60 * S, [0.0, 0.0, 0.0]))
    _desired(node, _torque(58 * S, [0.0, 0.0, 0.0]))
    assert (node.counts["state_duplicate"], node.counts["state_out_of_order"]) == (1, 1)
    assert (node.counts["torque_des_duplicate"], node.counts["torque_des_out_of_order"]) == (2, 1)
    assert node.faults.episodes["torque_des_duplicate"] == 1  # two in a row: one line
    assert node.rejection == "stale (out of order)"  # why the latest was rejected
    # a NaN torque_des with a valid stamp: the core's non-finite-u_des fallback answers it
    _feed(node, _state(61 * S))
    _desired(node, _torque(61 * S, [math.nan, 0.0, 0.0]))
    rec = convert.filter_record(out[topics.FILTER_STATUS].msgs[-1], node.filter.names)
    assert rec["fallback"] == "non_finite_u_des" and node.counts["torque_des_rejected"] == 1
    last = convert.diagnostic_values(out[topics.FILTER_STATUS].msgs[-1])[topics.QP_STATUS_NAME]
    assert last[topics.REJECTION_KEY] == "not finite" and last["torque_des_rejected"] == 1
    # a quaternion slightly off unit is renormalised (counted), far off rejected (invalid state, u = 0)
    x = X0.copy()
    x[0:4] *= 1.005
    _feed(node, _state(62 * S, x))
    _desired(node, _torque(62 * S, [0.0, 0.0, 0.0]))
    x[0:4] *= 1.1
    _feed(node, _state(63 * S, x))
    _desired(node, _torque(63 * S, [0.0, 0.0, 0.0]))
    assert node.counts["state_renormalised"] == 1 and node.counts["state_rejected"] == 61
    recs = [convert.filter_record(m, node.filter.names) for m in out[topics.FILTER_STATUS].msgs[-2:]]
    assert recs[0]["fallback"] == "" and recs[1]["fallback"] == "invalid_state"
    # a torque_des in another frame: filtered as u_des = 0 as well, and filter_status says which frame
    _feed(node, _state(64 * S))
    _desired(node, _torque(64 * S, [1e-4, 0.0, 0.0], frame="base_link"))
    last = convert.diagnostic_values(out[topics.FILTER_STATUS].msgs[-1])[topics.QP_STATUS_NAME]
    assert (last["fallback"], last[topics.REJECTION_KEY], last["torque_des_rejected"]) == (
        "non_finite_u_des", "frame 'base_link'", 2)
    _check_outputs(out)


def test_filter_node_answers_a_state_without_torque_des_with_u_des_zero(filter_node: Any) -> None:
    """The timeout is armed by the first torque_des; then a missing one is answered with u_des = 0,
    and its late arrival is dropped and counted."""
    node = filter_node
    out = _reset(node, desired_timeout_s=0.05)
    _feed(node, _state(0))
    time.sleep(0.08)
    node._expire()
    assert out[topics.TORQUE_CMD].msgs == []  # not armed yet: the controller may still be starting
    _desired(node, _torque(0, [1e-4, 0.0, 0.0]))
    _feed(node, _state(1 * S))
    node._expire()
    assert len(out[topics.TORQUE_CMD].msgs) == 1  # within the timeout: still waiting
    time.sleep(0.08)
    node._expire()
    assert len(out[topics.TORQUE_CMD].msgs) == 2
    values = convert.diagnostic_values(out[topics.FILTER_STATUS].msgs[-1])[topics.QP_STATUS_NAME]
    assert values[topics.INPUT_SOURCE_KEY] == "missing" and values["torque_des_missing"] == 1
    assert values["u_des_x"] == values["u_des_y"] == values["u_des_z"] == 0.0
    _desired(node, _torque(1 * S, [1e-4, 0.0, 0.0]))
    assert node.counts["torque_des_late"] == 1 and len(out[topics.TORQUE_CMD].msgs) == 2
    _check_outputs(out)


def test_output_guard_replaces_an_invalid_filter_output_with_zero(filter_node: Any,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Defence in depth: were the core ever to return a non-finite u or one outside U, the node sends 0."""
    node = filter_node
    out = _reset(node)
    real = node.filter.filter
    def corrupted(x: np.ndarray, u: np.ndarray, bad: np.ndarray) -> Any:
        res = real(x, u)
        res.record["u"] = bad
        return res

    for bad in (np.array([math.nan, 0.0, 0.0]), 2.0 * U_MAX):
        monkeypatch.setattr(node.filter, "filter", lambda x, u, bad=bad: corrupted(x, u, bad))
        t_ns = (node.answered_ns // S + 1) * S
        _feed(node, _state(t_ns))
        _desired(node, _torque(t_ns, [0.0, 0.0, 0.0]))
    _check_outputs(out)
    recs = [convert.filter_record(m, node.filter.names) for m in out[topics.FILTER_STATUS].msgs]
    assert [r["fallback"] for r in recs] == ["output_guard"] * 2 and node.counts["output_guard"] == 2
    assert all(np.array_equal(r["u"], np.zeros(3)) for r in recs)


def test_a_lost_peer_back_for_less_than_its_confirmation_is_the_same_episode(filter_node: Any) -> None:
    """A killed writer's late packets can assert its liveliness once more after it was reported lost, and it is
    lost again a lease later (the flake hunt saw it): one episode, one report. Back for good only after
    PEER_BACK_LEASES leases alive (the timer's callback, called here as its firing would)."""
    from types import SimpleNamespace

    from rta_attitude.ros.spin import PEER_BACK_LEASES

    node = filter_node
    _reset(node)
    lost = SimpleNamespace(alive_count=0, not_alive_count=1, alive_count_change=-1, not_alive_count_change=1)
    alive = SimpleNamespace(alive_count=1, not_alive_count=0, alive_count_change=1, not_alive_count_change=-1)
    for info in (lost, alive, lost, alive, lost):
        node._on_liveliness(topics.PLANT, info)
    assert node.faults.episodes["plant_lost"] == 1 and node.counts["plant_lost"] == 1
    assert topics.PLANT in node.lost and not node.returning
    node._on_liveliness(topics.PLANT, alive)
    timer = node.returning[topics.PLANT]
    assert timer.timer_period_ns == round(PEER_BACK_LEASES * node.knobs["liveliness_lease_s"] * 1e9)
    node._peer_back(topics.PLANT)  # alive for the whole confirmation: back
    assert topics.PLANT not in node.lost and "plant_lost" not in node.faults.active and not node.returning
    node._on_liveliness(topics.PLANT, lost)  # a new loss is a new episode
    assert node.faults.episodes["plant_lost"] == 2


def test_stale_states_are_dropped_against_the_sim_clock(filter_node: Any) -> None:
    """With use_sim_time, a state older than /clock by more than max_state_age_s is dropped."""
    from rosgraph_msgs.msg import Clock

    node = filter_node
    out = _reset(node, max_state_age_s=2.0)
    node.set_parameters([Parameter("use_sim_time", value=True)])
    helper = rclpy.create_node("clock_source", context=node.context)
    executor = make_executor("single", context=node.context)
    executor.add_node(node)
    executor.add_node(helper)
    try:
        spec = topics.TOPICS[topics.CLOCK]
        pub = helper.create_publisher(Clock, spec.name, interface.qos_profile(spec.qos))
        deadline = time.monotonic() + 10
        while node.get_clock().now().nanoseconds != 100 * S:
            assert time.monotonic() < deadline, "no /clock"
            pub.publish(convert.clock_msg(100 * S))
            executor.spin_once(timeout_sec=0.05)
        _feed(node, _state(97 * S))  # 3 s old: stale
        _feed(node, _state(99 * S))  # 1 s old: taken
        _desired(node, _torque(99 * S, [0.0, 0.0, 0.0]))
    finally:
        executor.remove_node(node)
        executor.shutdown()
        helper.destroy_node()
        node.set_parameters([Parameter("use_sim_time", value=False)])
    assert node.counts["state_stale"] == 1
    assert _check_outputs(out) == [99 * S]


def test_fault_log_is_once_per_episode_and_counts_every_occurrence() -> None:
    lines = Lines()
    changes: list[tuple[str, bool]] = []
    log = FaultLog(lines, on_change=lambda kind, active: changes.append((kind, active)))
    for _ in range(1000):
        log.fault("stale", "old")
    log.clear("stale", "never_seen")
    log.fault("stale", "old again")
    assert log.counts == {"stale": 1001} and log.episodes == {"stale": 2}
    assert len(lines.warnings) == 2 and len(lines.infos) == 1 and "1000 in a row" in lines.infos[0]
    assert changes == [("stale", True), ("stale", False), ("stale", True)]
    order = StampOrder()
    assert order.check(5) == ""
    order.take(5)
    assert (order.check(5), order.check(4), order.check(6)) == ("duplicate", "out_of_order", "")


def test_quaternion_tolerance_renormalises_within_and_rejects_beyond() -> None:
    x = X0.copy()
    assert convert.unit_attitude(x, 0.01) == (x, False) or convert.unit_attitude(x, 0.01)[1] is False
    x[0:4] *= 1.004
    y, renormalised = convert.unit_attitude(x, 0.01)
    assert renormalised and abs(np.linalg.norm(y[0:4]) - 1.0) < 1e-15 and np.array_equal(y[4:], x[4:])
    x[0:4] *= 1.01
    with pytest.raises(MessageError, match="unit quaternion"):
        convert.unit_attitude(x, 0.01)
    x[0:4] = math.nan
    with pytest.raises(MessageError, match="unit quaternion"):
        convert.unit_attitude(x, 0.01)


# ----------------------------------------------------------------------------- the plant's command checks


def _spin_until(executor: Any, cond: Any, timeout_s: float) -> None:
    """Spin `executor` until `cond()` holds; fail after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline
        executor.spin_once(timeout_sec=0.02)

def test_plant_waits_for_a_reader_that_is_alive_but_still_starting() -> None:
    """A reader node in the graph that has not subscribed yet (a first start compiles the filter's kernels
    for tens of seconds, longer on a loaded machine) does not make the plant give up at startup_timeout_s;
    once that node is gone, the timeout ends the run with one line naming the topic."""
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor("single", context=context)
    plant = PlantNode(context=context, namespace=NS, parameter_overrides=[Parameter(k, value=v) for k, v in {
        "rta": False, "record": False, "startup_timeout_s": 0.5, "stop_timeout_s": 0.5}.items()])
    starting = starting_peer(topics.CONTROLLER, NS, context)  # in the graph, no endpoints of the run yet
    executor.add_node(plant)
    executor.add_node(starting)

    def spin_until(cond: Any, timeout_s: float = 60.0) -> None:
        _spin_until(executor, cond, timeout_s)

    try:
        spin_until(lambda: plant.startup_extensions >= 2)  # the timeout ran out twice: the plant waited on
        assert not plant.finished.done() and plant.published.get(topics.STATE, 0) == 0
        executor.remove_node(starting)
        starting.destroy_node()
        spin_until(lambda: plant.finished.done())
    finally:
        executor.shutdown()
        plant.destroy_node()
        rclpy.try_shutdown(context=context)
    assert plant.exit_code == 1 and plant.published.get(topics.STATE, 0) == 0


@pytest.mark.parametrize("writer", [True, False], ids=["command-writer-alive", "no-command-writer"])
def test_plant_waits_for_the_first_command_bounded(writer: bool) -> None:
    """No first command within startup_timeout_s: while a writer of torque_cmd is alive and matched (the
    chain still discovering itself on a loaded machine) the plant waits that long again, three times, then
    ends the run with one line; with no writer it ends the run after the first startup_timeout_s."""
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor("single", context=context)
    plant = PlantNode(context=context, namespace=NS, parameter_overrides=[Parameter(k, value=v) for k, v in {
        "rta": False, "record": False, "startup_timeout_s": 0.3, "stop_timeout_s": 0.5}.items()])
    stub = rclpy.create_node("silent_filter", namespace=NS, context=context)
    states: list[Any] = []
    spec = topics.TOPICS[topics.ODOMETRY]  # what a controller reads
    stub.create_subscription(interface.msg_class(spec.type_name), spec.name, states.append,
                             interface.qos_profile(spec.qos))
    if writer:
        spec = topics.TOPICS[topics.TORQUE_CMD]
        stub.create_publisher(interface.msg_class(spec.type_name), spec.name, interface.qos_profile(spec.qos))
    executor.add_node(plant)
    executor.add_node(stub)
    try:
        _spin_until(executor, lambda: plant.finished.done(), 60.0)
    finally:
        executor.shutdown()
        stub.destroy_node()
        plant.destroy_node()
        rclpy.try_shutdown(context=context)
    assert len(states) == 1 and plant.exit_code == 1 and plant.counts["commands"] == 0
    if writer:  # the writer matched within the first 0.3 s (one process, quiet or not) or a later one
        assert plant.first_command_extensions == FIRST_COMMAND_EXTENSIONS
    else:
        assert plant.first_command_extensions == 0


def test_plant_checks_commands_and_times_out_in_lockstep(tmp_path: Path) -> None:
    """Over DDS in one process: a plant in lockstep and a stand-in for the filter that sends bad
    commands. NaN or wrong frame: rejected; wrong stamps: future/duplicate/late; beyond the actuator
    limit: applied saturated and counted; no command within command_timeout_s: deadline miss, the
    last torque held once (hold_max_steps 1), then zero; the run goes on."""
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor("single", context=context)
    plant = PlantNode(context=context, namespace=NS, parameter_overrides=[Parameter(k, value=v) for k, v in {
        "rta": False, "record": False, "command_timeout_s": 1.0, "deadline_fallback": "hold", "stop_timeout_s": 0.5,
        "hold_max_steps": 1, "scenarios.paper_example.duration_s": 4.0}.items()])
    stub = rclpy.create_node("filter_stub", namespace=NS, context=context)
    states: list[Any] = []
    spec = topics.TOPICS[topics.ODOMETRY]  # what a controller reads
    stub.create_subscription(interface.msg_class(spec.type_name), spec.name, states.append,
                             interface.qos_profile(spec.qos))
    spec = topics.TOPICS[topics.TORQUE_CMD]
    pub = stub.create_publisher(interface.msg_class(spec.type_name), spec.name, interface.qos_profile(spec.qos))
    executor.add_node(plant)
    executor.add_node(stub)

    def spin_until(cond: Any, timeout_s: float = 60.0) -> None:
        _spin_until(executor, cond, timeout_s)

    e = plant.epoch_ns  # the plant stamps step k with epoch + k dt
    try:
        spin_until(lambda: len(states) == 1 and pub.get_subscription_count() == 1)
        big = to_torque(np.array([2.0 * CFG.limits.wheel_accel_max_rad_s2, 0.0, 0.0]), CFG)
        for msg in (_torque(e, [math.nan, 0.0, 0.0]), _torque(e, [0.0, 0.0, 0.0], "hill"), _torque(e + 5 * S, big),
                    _torque(e, big)):
            pub.publish(msg)
        spin_until(lambda: len(states) == 2)  # the saturated command was applied: step 1
        pub.publish(_torque(e, big))  # duplicate of the applied one
        spin_until(lambda: len(states) == 4)  # two misses: hold once, then zero
        pub.publish(_torque(e + 1 * S, big))  # late
        spin_until(lambda: plant.finished.done())
    finally:
        executor.shutdown()
        stub.destroy_node()
        plant.destroy_node()
        rclpy.try_shutdown(context=context)
    c = plant.counts
    assert (c["rejected"], c["future"], c["duplicate"], c["late"]) == (2, 1, 1, 1)
    assert c["outside_u"] == c["saturated"] == 1  # the applied one; the late and the duplicate are not
    assert c["deadline_misses"] == 4 and c["fallback_hold"] == 1 and c["fallback_zero"] == 3
    assert plant.exit_code == 0 and plant.k == 4
    u_big = to_wheel_accel(big, CFG)
    x = X0
    for u in (u_big, u_big, np.zeros(3), np.zeros(3)):  # saturated, held once, then zero
        x, _ = integrate(x, u, 1.0, CFG)
    assert np.max(np.abs(plant.x - x)) <= 1e-12


# ----------------------------------------------------------------------------- faults in the running loop


@pytest.mark.slow
def test_clock_jumping_back_resets_the_stamp_screens_once(tmp_path: Path) -> None:
    """A replay that starts over: /clock jumps back. Controller and filter say so once, reset their stamp
    screens and answer the second pass's states (same stamps as the first) as new."""
    parser = argparse.ArgumentParser()
    launch.add_arguments(parser)
    plan = launcher.plan(parser.parse_args(["--bag", str(tmp_path / "unused.mcap"), "--no-scene", "-p", "record=false",
                                            "-p", "stop_timeout_s=1.0"]))
    env = {**os.environ, **plan.env, "PYTHONUNBUFFERED": "1", "RCUTILS_COLORIZED_OUTPUT": "0"}
    logs = {role: tmp_path / f"{role}.log" for role in (topics.CONTROLLER, topics.FILTER)}
    procs = {}
    for role, path in logs.items():
        with path.open("wb") as log:
            procs[role] = subprocess.Popen(plan.commands[role], stdout=log, stderr=subprocess.STDOUT, env=env,
                                           start_new_session=True)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("plant_stand_in", namespace=NS, context=context)
    executor = make_executor("single", context=context)
    executor.add_node(node)
    lease = next(k.default for k in topics.KNOBS if k.name == "liveliness_lease_s")  # the nodes request it
    clock = node.create_publisher(interface.msg_class("rosgraph_msgs/msg/Clock"), "/clock",
                                  interface.qos_profile(topics.STREAM_QOS))
    state = {name: node.create_publisher(interface.msg_class(topics.TOPICS[name].type_name), name,
                                         interface.qos_profile(topics.TOPICS[name].qos, lease))
             for name in topics.STATE_INPUTS}
    answered: list[int] = []
    spec = topics.TOPICS[topics.TORQUE_CMD]
    node.create_subscription(interface.msg_class(spec.type_name), spec.name,
                             lambda m: answered.append(convert.stamp_ns(m.header.stamp)),
                             interface.qos_profile(spec.qos))

    def spin_until(cond: Any, what: str, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not cond():
            assert time.monotonic() < deadline, f"{what} within {timeout_s:g} s"
            for p in procs.values():
                assert p.poll() is None, [path.read_text() for path in logs.values()]
            executor.spin_once(timeout_sec=0.05)

    x = CFG.scenario("paper-example").x0
    try:
        spin_until(lambda: state[topics.ODOMETRY].get_subscription_count() >= 2
                   and all(pub.get_subscription_count() >= 1 for pub in state.values())
                   and clock.get_subscription_count() >= 2
                   and node.count_publishers(f"{NS}/{topics.TORQUE_CMD}") >= 1, "controller and filter matched")
        for lap in range(2):
            for k in range(5):
                clock.publish(convert.clock_msg(k * S))  # k = 0 of the second lap: the clock jumps back
                if lap == 1 and k == 0:
                    spin_until(lambda: all("jumped back" in p.read_text() for p in logs.values()),
                               "both nodes notice the jump")
                for name, msg in _state(k * S, x):
                    state[name].publish(msg)
                spin_until(lambda lap=lap, k=k: len(answered) == 5 * lap + k + 1, f"the answer to t = {k} s")
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        codes = [p.wait(30) for p in procs.values()]
    assert answered == [k * S for k in range(5)] * 2
    assert codes == [0, 0]
    for path in logs.values():
        text = path.read_text()
        assert text.count("jumped back") == 1 and "state_duplicate" not in text and "state_out_of_order" not in text, \
            text


# ----------------------------------------------------------------------------- configuration errors


def _bad_files(tmp_path: Path, full: bool) -> dict[str, tuple[Path, str]]:
    """name -> (parameter file, what the one error line must say). full: a whole parameter file (the
    package's, with one bad entry), as the launcher and CLI take; else only the bad entry, as a node's
    --params-file overrides its config_file."""
    import yaml

    cases: dict[str, tuple[tuple[str, ...], Any, str]] = {
        "unknown": (("filter", "prest"), "paper", "unknown key 'prest'"),
        "type": (("limits", "psi_max_rad_s"), "fast", "psi_max_rad_s must be a finite number, got 'fast'"),
        "range": (("limits", "psi_max_rad_s"), -5.0, "psi_max_rad_s must be > 0, got -5.0"),
        "knob": (("command_timeout_s",), -1.0, "command_timeout_s must be a float > 0, got -1.0"),
    }
    base = yaml.safe_load(Path(CFG.source).read_text()) if full else {"/**": {"ros__parameters": {}}}
    out = {}
    for name, (keys, value, message) in cases.items():
        doc = yaml.safe_load(yaml.safe_dump(base))
        node = next(iter(doc.values()))["ros__parameters"]
        for key in keys[:-1]:
            node = node.setdefault(key, {})
        node[keys[-1]] = value
        path = tmp_path / f"{name}{'_full' if full else ''}.yaml"
        path.write_text(yaml.safe_dump(doc))
        out[name] = (path, message)
    out["yaml"] = (tmp_path / "broken.yaml", "is not valid YAML at line")
    out["yaml"][0].write_text("/**:\n  ros__parameters:\n    limits: [psi_max_rad_s: \n")
    out["missing"] = (tmp_path / "missing.yaml", "does not exist")
    return out


def _one_error_line(proc: subprocess.CompletedProcess[str] | Any, message: str) -> None:
    text = proc.stdout + proc.stderr
    assert proc.returncode == 1, text
    assert "Traceback" not in text, text
    errors = [line for line in text.splitlines() if "ERROR" in line]
    assert len(errors) == 1 and message in errors[0], text


def test_node_with_a_bad_parameter_file_exits_1_with_one_line(tmp_path: Path) -> None:
    cases = _bad_files(tmp_path, full=False)
    procs = {name: subprocess.Popen([sys.executable, "-m", topics.MODULES[topics.PLANT], "--ros-args",
                                     "--params-file", str(path), "-p", "record:=false"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, (path, _) in cases.items()}  # fmt: skip
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=300)
        _one_error_line(subprocess.CompletedProcess(proc.args, proc.returncode, out, err), cases[name][1])


def test_launcher_and_cli_with_bad_files_or_values_exit_1_with_one_line(tmp_path: Path) -> None:
    cases = _bad_files(tmp_path, full=True)
    runs = {
        "launch-unknown": (["-m", "rta_attitude.cli.launch", "--config", str(cases["unknown"][0])],
                           "unknown key 'prest'"),
        "launch-range": (["-m", "rta_attitude.cli.launch", "--config", str(cases["range"][0])],
                         "psi_max_rad_s must be > 0, got -5.0"),
        "launch-missing": (["-m", "rta_attitude.cli.launch", "--config", str(cases["missing"][0])], "does not exist"),
        "launch-knob": (["-m", "rta_attitude.cli.launch", "-p", "command_timeout_s=-1"],
                        "parameter command_timeout_s must be a float > 0, got -1.0"),
        "launch-knob-type": (["-m", "rta_attitude.cli.launch", "-p", "deadline_fallback=pray"],
                             "parameter deadline_fallback must be one of hold, zero, got 'pray'"),
        "launch-domain": (["-m", "rta_attitude.cli.launch", "--domain-id", "999"],
                          "--domain-id must be in 0..232, got 999"),
        "cli-type": (["-m", "rta_attitude.cli", "check-config", "--config", str(cases["type"][0])],
                     "psi_max_rad_s must be a finite number, got 'fast'"),
        "cli-missing": (["-m", "rta_attitude.cli", "check-config", "--config", str(cases["missing"][0])],
                        "does not exist"),
        "cli-yaml": (["-m", "rta_attitude.cli", "simulate", "--config", str(cases["yaml"][0])], "not valid YAML"),
    }
    procs = {name: subprocess.Popen([sys.executable, *argv, *(["--bag", str(tmp_path / f"{name}.mcap")]
                                                              if "launcher" in argv[1] else [])],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, (argv, _) in runs.items()}  # fmt: skip
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=300)
        _one_error_line(subprocess.CompletedProcess(proc.args, proc.returncode, out, err), runs[name][1])
    assert not list(tmp_path.glob("*.mcap"))  # nothing started


# ----------------------------------------------------------------------------- isolation


def test_launcher_runs_nodes_on_localhost_and_a_configurable_domain(monkeypatch: pytest.MonkeyPatch,
                                                                     tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    launch.add_arguments(parser)
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    plan = launcher.plan(parser.parse_args(["--bag", str(tmp_path / "a.mcap")]))
    assert plan.env == {"ROS_DOMAIN_ID": str(launcher.DEFAULT_DOMAIN_ID), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert launcher.plan(parser.parse_args(["--bag", str(tmp_path / "b.mcap")])).env["ROS_DOMAIN_ID"] == "42"
    plan = launcher.plan(parser.parse_args(["--bag", str(tmp_path / "c.mcap"), "--domain-id", "7",
                                            "--discovery", "subnet"]))
    assert plan.env == {"ROS_DOMAIN_ID": "7", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"  # the tests' own default (conftest)
    text = (Path(__file__).resolve().parents[1] / "launch" / "rta_attitude.launch.py").read_text()
    assert '("ROS_AUTOMATIC_DISCOVERY_RANGE", a["discovery_range"])' in text  # set before the nodes start
    from rta_attitude.ros.launch_file import validate

    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    checked = validate({"bag": str(tmp_path / "d.mcap")})
    assert checked["discovery_range"] == "LOCALHOST" and checked["domain_id"] == launcher.DEFAULT_DOMAIN_ID
