"""The four nodes over real Fast DDS, in one process on one executor (rclpy, no mocks).

- lockstep identity: the whole `paper-example` (2000 steps) over DDS equals ClosedLoop.run() to
  <= 1e-9 (it is bit-exact), with and without RTA; the recorder's bag, read with two independent
  readers (rosbags and mcap_ros2), holds every message with the in-process run's values;
- real-time stepping: a missing command is a counted deadline miss with the configured fallback,
  the run never stalls;
- conversions, validation and the parameter loader.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from helpers import integrate, saturate, to_wheel_accel
from rclpy.parameter import Parameter

from rta_attitude import config, topics
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.sensors import ENERGY_RELATIVE_ERROR, Instruments, message_fields, sensors_record
from rta_attitude.dynamics.state import ENERGY, STATE_NAMES
from rta_attitude.errors import ConfigError, MessageError
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.ros import convert, interface
from rta_attitude.ros.controller_node import ControllerNode
from rta_attitude.ros.filter_node import FilterNode
from rta_attitude.ros.plant_node import PlantNode
from rta_attitude.ros.recorder_node import RecorderNode
from rta_attitude.ros.spin import make_executor
from rta_attitude.simulation.closed_loop import ClosedLoop

pytestmark = pytest.mark.dds
CFG = config.load()
NODE_CLASSES = {topics.PLANT: PlantNode, topics.CONTROLLER: ControllerNode, topics.FILTER: FilterNode,
                topics.RECORDER: RecorderNode}
NS = topics.DEFAULT_NAMESPACE


def _topic(name: str) -> str:
    return name if name.startswith("/") else f"{NS}/{name}"


def run_nodes(tmp_path: Path, *, rta: bool = True, roles: tuple[str, ...] = tuple(NODE_CLASSES),
              params: dict[str, Any] | None = None, timeout_s: float = 240.0,
              probe_state: bool = False) -> dict[str, Any]:
    """Run nodes of `roles` on one executor until the plant (and recorder) finish.

    Returns {'bag': path, 'plant': plant node, 'nodes': {...}}; the context is shut down.
    """
    context = rclpy.Context()
    rclpy.init(context=context)
    bag = tmp_path / "run.mcap"
    common = {"scenario": "paper_example", "rta": rta, "record": topics.RECORDER in roles, **(params or {})}
    nodes: dict[str, Any] = {}
    probe = None
    executor = make_executor("events", context=context)
    try:
        for role in roles:
            values = dict(common)
            if role == topics.RECORDER:
                values["bag_path"] = str(bag)
            knob_names = {k.name for k in topics.knobs_for(role)}
            overrides = [Parameter(k, value=v) for k, v in values.items()
                         if k in knob_names or "." in k]
            nodes[role] = NODE_CLASSES[role](context=context, namespace=NS, parameter_overrides=overrides)
            executor.add_node(nodes[role])
        if probe_state:  # a silent stand-in for the controller: it reads odometry and never answers
            probe = rclpy.create_node("probe", namespace=NS, context=context)
            spec = topics.TOPICS[topics.ODOMETRY]
            probe.create_subscription(interface.msg_class(spec.type_name), spec.name, lambda m: None,
                                      interface.qos_profile(spec.qos))
            executor.add_node(probe)
        waits = [n.finished for r, n in nodes.items() if r in (topics.PLANT, topics.RECORDER)]
        deadline = time.monotonic() + timeout_s
        while not all(f.done() for f in waits):
            assert time.monotonic() < deadline, "run did not finish"
            executor.spin_once(timeout_sec=0.1)
        return {"bag": bag, "plant": nodes.get(topics.PLANT), "nodes": nodes}
    finally:
        for node in nodes.values():
            node.close()
            node.destroy_node()
        if probe is not None:
            probe.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=context)


def _by_topic(contents: Any) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    for m in contents.messages:
        out.setdefault(m.topic, []).append(m)
    return out


# ----------------------------------------------------------------------------- lockstep identity


@pytest.mark.slow
@pytest.mark.parametrize("rta", [True, False], ids=["rta", "no_rta"])
def test_lockstep_run_over_dds_equals_in_process_run(rta: bool, tmp_path: Path, paper_reference: dict) -> None:
    from mcap_ros2.reader import read_ros2_messages
    from rosbags.highlevel import AnyReader

    ref = paper_reference[rta]
    n = ref.steps
    out = run_nodes(tmp_path, rta=rta)
    plant = out["plant"]
    assert plant.exit_code == 0 and plant.k == n
    # no fault of any kind; without RTA the paper's PD law exceeds U (counted, applied as it is)
    assert {k: v for k, v in plant.counts.items() if v and k != "commands"} == ({} if rta else {
        "outside_u": plant.counts["outside_u"]})
    assert plant.counts["commands"] == n + 1

    # reader 1: mcap_ros2 (decodes with the bag's own schemas)
    msgs: dict[str, list[Any]] = {}
    for m in read_ros2_messages(str(out["bag"])):
        msgs.setdefault(m.channel.topic, []).append(m)
    counts = {t: len(v) for t, v in msgs.items()}
    expected = {_topic(t): n + 1 for t in (topics.CLOCK, topics.STATE, topics.TORQUE_DES, topics.TORQUE_CMD,
                                             *topics.STATE_INPUTS)}
    expected[_topic(topics.TORQUE_APPLIED)] = n
    expected[_topic(topics.RUN_STATUS)] = 2
    if rta:
        expected[_topic(topics.FILTER_STATUS)] = n + 1
    assert counts == expected

    x = np.array([convert.state_from_msg(m.ros_msg)[1] for m in msgs[_topic(topics.STATE)]])
    assert x.shape == ref.x.shape
    assert np.max(np.abs(x - ref.x)) <= 1e-9
    stamps = [convert.state_from_msg(m.ros_msg)[0] for m in msgs[_topic(topics.STATE)]]
    epoch = CFG.scenario("paper_example").epoch_ns  # t = 0 is the scenario epoch in ROS time
    assert stamps == [epoch + convert.seconds_to_ns(t) for t in ref.t_s]
    assert min(m.log_time_ns for ms in msgs.values() for m in ms) == epoch  # every bag time a real date, none 1970
    assert all(m.log_time_ns == s for m, s in zip(msgs[_topic(topics.STATE)], stamps))
    u_des = to_wheel_accel(
        np.array([convert.torque_from_msg(m.ros_msg)[1] for m in msgs[_topic(topics.TORQUE_DES)]]), CFG)[:n]
    u_cmd = saturate(to_wheel_accel(
        np.array([convert.torque_from_msg(m.ros_msg)[1] for m in msgs[_topic(topics.TORQUE_CMD)]]), CFG), CFG)[:n]
    assert np.max(np.abs(u_des - ref.u_des)) <= 1e-9 and np.max(np.abs(u_cmd - ref.u)) <= 1e-9
    if rta:
        recs = [convert.filter_record(m.ros_msg, ref.names) for m in msgs[_topic(topics.FILTER_STATUS)]][:n]
        assert [r["status"] for r in recs] == ref.status.tolist()
        assert [r["fallback"] for r in recs] == ref.fallback.tolist()
        assert np.array_equal(np.array([r["intervening"] for r in recs]), ref.intervening)
        assert np.array_equal(np.array([r["box_active"] for r in recs]), ref.box_active)
        assert np.max(np.abs(np.array([r["slack"] for r in recs]) - ref.slack)) <= 1e-9
        assert np.max(np.abs(np.array([r["bc"] for r in recs]) - ref.bc)) <= 1e-9 * max(1.0, np.abs(ref.bc).max())
        # the filter's h is of the state it reads: across the message interface (the battery's float32 charge)
        read = Instruments(CFG)
        h_read = ConstraintSet(CFG).safety_values(np.array([read.deliver(x) for x in ref.x[:-1]]))
        assert np.allclose([r["h"] for r in recs], h_read, rtol=1e-12, atol=1e-12)
        battery = ref.names.index("battery")
        error = np.abs(h_read[:, battery] - ref.h[:-1, battery])
        assert error.max() > 0 and np.all(error <= ENERGY_RELATIVE_ERROR * ref.x[:-1, ENERGY])
        assert all(r["preset"] == CFG.filter.preset for r in recs)
        assert [n_ for n_, s in zip(ref.names, recs[0]["slacked"]) if s] == ["communication"]
    status = convert.run_status_from_msg(msgs[_topic(topics.RUN_STATUS)][-1].ros_msg)
    assert status[0] == topics.RUN_DONE and status[1]["steps"] == n

    # reader 2: rosbags (independent CDR parser, types from the bag's definitions)
    with AnyReader([out["bag"]]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections if c.msgcount} == expected
        states = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                  if c.topic == _topic(topics.STATE)]
        odom = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                if c.topic == _topic(topics.ODOMETRY)]
        wheels = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                  if c.topic == _topic(topics.WHEELS)]
        battery = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                   if c.topic == _topic(topics.BATTERY)]
    assert [list(s.name) for s in states[:1]] == [list(STATE_NAMES)]
    assert np.array_equal(np.array([s.position for s in states]), x)
    q_odom = np.array([[o.pose.pose.orientation.x, o.pose.pose.orientation.y, o.pose.pose.orientation.z,
                        o.pose.pose.orientation.w] for o in odom])
    assert np.array_equal(q_odom, ref.x[:, :4])
    # the wheels as a real JointState (rotor speed = -psi with the paper's sign), the charge a float32 of E / (V h)
    assert {tuple(w.name) for w in wheels} == {("wheel_x", "wheel_y", "wheel_z")} and len(wheels) == n + 1
    assert all(w.header.frame_id == "body" and len(w.position) == 0 for w in wheels)
    assert np.array_equal(np.array([w.velocity for w in wheels]), -CFG.spacecraft.torque_sign * ref.x[:, 7:10])
    charge = (ref.x[:, 11] / (CFG.power.bus_voltage_V * 3600.0)).astype(np.float32)
    assert np.array_equal(np.array([b.charge for b in battery], dtype=np.float32), charge)


@pytest.mark.slow
def test_lockstep_with_sensor_errors_publishes_measured_and_true_states(tmp_path: Path) -> None:
    """sensors.enabled:=true: `state` carries what the sensors measure (the controller and the filter
    read it), `state_true` the truth; the run equals the in-process run with the same noise bit for bit,
    and the analysis judges safety on the truth."""
    from rosbags.highlevel import AnyReader

    from rta_attitude.recording.analysis import load_run
    from rta_attitude.simulation.closed_loop import simulate

    noisy = CFG.with_noise()
    ref = simulate(noisy, "paper-example")
    n = ref.steps
    out = run_nodes(tmp_path, params={"sensors.enabled": True})
    assert out["plant"].exit_code == 0 and out["plant"].k == n
    with AnyReader([out["bag"]]) as reader:
        got: dict[str, list[np.ndarray]] = {}
        for c, _, raw in reader.messages():
            if c.topic in (_topic(topics.STATE), _topic(topics.STATE_TRUE)):
                got.setdefault(c.topic, []).append(np.array(reader.deserialize(raw, c.msgtype).position))
    measured, truth = np.array(got[_topic(topics.STATE)]), np.array(got[_topic(topics.STATE_TRUE)])
    assert truth.shape == ref.x.shape and np.array_equal(truth, ref.x)
    assert ref.y is not None and np.array_equal(measured[:n], ref.y)
    assert np.abs(measured[:n] - truth[:n]).max() > 0
    run = load_run(out["bag"], noisy)
    assert np.array_equal(run.x, ref.x) and run.y is not None and np.array_equal(run.y[:n], ref.y)
    assert any("true state" in note for note in run.notes)
    assert run.reintegration_residual < 1e-9  # torque_applied is what the wheels held
    assert np.allclose(run.h_substep_min, ref.h_substep_min, rtol=1e-9, atol=1e-12)  # re-integrated: D u / D rounds


VEHICLE_OPTIONS = {
    "transport_delay": {"spacecraft.transport_delay_s": 0.1},
    "products_of_inertia": {"spacecraft.inertia_kgm2": [0.0263875, 0.0413341, 0.0542784],
                            "spacecraft.products_of_inertia_kgm2": [-0.0072898, 0.0069871, 0.0007506]},
    "skewed_wheels": {"spacecraft.wheel_spin_axes_body.wheel_x": [0.9592, 0.1998, -0.1998],
                      "spacecraft.wheel_spin_axes_body.wheel_y": [0.3, 0.9, 0.3162],
                      "spacecraft.wheel_spin_axes_body.wheel_z": [-0.2506, 0.3509, 0.9023]},
    "failed_wheel": {"spacecraft.failed_wheels": "wheel_x"},
}
"""A vehicle the nodes must model as `simulate` does: a 0.1 s transport delay; the 6U with products of inertia
(config/examples/products_of_inertia.yaml); wheels on skewed axes (`helpers.SKEWED_AXES`: the torque interface
carries D A u); a failed wheel (the plant holds it at 0, the filter leaves it out)."""


@pytest.mark.slow
@pytest.mark.parametrize("option", list(VEHICLE_OPTIONS))
def test_lockstep_with_a_vehicle_option_equals_the_in_process_run(option: str, tmp_path: Path) -> None:
    """The plant node and the filter node model the vehicle as `simulate` does: with a 0.1 s transport delay the
    plant holds the previous command over the delay and the filter plans from the state at its end; with products
    of inertia both use the full tensor; with skewed wheels the torques they exchange are D A u. The run over DDS
    equals `simulate` bit for bit, and the bag's analysis
    re-integrates it to the recorded states."""
    from rosbags.highlevel import AnyReader

    from rta_attitude.recording.analysis import load_run
    from rta_attitude.simulation.closed_loop import simulate

    delayed = config.load(overrides=VEHICLE_OPTIONS[option])
    ref = simulate(delayed, "paper-example")
    out = run_nodes(tmp_path, params=VEHICLE_OPTIONS[option])
    assert out["plant"].exit_code == 0 and out["plant"].k == ref.steps
    with AnyReader([out["bag"]]) as reader:
        states = [np.array(reader.deserialize(raw, c.msgtype).position) for c, _, raw in reader.messages()
                  if c.topic == _topic(topics.STATE)]
    assert np.array_equal(np.array(states), ref.x)
    assert not np.array_equal(ref.x, simulate(CFG, "paper-example").x)  # the option changed the run
    run = load_run(out["bag"], delayed)
    assert np.array_equal(run.x, ref.x) and run.reintegration_residual < 1e-9


@pytest.mark.slow
def test_lockstep_with_named_wheels_names_them_on_joint_states(tmp_path: Path) -> None:
    """A user's file names its (skewed) wheels: joint_states carries those names, the filter reads them, and the
    run over DDS equals `simulate` bit for bit."""
    from rosbags.highlevel import AnyReader

    from rta_attitude.simulation.closed_loop import simulate

    path = tmp_path / "named.yaml"
    axes = {"rw_a": [0.9592, 0.1998, -0.1998], "rw_b": [0.3, 0.9, 0.3162], "rw_c": [-0.2506, 0.3509, 0.9023]}
    path.write_text("/**:\n  ros__parameters:\n    spacecraft:\n      wheel_spin_axes_body:\n"
                    + "".join(f"        {k}: {v}\n" for k, v in axes.items()))
    named = config.load(path)
    assert named.spacecraft.wheel_names == tuple(axes)
    ref = simulate(named, "paper-example")
    out = run_nodes(tmp_path, params={"config_file": str(path)})
    assert out["plant"].exit_code == 0 and out["plant"].k == ref.steps
    assert out["nodes"][topics.FILTER].counts.get("state_rejected", 0) == 0
    with AnyReader([out["bag"]]) as reader:
        msgs = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()
                if c.topic in (_topic(topics.STATE), _topic(topics.WHEELS))]
    assert {tuple(m.name) for t, m in msgs if t == _topic(topics.WHEELS)} == {tuple(axes)}
    assert np.array_equal(np.array([m.position for t, m in msgs if t == _topic(topics.STATE)]), ref.x)


# ----------------------------------------------------------------------------- real time


@pytest.mark.parametrize("fallback", ["hold", "zero"])
def test_realtime_missing_commands_are_counted_deadline_misses(fallback: str, tmp_path: Path) -> None:
    """No controller answers: every step is a deadline miss, the fallback applies, no stall."""
    steps = 12  # a stall fails run_nodes' deadline (30 s for 12 steps at 200x real time)
    out = run_nodes(tmp_path, rta=False, roles=(topics.PLANT,), probe_state=True, timeout_s=30, params={
        "stepping": "realtime", "real_time_factor": 200.0, "deadline_fallback": fallback,
        "scenarios.paper_example.duration_s": float(steps)})
    plant = out["plant"]
    assert plant.exit_code == 0 and plant.k == steps
    assert plant.counts["deadline_misses"] == steps
    x = CFG.scenario("paper_example").x0
    for _ in range(steps):  # both fallbacks apply zero torque here: nothing was ever received
        x, _subs = integrate(x, np.zeros(3), 1.0, CFG)
    assert np.max(np.abs(plant.x - x)) <= 1e-12


def test_realtime_run_with_every_node_completes_and_is_recorded(tmp_path: Path) -> None:
    steps = 40
    ref = ClosedLoop(CFG, replace(CFG.scenario("paper_example"), duration_s=float(steps))).run()
    out = run_nodes(tmp_path, params={"stepping": "realtime", "real_time_factor": 40.0,
                                      "scenarios.paper_example.duration_s": float(steps)})
    plant = out["plant"]
    assert plant.exit_code == 0 and plant.k == steps
    from rta_attitude.recording.bag import read_bag

    contents = read_bag(out["bag"], topics=[_topic(topics.STATE)])
    assert contents.counts[_topic(topics.STATE)] == steps + 1
    if plant.counts["deadline_misses"] == 0:  # every command in time: the lockstep trajectory
        x = np.array([convert.state_from_msg(m.message)[1] for m in contents.messages])
        assert np.max(np.abs(x - ref.x)) <= 1e-9


# ----------------------------------------------------------------------------- conversions


def test_state_message_round_trip_and_validation() -> None:
    x = CFG.scenario("paper_example").x0
    msg = convert.state_msg(x, 1_500_000_000)
    t_ns, back = convert.state_from_msg(msg)
    assert t_ns == 1_500_000_000 and np.array_equal(back, x)
    bad = convert.state_msg(x, 0)
    bad.position = [*x[:-1].tolist(), math.nan]
    with pytest.raises(MessageError, match="z_dot is not finite"):
        convert.state_from_msg(bad)
    bad = convert.state_msg(x, 0)
    bad.name = list(reversed(STATE_NAMES))
    with pytest.raises(MessageError, match="names"):
        convert.state_from_msg(bad)
    bad = convert.state_msg(x, 0)
    bad.position = x[:5].tolist()
    with pytest.raises(MessageError, match="5 positions"):
        convert.state_from_msg(bad)


def test_torque_and_command_validation() -> None:
    msg = convert.torque_msg(np.array([1e-3, -2e-3, 0.0]), 7)
    assert convert.torque_from_msg(msg)[0] == 7
    msg.header.frame_id = "hill"
    with pytest.raises(MessageError, match="frame_id"):
        convert.torque_from_msg(msg)
    msg = convert.torque_msg(np.array([math.inf, 0.0, 0.0]), 7)
    with pytest.raises(MessageError, match="not finite"):
        convert.torque_from_msg(msg)
    from geometry_msgs.msg import QuaternionStamped

    q = QuaternionStamped()
    q.quaternion.x, q.quaternion.w = 0.0, 1.2
    assert np.allclose(convert.quaternion_from_msg(q)[1], [0, 0, 0, 1])
    q.quaternion.w = 0.0
    with pytest.raises(MessageError, match="unit quaternion"):
        convert.quaternion_from_msg(q)


def test_cdr_stamp_matches_serialized_messages() -> None:
    from rclpy.serialization import serialize_message

    x = CFG.scenario("paper_example").x0
    t = 123 * convert.NS_PER_S + 456
    views = convert.state_messages(message_fields(x, sensors_record(CFG)), t, 8.0, -1.0, np.zeros(3))
    for msg in (convert.state_msg(x, t), convert.clock_msg(t), *views.values()):
        assert convert.cdr_stamp_ns(serialize_message(msg)) == t
    with pytest.raises(MessageError):
        convert.cdr_stamp_ns(b"\x00\x01\x00\x00")


def test_filter_status_round_trips_every_field_exactly() -> None:
    traj = ClosedLoop(CFG, replace(CFG.scenario("paper_example"), duration_s=5.0)).run()
    k = int(np.flatnonzero(traj.status == "solved")[0])
    filt = AsifFilter(CFG)
    res = filt.filter(traj.x[k], traj.u_des[k])
    assert res.status == "solved" and res.intervening.any()
    msg = convert.filter_status_msg(res, 42, filt.counters, "robust", ("communication",))
    rec = convert.filter_record(msg, res.names)
    for key in ("h", "psi0", "psi1", "bc", "slack", "intervening", "uncontrollable", "box_active", "u", "u_des"):
        assert np.array_equal(rec[key], getattr(res, key)), key
    assert (rec["status"], rec["fallback"], rec["iterations"], rec["solve_time_s"]) == (
        res.status, res.fallback, res.iterations, res.solve_time_s)
    assert msg.status[0].name == topics.QP_STATUS_NAME
    assert [s.name for s in msg.status[1:]] == list(res.names)
    values = convert.diagnostic_values(msg)
    assert set(values[topics.QP_STATUS_NAME]) - {"_message"} == set(topics.QP_KEYS)
    assert set(values["battery"]) - {"_message"} == set(topics.CONSTRAINT_KEYS)


def _rosbags_store() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def test_fixed_layouts_write_what_rclpy_writes_and_read_what_rclpy_reads() -> None:
    """The loop's per-step messages go out as bytes written into templates (`convert.CdrLayout`) and come in
    through raw subscriptions: rclpy and rosbags (an independent CDR decoder, which also checks the length)
    read our bytes as the messages the object builders make; our readers read rclpy's bytes (whose padding is
    whatever its buffer held) as the object parsers read the messages; other layouts fall back to rclpy."""
    from rclpy.serialization import deserialize_message, serialize_message

    store = _rosbags_store()
    rng = np.random.default_rng(7)
    x0 = CFG.scenario("paper_example").x0
    for _trial in range(40):
        x = x0 + rng.normal(size=x0.size) * 10.0 ** rng.uniform(-4, 2)
        f = message_fields(x, sensors_record(CFG))
        t = int(rng.integers(0, 2**41))
        current, effort = float(rng.normal()), rng.normal(size=3) * 1e-4
        objs = convert.state_messages(f, t, 8.0, current, effort)
        ours = convert.state_messages_cdr(f, t, 8.0, current, effort)
        pairs = [*((objs[k], ours[k]) for k in objs), (convert.state_msg(x, t), convert.state_cdr(x, t)),
                 (convert.torque_msg(effort, t), convert.torque_cdr(effort, t)),
                 (convert.clock_msg(t), convert.clock_cdr(t))]
        for obj, data in pairs:
            theirs = bytes(serialize_message(obj))
            kind = type(obj)
            assert repr(deserialize_message(data, kind)) == repr(deserialize_message(theirs, kind))
            name = f"{kind.__module__.split('.')[0]}/msg/{kind.__name__}"
            assert repr(store.deserialize_cdr(data, name)) == repr(store.deserialize_cdr(theirs[:len(data)], name))
        for views in (ours, {k: bytes(serialize_message(m)) for k, m in objs.items()}):
            assert np.array_equal(convert.state_fields(views), convert.state_fields(objs))
            out, ref = np.zeros(len(f)), np.zeros(len(f))
            convert.odometry_fields(views[topics.ODOMETRY], out)
            convert.odometry_fields(objs[topics.ODOMETRY], ref)
            assert np.array_equal(out, ref)
        for data in (convert.torque_cdr(effort, t), bytes(serialize_message(convert.torque_msg(effort, t)))):
            t_read, tau = convert.torque_from_msg(data)
            assert t_read == t and np.array_equal(tau, effort)
    # other layouts (a frame id, reversed or fewer joints, a frame of the same length): rclpy's path, same errors
    objs = convert.state_messages(message_fields(x0, sensors_record(CFG)), 5, 8.0, -1.0, np.zeros(3))
    odometry = convert.layouts().odometry.message(convert.state_messages_cdr(
        message_fields(x0, sensors_record(CFG)), 5, 8.0, -1.0, np.zeros(3))[topics.ODOMETRY])
    odometry.header.frame_id = "body"
    wheels_reversed = convert.layouts().wheels.message(serialize_message(objs[topics.WHEELS]))
    wheels_reversed.name = list(reversed(topics.WHEEL_JOINTS))
    wheels_short = convert.layouts().wheels.message(serialize_message(objs[topics.WHEELS]))
    wheels_short.velocity = [0.0, 0.0]
    for topic, spoiled, match in ((topics.ODOMETRY, odometry, "frame_id"), (topics.WHEELS, wheels_reversed, "joints"),
                                  (topics.WHEELS, wheels_short, "joints")):
        data = bytes(serialize_message(spoiled))
        assert convert.layouts().by_topic[topic].unpack(data) is None
        for views in ({**objs, topic: spoiled}, {**objs, topic: data}):
            with pytest.raises(MessageError, match=match):
                convert.state_fields(views)
    torque = convert.torque_msg(np.ones(3), 5)
    torque.header.frame_id = "hill"
    with pytest.raises(MessageError, match="frame_id"):
        convert.torque_from_msg(bytes(serialize_message(torque)))
    with pytest.raises(MessageError, match="not a Vector3Stamped"):
        convert.torque_from_msg(convert.torque_cdr(np.ones(3), 5)[:30])
    with pytest.raises(MessageError, match="not finite"):
        convert.torque_from_msg(convert.torque_cdr(np.array([math.nan, 0.0, 0.0]), 5))


def test_filter_status_bytes_are_the_message() -> None:
    """`build_cdr` (what the filter node publishes) is `build`'s message: rclpy and rosbags decode its bytes
    into the same fields, for a passing, an intervening and a fallback result."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message

    store = _rosbags_store()
    traj = ClosedLoop(CFG, replace(CFG.scenario("paper_example"), duration_s=5.0)).run()
    filt = AsifFilter(CFG)
    results = [filt.filter(traj.x[0], np.zeros(3))]  # nothing to change: passes
    results += [filt.filter(traj.x[k], traj.u_des[k]) for k in range(3)]
    results.append(filt.filter(np.full(traj.x.shape[1], math.nan), traj.u_des[0]))  # the invalid-state fallback
    assert [str(r.status) for r in results] == ["pass", "solved", "solved", "solved", "fallback"]
    builder = convert.FilterStatusBuilder(results[0].names)
    for i, res in enumerate(results):
        t = 10**9 * i + 7
        data = builder.build_cdr(res, t, filt.counters, "robust", ("communication",), {"state_rejected": i}, "missing")
        msg = builder.build(res, t, filt.counters, "robust", ("communication",), {"state_rejected": i}, "missing")
        assert deserialize_message(data, DiagnosticArray) == msg
        decoded = store.deserialize_cdr(data, "diagnostic_msgs/msg/DiagnosticArray")
        assert [(st.level, st.name, st.message, [(kv.key, kv.value) for kv in st.values]) for st in decoded.status] == [
            (int.from_bytes(st.level, "little"), st.name, st.message, [(kv.key, kv.value) for kv in st.values])
            for st in msg.status]
        assert convert.cdr_stamp_ns(data) == t


def test_wiring_counts_every_reader_of_the_run() -> None:
    # the loop reads the state on its STATE_INPUTS (controller: odometry; filter: all five); `state` is the record's
    assert topics.expected_readers(topics.ODOMETRY, rta=True, record=True) == 3
    assert topics.expected_readers(topics.ODOMETRY, rta=False, record=True) == 2
    assert topics.expected_readers(topics.WHEELS, rta=True, record=False) == 1
    assert topics.expected_readers(topics.BATTERY, rta=False, record=False) == 0
    assert topics.expected_readers(topics.STATE, rta=True, record=True) == 1
    assert topics.expected_readers(topics.TORQUE_DES, rta=False, record=False) == 1
    assert topics.expected_readers(topics.TORQUE_CMD, rta=True, record=True) == 2
    assert topics.expected_readers(topics.CLOCK, rta=True, record=False) == 0
    scene = set(topics.SCENE_TOPICS)
    assert {t.name for t in topics.recorded(False)} == \
        set(topics.TOPICS) - {topics.FILTER_STATUS, topics.STATE_TRUE} - scene
    assert {t.name for t in topics.recorded(True, truth=True)} == set(topics.TOPICS) - scene
    node, hosted = topics.SCENE_NODE, topics.SCENE_RECORDER
    assert {t.name for t in topics.recorded(True, truth=True, scene=node)} == set(topics.TOPICS)
    assert {t.name for t in topics.recorded(True, truth=True, scene=hosted)} == set(topics.TOPICS)
    # a scene node of its own is waited for at start-up on what it reads (state, filter_status with RTA), and
    # waits for the recorder; one hosted by the recorder reads nothing and nobody reads its topics over DDS
    assert topics.expected_readers(topics.STATE, rta=True, record=True, scene=node) == 2
    assert topics.expected_readers(topics.FILTER_STATUS, rta=True, record=True, scene=node) == 2
    assert topics.expected_readers(topics.FILTER_STATUS, rta=True, record=True) == 1
    assert topics.expected_readers(topics.SCENE_MARKERS, rta=False, record=True, scene=node) == 1
    assert topics.expected_readers(topics.SCENE_MARKERS, rta=False, record=False, scene=node) == 0
    assert topics.expected_readers(topics.STATE, rta=True, record=True, scene=hosted) == 1
    assert topics.expected_readers(topics.FILTER_STATUS, rta=True, record=True, scene=hosted) == 1
    assert topics.expected_readers(topics.SCENE_MARKERS, rta=True, record=True, scene=hosted) == 0
    assert topics.expected_readers(topics.STATE_TRUE, rta=True, record=True) == 0
    assert topics.expected_readers(topics.STATE_TRUE, rta=True, record=True, truth=True) == 1


# ----------------------------------------------------------------------------- parameters


def _node(role: str, overrides: dict[str, Any]) -> Any:
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = NODE_CLASSES[role](context=context, namespace=NS, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        values = (node.cfg, dict(node.knobs), node.set_parameters([Parameter("filter.preset", value="robust")]))
        node.destroy_node()
        return values
    finally:
        rclpy.try_shutdown(context=context)


def test_yaml_leaves_are_ros_parameters_and_overrides_reach_the_core() -> None:
    cfg, knobs, refused = _node(topics.FILTER, {"filter.preset": "paper", "scenarios.paper_example.duration_s": 50,
                                                "constraints.omega.k1": 0.3})
    assert cfg.filter.preset == "paper" and cfg.scenario("paper_example").duration_s == 50.0
    assert cfg.barriers["omega"].k1 == 0.3
    # the node runs its scenario (paper_example: the paper's model in plant and filter, `model: paper`)
    assert cfg.spacecraft == CFG.for_scenario(CFG.scenario("paper_example")).spacecraft and knobs["rta"] is True
    assert (cfg.spacecraft.model, cfg.filter.model) == ("paper", "paper")
    assert not refused[0].successful and "read-only" in refused[0].reason


def test_each_node_declares_only_what_it_uses_and_the_controller_gains_change_live(tmp_path: Path) -> None:
    """`ros2 param list` per node: its knobs, its own scenario and the core sections it uses; a parameter
    it does not declare still reaches its configuration (one file, no disagreement between nodes). The
    controller's gains change while it runs: validated by the core loader, and the next answer uses them
    (checked against the PD law written out here: q = q_c, so u = a_max tanh(-kd omega))."""
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        names, nodes = {}, {}
        own = {topics.CONTROLLER: "paper_example", topics.FILTER: "passed_example", topics.RECORDER: "passed_example"}
        for role, scenario in own.items():
            extra = ([Parameter("bag_path", value=str(tmp_path / "unused.mcap"))] if role == topics.RECORDER
                     else [Parameter("environment.albedo_factor", value=0.3)])
            node = NODE_CLASSES[role](context=context, namespace=NS, parameter_overrides=[
                Parameter("scenario", value=scenario), *extra])
            names[role] = set(node.list_parameters([], 0).names)
            nodes[role] = node
        ctl = nodes[topics.CONTROLLER]
        assert ctl.cfg.environment.albedo_factor == 0.3  # not declared there, still the node's configuration
        x = np.zeros(19)
        x[0:4], x[4:7] = ctl.scenario.command_at(0.0), (0.01, -0.02, 0.005)
        ok = ctl.set_parameters([Parameter("controller.kd", value=2.5)])[0]
        bad = ctl.set_parameters([Parameter("controller.kp", value=-0.3)])[0]
        frozen = ctl.set_parameters([Parameter("spacecraft.wheel_inertia_kgm2", value=1e-4)])[0]
        from rta_attitude.dynamics.controller import desired_command
        u = desired_command(x, ctl.scenario.command_at(0.0), ctl.law)
        for node in nodes.values():
            node.close()
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    ctl_names, filter_names, rec_names = names[topics.CONTROLLER], names[topics.FILTER], names[topics.RECORDER]
    for role, declared in names.items():
        other = "passed_example" if own[role] == "paper_example" else "paper_example"
        assert not any(n.startswith(f"scenarios.{other}.") for n in declared), role
        assert f"scenarios.{own[role]}.duration_s" in declared, role
    assert {"controller.kp", "controller.kd", "spacecraft.wheel_inertia_kgm2"} <= ctl_names
    assert not any(n.startswith(("constraints.", "filter.", "environment.", "thermal.")) for n in ctl_names)
    assert {"constraints.battery.k1", "filter.preset", "environment.albedo_factor"} <= filter_names
    assert not any(n.startswith("controller.") for n in filter_names) and "stepping" not in filter_names
    assert not any(n.startswith(("constraints.", "spacecraft.")) for n in rec_names) and "bag_path" in rec_names
    assert ok.successful and not bad.successful and "kp" in bad.reason
    assert not frozen.successful and "read-only" in frozen.reason
    a_max = CFG.limits.wheel_accel_max_rad_s2
    np.testing.assert_allclose(u, -a_max * np.tanh(2.5 * x[4:7]), rtol=1e-14)


@pytest.mark.parametrize(("overrides", "message"), [
    ({"filter.prest": "paper"}, "unknown key 'prest'"),
    ({"limits.psi_max_rad_s": "fast"}, "psi_max_rad_s must be a finite number"),
    ({"filter.fallback": "pray"}, "fallback must be one of"),
    ({"scenario": "nope"}, "unknown scenario"),
    ({"startup_timeout_s": "soon"}, "startup_timeout_s must be a float"),
])
def test_bad_parameters_are_one_config_error(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        _node(topics.CONTROLLER, overrides)


def test_node_with_bad_parameter_exits_1_with_one_line(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", topics.MODULES[topics.CONTROLLER], "--ros-args", "-p",
                           "filter.preset:=fast"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr + proc.stdout
    assert "filter.preset must be one of robust, paper, got 'fast'" in proc.stderr + proc.stdout


def test_nodes_package_keeps_rclpy_out_of_the_core_and_launcher() -> None:
    code = ("import sys, rta_attitude.cli.launcher, rta_attitude.ros, rta_attitude.topics, "
            "rta_attitude.ros.convert; print('rclpy' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert proc.stdout.strip() == "False"


# ----------------------------------------------------------------------------- /diagnostics


def test_status_on_diagnostics_names_the_node_and_means_its_level() -> None:
    """A lockstep run in one process: the filter and the plant put their summaries on /diagnostics,
    named `<node>: <what>`; the filter's level follows its call (OK, WARN with slack, ERROR on a fallback)
    and the run ends OK `done`."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    from rta_attitude.ros.diagnostics import filter_level, run_level

    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor("events", context=context)
    common = {"scenario": "paper_example", "rta": True, "record": False, "scenarios.paper_example.duration_s": 60.0}
    nodes = {}
    got: list[Any] = []
    try:
        for role in (topics.FILTER, topics.CONTROLLER, topics.PLANT):
            knob_names = {k.name for k in topics.knobs_for(role)}
            nodes[role] = NODE_CLASSES[role](context=context, namespace=NS, parameter_overrides=[
                Parameter(k, value=v) for k, v in common.items() if k in knob_names or "." in k])
            executor.add_node(nodes[role])
        probe = rclpy.create_node("diagnostics_probe", context=context)
        probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, got.append,
                                  interface.qos_profile(topics.DIAGNOSTICS_QOS))
        executor.add_node(probe)
        deadline = time.monotonic() + 120
        while not (nodes[topics.PLANT].finished.done() and any(
                s.message == topics.RUN_DONE for m in got for s in m.status)):
            assert time.monotonic() < deadline, "run did not finish with a `done` on /diagnostics"
            executor.spin_once(timeout_sec=0.1)
    finally:
        for node in nodes.values():
            node.close()
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=context)
    statuses = [s for m in got for s in m.status]
    assert {s.name for s in statuses} == {f"{NS}/asif_filter: filter", f"{NS}/plant: run"}
    run = [s for s in statuses if s.name.endswith(": run")]
    assert run[-1].level == DiagnosticStatus.OK and run[-1].message == topics.RUN_DONE
    filt = [s for s in statuses if s.name.endswith(": filter")]
    calls = [int({kv.key: kv.value for kv in s.values}["calls"]) for s in filt]
    assert filt and calls == sorted(calls) and calls[0] >= 1
    assert {s.level for s in filt} <= {DiagnosticStatus.OK, DiagnosticStatus.WARN}  # no fallback in this run
    # the level rules themselves
    assert filter_level("fallback", "soften", False) == (DiagnosticStatus.ERROR, "fallback: soften")
    assert filter_level("solved", "", True)[0] == DiagnosticStatus.WARN
    assert filter_level("pass", "", False) == (DiagnosticStatus.OK, "passing u_des through")
    assert run_level("failed: no torque_cmd", 0)[0] == DiagnosticStatus.ERROR
    assert run_level("running", 2) == (DiagnosticStatus.WARN, "running; 2 fault episode(s) active")


def test_parameters_describe_themselves_and_are_read_only() -> None:
    """`ros2 param describe` shows something: a description for every parameter, read_only (read at start-up)
    but the plant's live ones (a failed wheel, topics.LIVE_PARAMETERS), and a knob's choices and range; an
    override out of range is one ConfigError."""
    from rcl_interfaces.msg import ParameterType

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = PlantNode(context=context, parameter_overrides=[Parameter("real_time_factor", value=50.0)])
        skip = ("use_sim_time", "start_type_description_service")
        names = [n for n in node.list_parameters([], 0).names if n not in skip and not n.startswith("qos_overrides.")]
        described = dict(zip(names, node.describe_parameters(names)))
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    live = set(topics.LIVE_PARAMETERS[topics.PLANT])
    assert live == {"spacecraft.failed_wheels"} and live <= set(described)
    assert len(described) > 50 and all(d.description and d.read_only != (n in live) for n, d in described.items())
    assert "may be changed while the node runs" in described["spacecraft.failed_wheels"].description
    rtf, stepping = described["real_time_factor"], described["stepping"]
    assert rtf.floating_point_range[0].from_value == 0.0 and rtf.type == ParameterType.PARAMETER_DOUBLE
    assert "lockstep" in stepping.additional_constraints and "realtime" in stepping.additional_constraints
    assert described["hold_max_steps"].integer_range[0].from_value == 0
    assert "config/rta_attitude.yaml" in described["spacecraft.model"].description
    with pytest.raises(ConfigError, match=r"^parameter real_time_factor must be"):
        _node(topics.PLANT, {"real_time_factor": -2.0})
