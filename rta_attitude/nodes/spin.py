"""What every node shares: the base node class, the startup gate and `main`.

`run(factory, args)` is each console script's body: rclpy.init (SIGINT and SIGTERM handlers),
build the node, spin until it finishes or a signal arrives, then `close()`, destroy_node and
try_shutdown. A configuration or runtime error of ours is one log line and exit code 1; Ctrl-C is a
clean exit 0 (no traceback).

Startup gate: a writer whose readers have not matched yet would lose its first messages (volatile
durability). `PublishGate` holds messages until the publisher has matched the run's expected
readers (topics.expected_readers), polling on a steady timer so the executor keeps running (all
nodes can share one executor); past `startup_timeout_s` the node fails with a line naming the
topic and the counts.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.task import Future
from rclpy.timer import Timer

from ..errors import RtaError
from . import parameters, topics

GATE_POLL_S = 0.005
SPIN_TIMEOUT_S = 0.1
"""spin_once timeout of main's loop: a signal is noticed within this time [s] (the EventsExecutor's
own spin() does not return on SIGINT in rclpy 7.1)."""
"""How often a closed gate checks its publisher's matches [s]."""


class RtaNode(Node):
    """Base of the four nodes: parameters from the core YAML, a `finished` future, failure path.

    Args:
        role: topics.PLANT, CONTROLLER, FILTER or RECORDER.
        **kwargs: passed to rclpy Node (e.g. parameter_overrides, cli_args, context).

    Raises:
        ConfigError: invalid parameters (the node is destroyed first).
    """

    def __init__(self, role: str, **kwargs: Any) -> None:
        kwargs.setdefault("namespace", topics.DEFAULT_NAMESPACE)
        super().__init__(topics.NODE_NAMES[role], automatically_declare_parameters_from_overrides=True, **kwargs)
        self.role = role
        self.exit_code = 0
        self.finished = Future()
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        try:
            self.cfg, self.knobs = parameters.load(self, topics.knobs_for(role))
            self.scenario = self.cfg.scenario(self.knobs["scenario"])
        except RtaError:
            self.destroy_node()
            raise
        self.cfg = self.cfg.for_scenario(self.scenario)
        self.rta: bool = self.knobs["rta"]
        self.record: bool = self.knobs["record"]

    def wall_timer(self, period_s: float, callback: Callable[[], None]) -> Timer:
        """A timer on the steady clock (independent of use_sim_time)."""
        return self.create_timer(period_s, callback, clock=self.steady)

    def wall_now_s(self) -> float:
        """Steady time [s]."""
        return self.steady.now().nanoseconds * 1e-9

    def gate(self, topic: str, publisher: Publisher) -> PublishGate:
        """A PublishGate for one of this node's publishers, expecting the run's readers of `topic`."""
        expected = topics.expected_readers(topic, self.rta, self.record)
        return PublishGate(self, publisher, expected, self.knobs["startup_timeout_s"])

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
        """Release resources before destroy_node (the recorder closes its bag here)."""


class PublishGate:
    """Publish through this: messages wait until the publisher matched `expected` subscriptions.

    Once open the gate stays open (later publishes go straight through).
    """

    def __init__(self, node: RtaNode, publisher: Publisher, expected: int, timeout_s: float) -> None:
        self.node, self.publisher, self.expected = node, publisher, expected
        self.timeout_s = timeout_s
        self.is_open = expected <= 0
        self._queue: list[Any] = []
        self._timer: Timer | None = None
        self._since = 0.0

    def matched(self) -> bool:
        """True (and open from now on) once the expected readers are matched."""
        if not self.is_open and self.publisher.get_subscription_count() >= self.expected:
            self.is_open = True
        return self.is_open

    def publish(self, msg: Any) -> None:
        if self.is_open or self.matched():
            self.publisher.publish(msg)
            return
        self._queue.append(msg)
        if self._timer is None:
            self._since = self.node.wall_now_s()
            self._timer = self.node.wall_timer(GATE_POLL_S, self._poll)

    def _poll(self) -> None:
        if self.matched():
            for msg in self._queue:
                self.publisher.publish(msg)
            self._queue.clear()
        elif self.node.wall_now_s() - self._since > self.timeout_s:
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


def run(factory: Callable[[], RtaNode], args: Sequence[str] | None = None, name: str = "rta_attitude") -> int:
    """Init rclpy, build the node, spin until it finishes or SIGINT/SIGTERM, shut down cleanly.

    Args:
        factory: builds the node (after rclpy.init).
        args: command line (default sys.argv), with `--ros-args ...`.
        name: logger name for errors raised before the node exists.

    Returns:
        Exit code: 0, or 1 after a configuration or runtime error (logged as one line).
    """
    rclpy.init(args=list(args) if args is not None else sys.argv)
    node: RtaNode | None = None
    executor: Executor | None = None
    code = 0
    try:
        node = factory()
        executor = make_executor(node.knobs["executor"])
        executor.add_node(node)
        while rclpy.ok() and not node.finished.done():
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
        code = node.exit_code
    except (KeyboardInterrupt, ExternalShutdownException):
        code = node.exit_code if node is not None else 0
    except RtaError as exc:
        rclpy.logging.get_logger(node.get_name() if node is not None else name).error(str(exc))
        code = 1
    except Exception:
        if rclpy.ok():
            raise
        code = node.exit_code if node is not None else 0  # SIGINT/SIGTERM while starting: a clean stop
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            try:
                node.close()
            except RtaError as exc:
                node.get_logger().error(str(exc))
                code = 1
            node.destroy_node()
        rclpy.try_shutdown()
    return code


__all__ = ["GATE_POLL_S", "SPIN_TIMEOUT_S", "PublishGate", "RtaNode", "make_executor", "run"]
