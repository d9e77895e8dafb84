"""The DDS loop's floor: four rclpy nodes with the run's topics, types, QoS and messages per step that
only forward (no physics, no filter, no bag). bench_dds.py runs it beside the real loop.

    python bench/forward_chain.py ROLE --steps N [--result FILE] [--raw]   (ROLE: plant controller filter recorder)

- plant: waits until every topic it writes has the run's readers, then publishes the state of t_0; on each
  torque_cmd(t_k) publishes /clock, the five state messages (topics.STATE_INPUTS), the packed `state` and
  torque_applied, the real plant's set; after the last step run_status `done`. It writes the wall
  time from its first state to the last command to --result (the real plant's `wall_time_s`).
- controller: on each odometry, publishes torque_des with its stamp.
- filter: on the five state messages and torque_des of the same stamp, publishes torque_cmd and filter_status.
- recorder: subscribes raw to every recorded topic and counts; exits on run_status `done`.

Controller, filter and recorder run with use_sim_time (so they subscribe to /clock), as the launcher starts
the real ones. The messages are the real nodes' messages (built once by `ros.convert` from a real state and filter
result, then re-stamped), on the real QoS profiles, spun by the same executor (rclpy's EventsExecutor).

By default the chain is what the issue names: plain rclpy nodes that take and send message objects. With
`--raw` every node takes its messages as bytes (raw subscriptions) and sends bytes re-stamped in place, as the
real nodes do since they write and read the loop's messages as CDR bytes (`convert.CdrLayout`): the floor of
that design, with no message conversion at all.
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.signals import SignalHandlerOptions

from rta_attitude import config, topics
from rta_attitude.dynamics.sensors import message_fields, sensors_record
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.ros import convert, interface

LEASE_S = 2.0
MATCH_TIMEOUT_S = 60.0


def _stamp(msg: Any, t_ns: int) -> Any:
    if isinstance(msg, bytes):  # every message here starts with its stamp (a Header's, or Clock's)
        return msg[:4] + struct.pack("<iI", *divmod(t_ns, convert.NS_PER_S)) + msg[12:]
    msg.header.stamp = convert.stamp(t_ns)
    return msg


def _stamp_ns(msg: Any) -> int:
    return convert.cdr_stamp_ns(msg) if isinstance(msg, bytes) else convert.stamp_ns(msg.header.stamp)


class Forwarder(Node):
    def __init__(self, role: str, steps: int, raw: bool = False) -> None:
        sim_time = [] if role == topics.PLANT else [Parameter("use_sim_time", value=True)]  # as the launcher does
        super().__init__(topics.NODE_NAMES[role], namespace=topics.DEFAULT_NAMESPACE, parameter_overrides=sim_time)
        self.role, self.steps, self.done, self.raw = role, steps, False, raw
        self.result: dict[str, Any] = {}
        self.matched: set[str] = set()
        self.pubs = {s.name: self.create_publisher(interface.msg_class(s.type_name), s.name,
                                                   interface.qos_profile(s.qos, LEASE_S))
                     for s in topics.published(role, rta=True)}  # fmt: skip
        cfg = config.load()
        scen = cfg.scenario("paper-example")
        x = np.asarray(scen.x0, dtype=float)
        self.msgs: dict[str, Any] = {}
        if role == topics.PLANT:
            fields = message_fields(x, sensors_record(cfg))
            self.msgs = convert.state_messages(fields, 0, cfg.power.bus_voltage_V, -1.0, np.zeros(3))
            self.msgs[topics.STATE] = convert.state_msg(x, 0)
            self.msgs[topics.TORQUE_APPLIED] = convert.torque_msg(np.zeros(3), 0)
            self.sub(topics.TORQUE_CMD, self.on_command)
            self.k, self.t0 = 0, 0.0
            self.gate = self.create_timer(0.005, self.start)
        elif role == topics.CONTROLLER:
            self.msgs = {topics.TORQUE_DES: convert.torque_msg(np.ones(3) * 1e-5, 0)}
            self.sub(topics.ODOMETRY, self.on_state_controller)
        elif role == topics.FILTER:
            f = AsifFilter(cfg)
            res = f.filter(x, np.zeros(3))
            self.msgs = {topics.TORQUE_CMD: convert.torque_msg(np.ones(3) * 1e-5, 0),
                         topics.FILTER_STATUS: convert.filter_status_msg(res, 0, f.counters, "robust",
                                                                         list(cfg.slacked_constraints))}
            self.parts: dict[int, int] = {}
            self.states: set[int] = set()
            self.desired: set[int] = set()
            for name in topics.STATE_INPUTS:
                self.sub(name, self.on_state_filter)
            self.sub(topics.TORQUE_DES, self.on_desired)
        else:
            self.count = 0
            for spec in topics.recorded(rta=True):
                cb = self.on_run_status if spec.name == topics.RUN_STATUS else self.on_raw
                self.sub(spec.name, cb, raw=spec.name != topics.RUN_STATUS)
        if raw:
            self.msgs = {k: bytes(serialize_message(m)) for k, m in self.msgs.items()}
            self.msgs[topics.CLOCK] = bytes(serialize_message(convert.clock_msg(0)))

    def sub(self, topic: str, cb: Any, raw: bool = False) -> None:
        spec = topics.TOPICS[topic]
        self.create_subscription(interface.msg_class(spec.type_name), spec.name, cb,
                                 interface.qos_profile(spec.qos, LEASE_S), raw=raw or self.raw)

    def publish(self, topic: str, t_ns: int) -> None:
        if topic not in self.matched:  # as the nodes' PublishGate: a volatile message sent before its reader
            # matched is lost, and the lockstep chain would stall on it (found: a bench run hung at its start)
            deadline = time.monotonic() + MATCH_TIMEOUT_S
            while self.pubs[topic].get_subscription_count() < topics.expected_readers(topic, rta=True, record=True):
                if time.monotonic() > deadline:
                    raise SystemExit(f"forward chain: {topic} has no reader after {MATCH_TIMEOUT_S:g} s")
                time.sleep(0.005)
            self.matched.add(topic)
        self.pubs[topic].publish(_stamp(self.msgs[topic], t_ns) if topic in self.msgs else convert.clock_msg(t_ns))

    # plant
    def start(self) -> None:
        for name, pub in self.pubs.items():
            if pub.get_subscription_count() < topics.expected_readers(name, rta=True, record=True):
                return
        self.gate.cancel()
        self.pubs[topics.RUN_STATUS].publish(convert.run_status_msg(0, topics.RUN_RUNNING, {}))
        self.t0 = time.perf_counter()
        self.sample(0)

    def sample(self, t_ns: int) -> None:
        self.publish(topics.CLOCK, t_ns)
        for name in topics.STATE_INPUTS:
            self.publish(name, t_ns)
        self.publish(topics.STATE, t_ns)

    def on_command(self, msg: Any) -> None:
        t_ns = _stamp_ns(msg)
        if t_ns != convert.seconds_to_ns(self.k):
            return
        if self.k == self.steps:
            self.result = {"loop_s": time.perf_counter() - self.t0, "steps": self.steps}
            self.pubs[topics.RUN_STATUS].publish(convert.run_status_msg(t_ns, topics.RUN_DONE, {}))
            # as the plant node: the recorder ends on this status, and a reliable sample lost under load is
            # repaired only while its writer lives (found: a bench run's recorder waited out its timeout)
            self.pubs[topics.RUN_STATUS].wait_for_all_acked(Duration(seconds=MATCH_TIMEOUT_S))
            self.done = True
            return
        self.k += 1
        t_next = convert.seconds_to_ns(self.k)
        self.sample(t_next)
        self.publish(topics.TORQUE_APPLIED, t_ns)

    # controller
    def on_state_controller(self, msg: Any) -> None:
        t_ns = _stamp_ns(msg)
        self.publish(topics.TORQUE_DES, t_ns)
        if t_ns == convert.seconds_to_ns(self.steps):
            self.done = True

    # filter
    def on_state_filter(self, msg: Any) -> None:
        t_ns = _stamp_ns(msg)
        self.parts[t_ns] = self.parts.get(t_ns, 0) + 1
        if self.parts[t_ns] == len(topics.STATE_INPUTS):
            del self.parts[t_ns]
            self.states.add(t_ns)
            self.answer()

    def on_desired(self, msg: Any) -> None:
        self.desired.add(_stamp_ns(msg))
        self.answer()

    def answer(self) -> None:
        for t_ns in sorted(self.states & self.desired):
            self.states.discard(t_ns)
            self.desired.discard(t_ns)
            self.publish(topics.TORQUE_CMD, t_ns)
            self.publish(topics.FILTER_STATUS, t_ns)
            if t_ns == convert.seconds_to_ns(self.steps):
                self.done = True

    # recorder
    def on_raw(self, data: bytes) -> None:
        self.count += 1

    def on_run_status(self, msg: Any) -> None:
        if isinstance(msg, bytes):
            msg = deserialize_message(msg, interface.msg_class(topics.TOPICS[topics.RUN_STATUS].type_name))
        if convert.run_status_from_msg(msg)[0] == topics.RUN_DONE:
            self.done = True


def command(role: str, steps: int, result: Path, raw: bool = False) -> list[str]:
    """This script's command line for one role of a chain of `steps` steps (the plant writes `result`)."""
    return [sys.executable, str(Path(__file__).resolve()), role, "--steps", str(steps),
            *(["--result", str(result)] if role == topics.PLANT else []), *(["--raw"] if raw else [])]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("role", choices=(topics.PLANT, topics.CONTROLLER, topics.FILTER, topics.RECORDER))
    ap.add_argument("--steps", type=int, required=True)
    ap.add_argument("--result", type=Path)
    ap.add_argument("--timeout", type=float, default=600.0)
    ap.add_argument("--raw", action="store_true", help="take and send bytes (the real nodes' design since CdrLayout)")
    args = ap.parse_args()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Forwarder(args.role, args.steps, args.raw)
    ex = EventsExecutor()
    ex.add_node(node)
    deadline = time.monotonic() + args.timeout
    try:
        while not node.done and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.1)
        if args.result is not None and node.result:  # before the teardown (bench_dds: a hang there is not fatal)
            args.result.write_text(json.dumps(node.result))
        end = time.monotonic() + 0.5  # let the last messages reach their readers
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if node.done else 1


if __name__ == "__main__":
    sys.exit(main())
