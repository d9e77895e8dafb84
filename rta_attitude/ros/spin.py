"""What every node shares: the base node class, the startup gate and `main`.

`run(factory, args)` is each console script's body: check the `--params-file` files, rclpy.init
(without rclpy's own signal handlers), build the node, spin until it finishes or a signal arrives,
then `close()`, destroy_node and try_shutdown. A configuration or runtime error of ours is one log
line and exit code 1, no traceback (a missing or unreadable `--params-file` too, which rcl would
otherwise report with a traceback from rclpy.init).

Signals: SIGINT and SIGTERM do not tear the context down at once (rclpy's default), which would lose
what the node published but its readers have not acknowledged yet. The first one asks the node to
stop (`RtaNode.request_stop`): the plant ends the run as `interrupted` and publishes its final
run_status, the recorder takes the last messages in flight and closes the bag, controller and filter
wait (at most `stop_timeout_s`) until their readers acknowledged everything they published; then the
node finishes and exits 0. A second signal, or `stop_timeout_s` + STOP_MARGIN_S, stops at once.

Startup gate: a writer whose readers have not matched yet would lose its first messages (volatile
durability). `PublishGate` holds messages until the publisher has matched the run's expected
readers (topics.expected_readers), polling on a steady timer so the executor keeps running (all
nodes can share one executor); past `startup_timeout_s` the node fails with a line naming the
topic and the counts.

Peers still starting: no node gives up at `startup_timeout_s` while a node of the run it waits for is
alive and still starting (a first start compiles numba's kernels for 40-70 s; with rta:=false nothing
else made the controller wait for the filter). The ROS graph itself is the announcement: rclpy puts a
node into the graph (its participant and name are discovered) the moment the node object exists, before
its slow start-up work, and the node creates the run's endpoints only when that work is done. So a peer
is *alive and still starting* when a node of its role is in the graph under the run's namespace and has
no publisher or subscription on any of the run's topics yet (`/clock` aside: rclpy's time source reads
it from a use_sim_time node's first moment): `RtaNode.peers_starting`. Waiting is extended one
`startup_timeout_s` at a time while that holds (each extension logged). Why this and not another
mechanism: it needs no extra topic, message or thread, and nothing of a peer that is not ours (a user's
controller, ros2 tools); lifecycle (managed) nodes are ROS's model of "configuring", but they need an
orchestrator to drive every transition and cannot answer their state service while their only thread
compiles; a heartbeat topic would need a thread beside the compiler and a subscriber in every peer. A
peer that dies leaves the graph (Fast DDS's participant lease), so waiting for it ends; a peer that has
started but does not read what it should (e.g. another `rta` value) has endpoints, so the timeout still
ends the wait with the line naming the topic.

Parent: with the knob `exit_with_parent` (the launch file and `rta-attitude launch` set it) a node asks
the kernel for SIGHUP when the process that started it exits (Linux `prctl(PR_SET_PDEATHSIG)`, and a
check of `os.getppid()` in the spin loop elsewhere), so a launcher stopped with SIGTERM or SIGKILL (stock
`ros2 launch` leaves its nodes running on SIGTERM; `docker stop` sends it) takes its nodes with it through
the ordinary stop, as on SIGTERM: the run ends `interrupted: SIGHUP`, the bag is closed.

One module because its parts are one lifecycle: `run` spins until the node's `finished` future is
set, and a signal (`RtaNode.request_stop`, which waits on the gates' publishers), a failure
(`RtaNode.fail`) or a gate's startup timeout all end the node through that future; apart, the stop
protocol would be spread over several files.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rclpy.clock import Clock, ClockType, JumpThreshold, TimeJump
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.event_handler import (
    QoSLivelinessChangedInfo,
    QoSRequestedIncompatibleQoSInfo,
    SubscriptionEventCallbacks,
)
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.serialization import serialize_message
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from rclpy.timer import Timer

from rta_attitude import topics
from rta_attitude.errors import ConfigError, MessageError, RtaError
from rta_attitude.ros import convert, interface, parameters, transport
from rta_attitude.ros.faults import FaultLog, StampOrder

GATE_POLL_S = 0.005
"""How often a closed gate checks its publisher's matches [s]."""
SPIN_TIMEOUT_S = 0.1
"""spin_once timeout of main's loop: a signal is noticed within this time [s] (the EventsExecutor's
own spin() does not return on SIGINT in rclpy 7.1)."""
PEER_BACK_LEASES = 3
"""A lost peer counts as back after this many liveliness leases alive again (`RtaNode._on_liveliness`)."""
PR_SET_PDEATHSIG = 1
"""prctl option (linux/prctl.h): the signal the kernel sends this process when its parent exits."""
PARENT_EXIT_SIGNAL = signal.SIGHUP
"""The signal a node with `exit_with_parent` gets when its parent exits ("hang up": the process that controls
it went away). Not SIGTERM: when a multi-threaded parent is killed, the kernel sends the parent-death signal
once for each of its threads that exits (the child is re-parented to the next), and a second SIGTERM means
"stop at once"; repeats of this one are ignored, so the node stops cleanly."""
PARENT_PID = os.getppid()
"""The process that started this one, as it was when the node's process imported this module."""
FLUSH_SLICE_S = 0.05
"""`flush` waits for acknowledgements in slices this long [s] (see there)."""
STOP_MARGIN_S = 2.0
"""After a stop request, main gives the node stop_timeout_s + this before it stops spinning anyway [s]."""


class RtaNode(Node):
    """Base of the four nodes: parameters from the core YAML, a `finished` future, failure path.

    Args:
        role: topics.PLANT, CONTROLLER, FILTER or RECORDER.
        **kwargs: passed to rclpy Node (e.g. parameter_overrides, cli_args, context).

    Raises:
        ConfigError: invalid parameters (the node is destroyed first).
    """

    def __init__(self, role: str, **kwargs: Any) -> None:
        super().__init__(topics.NODE_NAMES[role], automatically_declare_parameters_from_overrides=False, **kwargs)
        self.role = role
        self.exit_code = 0
        self.finished = Future()
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        try:
            self.cfg, self.knobs = parameters.load(self, role, self._on_live_parameters)
            self.scenario = self.cfg.scenario(self.knobs["scenario"])
        except RtaError:
            self.destroy_node()
            raise
        self.cfg = self.cfg.for_scenario(self.scenario)
        self.epoch_ns = self.scenario.epoch_ns
        """ROS time of t = 0 (the scenario's `epoch_utc`): every stamp of the run is epoch_ns + t."""
        self.rta: bool = self.knobs["rta"]
        self.truth: bool = self.cfg.sensors.enabled
        """Sensor errors on: the plant publishes the true state beside the measured one (TRUTH_TOPICS)."""
        self.record: bool = self.knobs["record"]
        self.scene: str = self.knobs["scene"]
        """The run's scene node (topics.SCENE_MODES)."""
        self.companions: list[RtaNode] = []
        """Nodes this node hosts in its process (the recorder: the scene); `run` spins and closes them too."""
        self.stopping = ""
        """The signal name once a stop was requested ('' before)."""
        self.counts: dict[str, int] = {}
        """Fault counters by kind (FaultLog increments them; nodes publish or log them)."""
        self.faults = FaultLog(self.get_logger(), self.counts, self.on_fault_change)
        self.gates: dict[str, PublishGate] = {}
        self.lost: set[str] = set()
        """Peers (roles) whose writer lost its liveliness and has not shown a sign of life since."""
        self.returning: dict[str, Timer] = {}
        """Lost peers alive again, not yet for PEER_BACK_LEASES leases (`_on_liveliness`)."""
        self.watch_parent = bool(self.knobs["exit_with_parent"]) and not exit_with_parent()
        """exit_with_parent where the kernel does not signal a parent's death: `run` watches os.getppid()."""
        self.counts.setdefault("clock_jumps", 0)
        # a backward jump of /clock (a replay that starts over) resets the stamp screens
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1), on_clock_change=False),
            post_callback=self._on_clock_jump)

    def _on_live_parameters(self, cfg: Any, changes: dict[str, Any]) -> None:
        self.cfg = cfg.for_scenario(self.scenario)
        self.on_live_parameters(changes)

    def on_live_parameters(self, changes: dict[str, Any]) -> None:
        """`ros2 param set` changed live parameters (topics.LIVE_PARAMETERS; self.cfg is the new configuration
        already). Nodes with live parameters override it."""

    def sim_s(self, t_ns: int) -> float:
        """Scenario time [s] of a ROS time stamp [ns] (for log lines and diagnostics)."""
        return (t_ns - self.epoch_ns) / convert.NS_PER_S

    def qos(self, topic: str) -> Any:
        """The QoS profile of one of the run's topics, with this run's liveliness lease."""
        return interface.qos_profile(topics.TOPICS[topic].qos, self.knobs["liveliness_lease_s"])

    def subscribe(self, topic: str, callback: Callable[[Any], None], peer: str = "", raw: bool = False) -> Any:
        """Subscribe to one of the run's topics; with `peer` (the writer's role), report that peer lost once
        when its writer loses liveliness (`on_peer_lost`), and back when it shows a sign of life."""
        spec = topics.TOPICS[topic]
        events = SubscriptionEventCallbacks(
            liveliness=partial(self._on_liveliness, peer) if peer else None,
            incompatible_qos=partial(self._on_incompatible, spec.name))
        return self.create_subscription(interface.msg_class(spec.type_name), spec.name, callback, self.qos(topic),
                                        raw=raw, event_callbacks=events)

    def _on_incompatible(self, topic: str, info: QoSRequestedIncompatibleQoSInfo) -> None:
        policy = getattr(info.last_policy_kind, "name", str(info.last_policy_kind))
        hint = (f" (this node requests a liveliness lease of {self.knobs['liveliness_lease_s']:g} s: give the "
                "writer an automatic lease at most that long, or set liveliness_lease_s:=0 here)"
                if "LIVELINESS" in policy else "")
        self.faults.fault("incompatible_qos", f"a writer of {self.resolve_topic_name(topic)} offers an incompatible "
                          f"QoS ({policy}) and is not matched{hint}")

    def _on_liveliness(self, peer: str, info: QoSLivelinessChangedInfo) -> None:
        """A peer's writer lost its liveliness: reported once (fault `<peer>_lost`). It counts as back only once
        alive again for PEER_BACK_LEASES leases: a killed writer's last packets, delivered late under load,
        assert its liveliness once more, and it is lost again a lease later (without this, a killed plant was
        reported lost, back and lost again within 1.3 s)."""
        if info.not_alive_count_change > 0 and info.alive_count == 0:
            back = self.returning.pop(peer, None)
            if back is not None:  # alive for less than PEER_BACK_LEASES leases: the same episode
                self.destroy_timer(back)
            elif peer not in self.lost:
                self.lost.add(peer)
                self.faults.fault(f"{peer}_lost", f"the {peer} shows no sign of life for "
                                  f"{self.knobs['liveliness_lease_s']:g} s (killed or hung)")
                self.on_peer_lost(peer)
        elif info.alive_count_change > 0 and peer in self.lost and peer not in self.returning:
            self.returning[peer] = self.wall_timer(PEER_BACK_LEASES * self.knobs["liveliness_lease_s"],
                                                   partial(self._peer_back, peer))

    def _peer_back(self, peer: str) -> None:
        """A lost peer stayed alive for PEER_BACK_LEASES leases: back (the fault clears)."""
        timer = self.returning.pop(peer, None)
        if timer is not None:
            self.destroy_timer(timer)
        if peer in self.lost:
            self.lost.discard(peer)
            self.faults.clear(f"{peer}_lost")

    def on_peer_lost(self, peer: str) -> None:
        """A peer's writer lost its liveliness (reported once by then). Nodes override it."""

    def _on_clock_jump(self, jump: TimeJump) -> None:
        if jump.delta.nanoseconds >= 0:
            return
        self.counts["clock_jumps"] += 1
        self.get_logger().info(f"/clock jumped back by {-jump.delta.nanoseconds / 1e9:g} s (a replay started "
                               "over?): stamp screens reset")
        self.on_clock_jump()

    def on_clock_jump(self) -> None:
        """/clock jumped backwards: reset stamp screens and pending work. Nodes override it."""

    def wall_timer(self, period_s: float, callback: Callable[[], None]) -> Timer:
        """A timer on the steady clock (independent of use_sim_time)."""
        return self.create_timer(period_s, callback, clock=self.steady)

    def wall_now_s(self) -> float:
        """Steady time [s]: CLOCK_MONOTONIC, the clock of the steady timers (time.monotonic: rclpy's
        Clock.now() costs ~10 us, and the recorder asks at every message)."""
        return time.monotonic()

    def gate(self, topic: str, publisher: Publisher) -> PublishGate:
        """A PublishGate for one of this node's publishers, expecting the run's readers of `topic`."""
        expected = topics.expected_readers(topic, self.rta, self.record, self.truth, self.scene)
        self.gates[topic] = PublishGate(self, publisher, expected, self.knobs["startup_timeout_s"], topic)
        return self.gates[topic]

    def missing_readers(self, topic: str, publisher: Publisher) -> list[str]:
        """The roles that read `topic` in this run (topics.reader_roles) whose node has no subscription on it
        yet (judged by node name in the graph, under this node's namespace)."""
        ns = self.get_namespace()
        have = {i.node_name for i in self.get_subscriptions_info_by_topic(publisher.topic_name)
                if i.node_namespace == ns}
        want = topics.reader_roles(topic, self.rta, self.record, self.truth, self.scene,
                                   bool(self.knobs.get("external_controller", False)))
        return [r for r in want if topics.NODE_NAMES[r] not in have]

    def peers_starting(self, roles: Iterable[str]) -> list[str]:
        """The node names of `roles` that are alive and still starting (see the module docstring): in the
        ROS graph under this node's namespace, without a publisher or subscription on any of the run's
        topics but /clock."""
        ns = self.get_namespace()
        alive = {name for name, node_ns in self.get_node_names_and_namespaces() if node_ns == ns}
        run_topics = {self.resolve_topic_name(t) for t in topics.TOPICS if t != topics.CLOCK}
        starting = set()
        for name in {topics.NODE_NAMES[r] for r in roles} & alive:
            try:
                endpoints = [*self.get_publisher_names_and_types_by_node(name, ns),
                             *self.get_subscriber_names_and_types_by_node(name, ns)]
            except RuntimeError:  # rclpy's NodeNameNonExistentError: it left the graph in between
                continue
            if not any(topic in run_topics for topic, _ in endpoints):
                starting.add(name)
        return sorted(starting)

    def on_fault_change(self, kind: str, active: bool) -> None:
        """A fault episode of `kind` started (active) or ended; the plant republishes run_status."""

    def message_stamp(self, msg: Any, kind: str) -> int | None:
        """The header stamp of msg (a message, or its CDR bytes from a raw subscription) in ns, or None (fault
        `kind` raised, message dropped) if unusable."""
        try:
            return convert.cdr_stamp_ns(msg) if isinstance(msg, bytes) else convert.stamp_ns(msg.header.stamp)
        except MessageError as exc:
            self.faults.fault(kind, f"{exc}; dropped")
            return None

    def unit_state(self, x: np.ndarray, t_ns: int) -> np.ndarray:
        """A received state (19,), its quaternion renormalised within `quaternion_tolerance` (fault
        `state_renormalised` raised or cleared).

        Raises:
            MessageError: the quaternion is not finite or off by more than the tolerance.
        """
        x, renormalised = convert.unit_attitude(x, self.knobs["quaternion_tolerance"])
        if renormalised:
            self.faults.fault("state_renormalised", f"state quaternion of t = {self.sim_s(t_ns):g} s "
                              "renormalised")
        else:
            self.faults.clear("state_renormalised")
        return x

    def admit_state_stamp(self, t_ns: int, order: StampOrder) -> bool:
        """Screen a state's stamp: duplicates, out-of-order stamps and (on /clock) states older than
        `max_state_age_s` are dropped and counted as one fault episode each; an admitted stamp is
        taken into `order`. Returns True if the state may be used."""
        kind = order.check(t_ns)
        if kind:
            self.faults.fault(f"state_{kind}", f"stamp t = {self.sim_s(t_ns):g} s, newest "
                              f"{self.sim_s(order.newest_ns or self.epoch_ns):g} s; dropped")
            return False
        max_age = self.knobs["max_state_age_s"]
        if max_age > 0 and self.uses_sim_time():
            age = (self.get_clock().now().nanoseconds - t_ns) / convert.NS_PER_S
            if age > max_age:
                self.faults.fault("state_stale", f"state of t = {self.sim_s(t_ns):g} s is {age:g} s old "
                                  f"(max_state_age_s {max_age:g}); dropped")
                return False
        order.take(t_ns)
        self.faults.clear("state_duplicate", "state_out_of_order", "state_stale")
        return True

    def uses_sim_time(self) -> bool:
        """True when the node's clock follows /clock (use_sim_time) and /clock has been heard."""
        clock = self.get_clock()
        return bool(self.get_parameter("use_sim_time").value) and bool(getattr(clock, "ros_time_is_active", False))

    def flush(self, timeout_s: float, needed: Callable[[], bool] | None = None) -> bool:
        """Wait until every reader acknowledged what this node's publishers sent (at most timeout_s in
        total). Returns True if all did.

        Args:
            needed: for the publishers other than run_status: wait only while this says the data is still
                needed (the plant's final flush: while the recorder is there; once it has closed the bag,
                nothing is owed). Checked every FLUSH_SLICE_S.
        """
        deadline = self.wall_now_s() + timeout_s
        ok = True
        # run_status first: the final status is what readers wait for; a dead reader of another topic
        # (a killed node stays matched until its lease expires) must not use up the time before it
        status = "/" + topics.RUN_STATUS
        for pub in sorted(self.own_publishers(), key=lambda p: not p.topic_name.endswith(status)):
            # in slices, so that `needed` is checked and a new wait counts only the readers still matched
            while not pub.wait_for_all_acked(Duration(nanoseconds=int(FLUSH_SLICE_S * 1e9))):
                if self.wall_now_s() >= deadline:
                    ok = False
                    break
                if needed is not None and not pub.topic_name.endswith(status) and not needed():
                    break
        return ok

    def own_publishers(self) -> list[Publisher]:
        """The run's publishers of this node (not rclpy's /rosout and /parameter_events)."""
        return [gate.publisher for gate in self.gates.values()]

    def request_stop(self, reason: str) -> None:
        """SIGINT/SIGTERM: stop cleanly (idempotent): log, then `on_stop`."""
        if self.stopping:
            return
        self.stopping = reason
        self.get_logger().info(f"{reason}: stopping")
        self.on_stop()

    def on_stop(self) -> None:
        """What a stop request does (after `stopping` is set). Default: wait (at most stop_timeout_s) until
        the readers acknowledged what this node published, then finish. Nodes override it."""
        self.flush(self.knobs["stop_timeout_s"])
        self.finish()

    def published_counts(self) -> dict[str, int]:
        """Messages published per topic (relative name) through this node's gates."""
        return {topic: gate.sent for topic, gate in self.gates.items()}

    def fail(self, reason: str) -> None:
        """Log one error line, set exit code 1 and finish."""
        self.get_logger().error(reason)
        self.exit_code = 1
        self.finish()

    def finish(self) -> None:
        """Mark the node done (main stops spinning); idempotent."""
        if not self.finished.done():
            self.finished.set_result(self.exit_code)

    def close(self) -> None:
        """Release resources before destroy_node (the recorder closes its bag here). Logs one line with
        what the node published and its fault counters."""
        sent = ", ".join(f"{t} {n}" for t, n in sorted(self.published_counts().items()))
        self.get_logger().info(f"published: {sent or 'nothing'}; counters: {self.faults.summary()}")


class PublishGate:
    """Publish through this: messages wait (serialized, so later changes of the message object do not
    reach them) until the publisher matched `expected` subscriptions.

    Once open the gate stays open (later publishes go straight through). Past `timeout_s` the node fails,
    unless a missing reader of `topic` is alive and still starting (`RtaNode.peers_starting`): then it
    waits another `timeout_s` (counted in `extensions`).
    """

    def __init__(self, node: RtaNode, publisher: Publisher, expected: int, timeout_s: float,
                 topic: str = "") -> None:
        self.node, self.publisher, self.expected = node, publisher, expected
        self.topic = topic
        """The relative topic name (topics.TOPICS) whose readers are expected; '' = none known by role."""
        self.timeout_s = timeout_s
        self.is_open = expected <= 0
        self._queue: list[Any] = []
        self._timer: Timer | None = None
        self._since = 0.0
        self.sent = 0
        """Messages handed to the publisher (not counting those still held)."""
        self.extensions = 0
        """How often `timeout_s` ran out while a missing reader was alive and still starting."""

    def matched(self) -> bool:
        """True (and open from now on) once the expected readers are matched."""
        if not self.is_open and self.publisher.get_subscription_count() >= self.expected:
            self.is_open = True
        return self.is_open

    def publish(self, msg: Any) -> None:
        if self.is_open or self.matched():
            self.publisher.publish(msg)
            self.sent += 1
            return
        # held as bytes: publishers rewrite one message object per call (convert's builders), so a held
        # reference would go out later with a later call's content (found: a restarted filter's first
        # filter_status recorded twice with its second call's values, its first lost)
        self._queue.append(msg if isinstance(msg, bytes) else serialize_message(msg))
        if self._timer is None:
            self._since = self.node.wall_now_s()
            self._timer = self.node.wall_timer(GATE_POLL_S, self._poll)

    def _poll(self) -> None:
        if self.matched():
            for msg in self._queue:
                self.publisher.publish(msg)
            self.sent += len(self._queue)
            self._queue.clear()
        elif self.node.wall_now_s() - self._since > self.timeout_s:
            starting = self.node.peers_starting(self.node.missing_readers(self.topic, self.publisher)) \
                if self.topic else []
            if starting:  # alive, not subscribed yet (compiling its kernels): wait as long as it takes
                self.extensions += 1
                self._since = self.node.wall_now_s()
                self.node.get_logger().info(f"{self.publisher.topic_name}: waiting for {', '.join(starting)} to "
                                            f"finish starting (alive, no endpoints after {self.timeout_s:g} s)")
                return
            have = self.publisher.get_subscription_count()
            self.node.fail(f"{self.publisher.topic_name}: {have} of {self.expected} expected readers after "
                           f"{self.timeout_s:g} s (is every node of the run up? set record:=false without a recorder)")
        else:
            return
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
            self._timer = None


def make_executor(kind: str, context: Context | None = None) -> Executor:
    """'events': rclpy's C++ EventsExecutor (rclpy.experimental; several times less overhead per
    callback than the Python executors); 'single': SingleThreadedExecutor."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def check_params_files(args: Sequence[str]) -> None:
    """Check every `--params-file FILE` of a ROS command line before rcl reads it: the file must exist
    and be YAML. (rcl would report either with a traceback from rclpy.init.)

    Raises:
        ConfigError: one line naming the file and what is wrong.
    """
    import yaml

    args = list(args)
    for i, arg in enumerate(args):
        if arg != "--params-file":
            continue
        if i + 1 >= len(args):
            raise ConfigError("--params-file needs a file name")
        path = Path(args[i + 1])
        if not path.is_file():
            raise ConfigError(f"--params-file {str(path)!r} does not exist (a YAML parameter file is required)")
        try:
            yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            line = getattr(getattr(exc, "problem_mark", None), "line", None)
            where = f" at line {line + 1}" if line is not None else ""
            raise ConfigError(f"--params-file {str(path)!r} is not valid YAML{where}") from None
        except OSError as exc:
            raise ConfigError(f"--params-file {str(path)!r} cannot be read ({exc.strerror})") from None


def _error(name: str, text: str) -> None:
    """One error line on stderr in rclpy's format, for errors before or without a node."""
    print(f"[ERROR] [{name}]: {text}", file=sys.stderr, flush=True)


def run(factory: Callable[[], RtaNode], args: Sequence[str] | None = None, name: str = "rta_attitude",
        restore_signals: bool = True) -> int:
    """Check the command line, init rclpy, build the node, spin until it finishes or is stopped by
    SIGINT/SIGTERM (see the module docstring), shut down cleanly.

    Args:
        factory: builds the node (after rclpy.init).
        args: command line (default sys.argv), with `--ros-args ...`.
        name: logger name for errors raised before the node exists.
        restore_signals: put the previous SIGINT/SIGTERM handlers back before returning (in-process
            callers); `main` passes False and ignores both signals until the process has exited.

    Returns:
        Exit code: 0, or 1 after a configuration or runtime error (logged as one line).
    """
    from rclpy._rclpy_pybind11 import RCLError

    argv = list(args) if args is not None else list(sys.argv)
    received: list[int] = []

    def on_signal(signum: int, frame: Any) -> None:
        if signum == PARENT_EXIT_SIGNAL and received:
            return  # the parent's exit is one event: the kernel signals it once per exiting thread of the parent
        received.append(signum)
        if _INTERRUPTIBLE[0]:  # compiling kernels in a constructor (nothing to close yet): abandon the start
            raise KeyboardInterrupt

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM, PARENT_EXIT_SIGNAL)}
    node: RtaNode | None = None
    executor: Executor | None = None
    code = 0
    try:
        check_params_files(argv)
        transport.use_profile()  # before the participant exists: a lost sample repaired in 0.1 s, not 3 s
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except ConfigError as exc:
        _error(name, str(exc))
        _restore(previous)
        return 1
    except RCLError as exc:
        _error(name, f"ROS arguments rejected: {str(exc).splitlines()[0]}")
        _restore(previous)
        return 1
    try:
        node = factory()
        executor = make_executor(node.knobs["executor"])
        executor.add_node(node)
        for companion in node.companions:
            executor.add_node(companion)
        hard_stop = float("inf")
        while rclpy.ok() and not node.finished.done():
            if node.watch_parent and not received and os.getppid() != PARENT_PID:  # no PR_SET_PDEATHSIG here
                received.append(PARENT_EXIT_SIGNAL)
            if received and not node.stopping:
                node.request_stop(signal.Signals(received[0]).name)
                hard_stop = node.wall_now_s() + node.knobs["stop_timeout_s"] + STOP_MARGIN_S
                continue
            if len(received) > 1 or node.wall_now_s() > hard_stop:
                node.get_logger().warning("stopped before the node finished (second signal or stop timeout)")
                break
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
        code = node.exit_code
    except (KeyboardInterrupt, ExternalShutdownException):
        code = node.exit_code if node is not None else 0
    except RtaError as exc:
        (node.get_logger() if node is not None else rclpy.logging.get_logger(name)).error(str(exc))
        code = 1
    except Exception:
        if rclpy.ok() and not received:
            raise
        code = node.exit_code if node is not None else 0  # a signal while starting: a clean stop
    finally:
        _INTERRUPTIBLE[0] = False
        if executor is not None:
            executor.shutdown()
        for companion in node.companions if node is not None else []:
            companion.close()
            companion.destroy_node()
        if node is not None:
            try:
                node.close()
            except RtaError as exc:
                node.get_logger().error(str(exc))
                code = 1
            node.destroy_node()
        rclpy.try_shutdown()
        if restore_signals:
            _restore(previous)
    return code


def main(factory: Callable[[], RtaNode], args: Sequence[str] | None, name: str) -> None:
    """A node's console script: run it, then exit with its code. Once the node has finished, SIGINT and
    SIGTERM are ignored until the process is gone: `ros2 launch` sends SIGINT to every process when a
    run ends, and one that reached a finished node during interpreter teardown would turn a clean end
    into "process has died [exit code -2]"."""
    code = run(factory, args, name, restore_signals=False)
    for s in (signal.SIGINT, signal.SIGTERM, PARENT_EXIT_SIGNAL):
        signal.signal(s, signal.SIG_IGN)
    sys.exit(code)


_INTERRUPTIBLE = [False]
"""True while a constructor runs a step that holds nothing to close (`interruptible`)."""


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """A start-up step that may take long and holds nothing that needs closing (loading or compiling
    kernels): a SIGINT/SIGTERM during it abandons the start at once (exit 0) instead of waiting for it,
    so a launch's shutdown never has to escalate to SIGKILL."""
    _INTERRUPTIBLE[0] = True
    try:
        yield
    finally:
        _INTERRUPTIBLE[0] = False


def exit_with_parent() -> bool:
    """Have PARENT_EXIT_SIGNAL (SIGHUP) sent to this process when its parent exits (Linux: prctl
    PR_SET_PDEATHSIG, which fires when the thread that started this process ends, and again for each thread
    of the parent it is re-parented to); if the parent is gone already, send it now. `run`'s handler then
    stops the node as on SIGTERM, once. Returns False where the kernel cannot do it: `run` then compares
    os.getppid() with PARENT_PID while it spins. (A parent that exits before this process imported this module
    is not noticed: the window of the interpreter's start.)"""
    armed = False
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            armed = ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(PARENT_EXIT_SIGNAL), 0, 0, 0) == 0
    if os.getppid() != PARENT_PID:
        os.kill(os.getpid(), PARENT_EXIT_SIGNAL)
    return armed


def _restore(previous: dict[signal.Signals, Any]) -> None:
    for s, handler in previous.items():
        signal.signal(s, handler)


__all__ = ["GATE_POLL_S", "PARENT_PID", "SPIN_TIMEOUT_S", "STOP_MARGIN_S", "PublishGate", "RtaNode",
           "check_params_files", "exit_with_parent", "interruptible", "main", "make_executor", "run"]
