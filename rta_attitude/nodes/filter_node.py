"""asif_filter_node: state + torque_des -> torque_cmd + filter_status, one AsifFilter.filter call
per step. With `rta:=false` it passes torque_des through unchanged (same bytes of float, same
stamp) and publishes no filter_status: the plant always takes torque_cmd, and a run without RTA
has the same topics and the same number of hops as one with it.

The state and the desired torque of a step travel on different topics (plant -> filter and plant ->
controller -> filter), so the node pairs them by stamp: whichever arrives second triggers the call,
and the pairing does not depend on arrival order. torque_cmd is published before filter_status
(the plant waits on it). With fallback `raise` a failed QP stops the node with one error line.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from .. import model
from ..asif import AsifFilter
from ..errors import MessageError
from . import convert, topics
from .spin import RtaNode, run

MAX_PENDING = 64
"""Unpaired messages kept per topic; older ones are dropped (and counted)."""


class FilterNode(RtaNode):
    """The ASIF safety filter; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(topics.FILTER, **kwargs)
        self.filter = AsifFilter(self.cfg)
        self.slacked = tuple(n for n, s in zip(self.filter.names, self.filter.slacked) if s)
        self.states: dict[int, np.ndarray] = {}
        self.desired: dict[int, np.ndarray] = {}
        self.rejected = self.dropped = 0
        self.out: dict[str, Any] = {}
        for spec in topics.published(topics.FILTER, self.rta):
            pub = self.create_publisher(topics.msg_class(spec.type_name), spec.name, topics.qos_profile(spec.qos))
            self.out[spec.name] = self.gate(spec.name, pub)
        callbacks = {topics.STATE: self._on_state, topics.TORQUE_DES: self._on_desired}
        for spec in topics.subscribed(topics.FILTER, self.rta):
            self.create_subscription(topics.msg_class(spec.type_name), spec.name, callbacks[spec.name],
                                     topics.qos_profile(spec.qos))
        if self.rta:
            self.get_logger().info(f"filter preset {self.cfg.filter.preset}, fallback {self.cfg.filter.fallback}, "
                                   f"slacked: {', '.join(self.slacked) or 'none'}")
        else:
            self.get_logger().info("rta off: passing torque_des through to torque_cmd")

    def _on_state(self, msg: Any) -> None:
        self._take(msg, convert.state_from_msg, self.states, "state")

    def _on_desired(self, msg: Any) -> None:
        if self.rta:
            self._take(msg, convert.torque_from_msg, self.desired, "torque_des")
            return
        try:
            t_ns, tau = convert.torque_from_msg(msg)
        except MessageError as exc:
            self.rejected += 1
            self.get_logger().warning(f"torque_des rejected ({exc})", throttle_duration_sec=5.0)
            return
        self.out[topics.TORQUE_CMD].publish(convert.torque_msg(tau, t_ns))

    def _take(self, msg: Any, parse: Any, into: dict[int, np.ndarray], what: str) -> None:
        try:
            t_ns, value = parse(msg)
        except MessageError as exc:
            self.rejected += 1
            self.get_logger().warning(f"{what} rejected ({exc})", throttle_duration_sec=5.0)
            return
        into[t_ns] = value
        if t_ns in self.states and t_ns in self.desired:
            self._filter(t_ns, self.states.pop(t_ns), self.desired.pop(t_ns))
        for pending in (self.states, self.desired):
            while len(pending) > MAX_PENDING:
                del pending[min(pending)]
                self.dropped += 1

    def _filter(self, t_ns: int, x: np.ndarray, tau_des: np.ndarray) -> None:
        res = self.filter.filter(x, model.torque_to_wheel_accel(tau_des, self.cfg))
        self.out[topics.TORQUE_CMD].publish(convert.torque_msg(model.wheel_accel_to_torque(res.u, self.cfg), t_ns))
        self.out[topics.FILTER_STATUS].publish(convert.filter_status_msg(
            res, t_ns, self.filter.counters, self.cfg.filter.preset, self.slacked))
        if res.fallback and res.fallback != "non_finite_u_des":
            self.get_logger().warning(f"t = {t_ns / convert.NS_PER_S:g} s: QP {res.solver_status}, "
                                      f"fallback {res.fallback}", throttle_duration_sec=5.0)


def main(args: Sequence[str] | None = None) -> None:
    """Console script `asif_filter_node` (`ros2 run rta_attitude asif_filter_node --ros-args ...`)."""
    sys.exit(run(FilterNode, args, topics.NODE_NAMES[topics.FILTER]))

if __name__ == "__main__":
    main()
