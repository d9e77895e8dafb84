"""asif_filter_node: the state (odometry, joint_states, temperature, battery, sun_vector:
`topics.STATE_INPUTS`, paired by exact stamp and rebuilt by `dynamics.sensors.decode`) + torque_des ->
torque_cmd + filter_status, one AsifFilter.filter call per step. With `rta:=false` it passes
torque_des through unchanged (same bytes of float, same stamp) and publishes no filter_status: the
plant always takes torque_cmd, and a run without RTA has the same topics and the same number of hops
as one with it.

The state and the desired torque of a step travel on different topics (plant -> filter and plant ->
controller -> filter), so the node pairs them by stamp: whichever arrives last triggers the call,
and the pairing does not depend on arrival order (a state is whole when its five messages are there;
at most MAX_PENDING stamps wait, older ones are dropped and counted). torque_cmd is published before filter_status
(the plant waits on it). With fallback `raise` a failed QP stops the node with one error line.

Bad, late or missing input (counted in filter_status, topics.INPUT_COUNTERS; each kind logged once
per episode, faults.FaultLog):

- a state message or torque_des whose stamp is invalid is dropped (counted per message); a state or
  torque_des whose stamp is a duplicate or older than the newest of its stream is dropped (a state's
  messages counted once); a state older than the /clock time by more than `max_state_age_s`
  (use_sim_time) is stale and dropped. The plant then misses that command and applies its own
  deadline fallback;
- a state whose values are unusable (a value not finite, a frame other than hill / body as its topic
  says, wheel joints other than the configured wheels (`Spacecraft.wheel_names`), quaternion norm off by more than
  `quaternion_tolerance`) is filtered as an invalid state: the core answers with its counted
  `invalid_state` fallback, u = 0. A quaternion off by less is renormalised (and counted);
- a torque_des that is not finite or not in the body frame is filtered as non-finite u_des (the
  core's counted `non_finite_u_des` fallback: u_des taken as 0);
- no torque_des for a state within `desired_timeout_s` (wall), or at once when the controller's
  publisher is gone: the state is filtered with u_des = 0 (`torque_des_missing`, `u_des_source`
  = missing in filter_status), so the spacecraft stays safe with the controller dead. The timeout
  is armed by the first torque_des the node receives, so a slow start never triggers it, and in a
  fault-free lockstep run it never fires (the run stays deterministic);
- every output is checked once more: a u that is not finite or outside U is replaced by 0
  (`output_guard`; the core already guarantees it, so this never happens).

A desired command the node does not use as sent (wrong frame, not finite, invalid stamp, or stale: a
repeated, older or late stamp; `topics.REJECTED_COMMANDS`) must not pass unseen, since the run then flies
u_des = 0 while a plain verdict says SAFE: each is counted in filter_status and the reason of the latest
(`frame 'base_link'`, `not finite`, ...) is its `torque_des_rejected_reason`; on /diagnostics the
filter's status carries the non-zero counters and the reason, and is at least WARN, naming the trouble,
while an episode of rejected (or missing) torque_des lasts. `rta-attitude analyze` reports both.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np

from rta_attitude import topics
from rta_attitude.dynamics.sensors import sensors_record, state_from_fields
from rta_attitude.dynamics.spacecraft import torque_to_wheels, wheels_to_torque
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.errors import MessageError
from rta_attitude.filter import outcome
from rta_attitude.filter.asif import AsifFilter, FilterResult
from rta_attitude.ros import convert, interface, spin
from rta_attitude.ros.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher, filter_level
from rta_attitude.ros.faults import StampOrder
from rta_attitude.ros.spin import RtaNode

MAX_PENDING = 64
"""Unpaired messages kept per topic; older ones are dropped (and counted)."""
EXPIRY_POLL_S = 0.05
"""Longest period of the timer that looks for states without torque_des [s]."""
U_RTOL = 1e-12
"""Relative slack of the output guard's |u| <= u_max check (rounding of the box edge)."""
SOURCE_DESIRED, SOURCE_MISSING = "torque_des", "missing"
_STATE_KINDS = ("state_rejected", "state_renormalised", "state_stale", "state_duplicate", "state_out_of_order")
_DESIRED_KINDS = ("torque_des_rejected", "torque_des_duplicate", "torque_des_out_of_order", "torque_des_late",
                  "torque_des_missing")


class FilterNode(RtaNode):
    """The ASIF safety filter; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(topics.FILTER, **kwargs)
        self.counts.update({k: 0 for k in topics.INPUT_COUNTERS})
        t0 = time.perf_counter()
        with spin.interruptible():
            self.filter = AsifFilter(self.cfg)  # compiles (or loads) numba's kernels before we subscribe
        self.get_logger().info(f"filter ready in {time.perf_counter() - t0:.2f} s")
        self._say_wheels()
        self.slacked = tuple(n for n, s in zip(self.filter.names, self.filter.slacked) if s)
        self.status_builder = convert.FilterStatusBuilder(self.filter.names, self.cfg.spacecraft.control_lost)
        self.diagnostics = DiagnosticsPublisher(self, "filter")
        self.interface = sensors_record(self.cfg)  # what decode needs: the bus voltage, the wheels' sign
        self.inputs: dict[int, dict[str, Any]] = {}  # stamp -> the STATE_INPUTS messages of it received so far
        self.refused: deque[int] = deque(maxlen=len(topics.STATE_INPUTS))
        """Stamps lately dropped as duplicate or out of order: their other messages are dropped uncounted."""
        self.states: dict[int, tuple[np.ndarray, float]] = {}  # stamp -> (state, wall time of arrival)
        self.desired: dict[int, np.ndarray] = {}
        self.state_order, self.desired_order = StampOrder(), StampOrder()
        self.answered_ns = -1
        """Newest stamp answered with a torque_cmd."""
        self.heard_controller = False
        """A torque_des arrived: from now on a missing one is a fault (desired_timeout_s)."""
        self.rejection = ""
        """Why the latest rejected torque_des was rejected (topics.REJECTION_KEY; '' while none was)."""
        self.out: dict[str, Any] = {}
        for spec in topics.published(topics.FILTER, self.rta):
            pub = self.create_publisher(interface.msg_class(spec.type_name), spec.name, self.qos(spec.name))
            self.out[spec.name] = self.gate(spec.name, pub)
        self.subs: dict[str, Any] = {}
        for spec in topics.subscribed(topics.FILTER, self.rta):
            if spec.name == topics.TORQUE_DES:
                self.subs[spec.name] = self.subscribe(spec.name, self._on_desired, raw=True)
            else:
                peer = topics.PLANT if spec.name == topics.ODOMETRY else ""
                self.subs[spec.name] = self.subscribe(spec.name, partial(self._on_input, spec.name), peer=peer,
                                                      raw=True)
        if self.rta:
            self.wall_timer(min(EXPIRY_POLL_S, self.knobs["desired_timeout_s"] / 4), self._expire)
            self.get_logger().info(f"filter preset {self.cfg.filter.preset}, fallback {self.cfg.filter.fallback}, "
                                   f"slacked: {', '.join(self.slacked) or 'none'}")
        else:
            self.get_logger().info("rta off: passing torque_des through to torque_cmd")

    # ------------------------------------------------------------------ inputs
    def _on_input(self, topic: str, msg: Any) -> None:
        """One of the state's messages (`topics.STATE_INPUTS`): kept by stamp until all of them are there."""
        if self.stopping:
            return
        t_ns = self.message_stamp(msg, "state_rejected")
        if t_ns is None:
            return
        if self.state_order.check(t_ns):  # a duplicate or an old state: dropped, counted once per stamp
            if t_ns not in self.refused:
                self.refused.append(t_ns)
                self.admit_state_stamp(t_ns, self.state_order)
            return
        parts = self.inputs.setdefault(t_ns, {})
        parts[topic] = msg
        if len(parts) == len(topics.STATE_INPUTS):
            self._on_state(t_ns, self.inputs.pop(t_ns))
        while len(self.inputs) > MAX_PENDING:
            del self.inputs[min(self.inputs)]
            self.counts["unpaired_dropped"] += 1

    def _on_state(self, t_ns: int, msgs: dict[str, Any]) -> None:
        """A whole state (its STATE_INPUTS messages of stamp t_k), rebuilt as `simulate` hands it to its filter."""
        if not self.admit_state_stamp(t_ns, self.state_order):
            return
        try:
            fields = convert.state_fields(msgs, self.cfg.spacecraft.wheel_names)
            x = self.unit_state(state_from_fields(fields, self.interface), t_ns)
        except MessageError as exc:
            self.faults.fault("state_rejected", f"{exc}; answered as an invalid state (u = 0)")
            x = np.full(STATE_SIZE, np.nan)  # the core's invalid-state fallback answers it
        else:
            self.faults.clear("state_rejected")
        self.states[t_ns] = (x, self.wall_now_s())
        if t_ns in self.desired:
            self._filter(t_ns, self.states.pop(t_ns)[0], self.desired.pop(t_ns), SOURCE_DESIRED)
        elif self._controller_gone():
            self._expire()
        self._trim()

    def _on_desired(self, msg: Any) -> None:
        if self.stopping:
            return
        t_ns = self.message_stamp(msg, "torque_des_rejected")
        if t_ns is None:
            self._rejected("invalid stamp")
            return
        order = self.desired_order.check(t_ns)
        if not order and t_ns <= self.answered_ns:
            order = "late"  # its state was answered without it (timeout) or is long gone
        if order:
            self.faults.fault(f"torque_des_{order}", f"stamp t = {self.sim_s(t_ns):g} s, newest taken "
                              f"{self.sim_s(self.desired_order.newest_ns or self.epoch_ns):g} s, answered "
                              f"{self.sim_s(max(self.answered_ns, self.epoch_ns)):g} s; dropped")
            self._rejected(f"stale ({order.replace('_', ' ')})")
            return
        self.desired_order.take(t_ns)
        self.heard_controller = True
        self.faults.clear("torque_des_duplicate", "torque_des_out_of_order", "torque_des_late", "torque_des_missing")
        try:
            _, tau = convert.torque_from_msg(msg)
        except MessageError as exc:
            self._rejected(f"frame {exc.frame_id!r}" if isinstance(exc, convert.FrameError) else "not finite")
            if not self.rta:
                self.faults.fault("torque_des_rejected", f"{exc}; not passed through")
                self._diagnose_pass_through(t_ns)
                return
            self.faults.fault("torque_des_rejected", f"{exc}; filtered as a non-finite u_des")
            tau = np.full(3, np.nan)  # the core's non-finite-u_des fallback answers it
        else:
            self.faults.clear("torque_des_rejected")
        if not self.rta:
            self.answered_ns = max(self.answered_ns, t_ns)
            self.out[topics.TORQUE_CMD].publish(convert.torque_cdr(tau, t_ns))
            self._diagnose_pass_through(t_ns)
            return
        self.desired[t_ns] = tau
        if t_ns in self.states:
            self._filter(t_ns, self.states.pop(t_ns)[0], self.desired.pop(t_ns), SOURCE_DESIRED)
        self._trim()

    def _rejected(self, why: str) -> None:
        """Note why a torque_des was rejected (filter_status and /diagnostics carry the latest reason)."""
        self.rejection = why

    def _input_values(self) -> dict[str, Any]:
        """The non-zero input counters and the latest rejection's reason, for /diagnostics."""
        values: dict[str, Any] = {k: self.counts[k] for k in topics.INPUT_COUNTERS if self.counts.get(k)}
        if self.rejection:
            values[topics.REJECTION_KEY] = self.rejection
        return values

    def _desired_trouble(self) -> str:
        """What is wrong with torque_des now (an active fault episode), for the /diagnostics message; ''."""
        if any(k in self.faults.active for k in topics.REJECTED_COMMANDS):
            return f"torque_des rejected ({self.rejection})"
        if "torque_des_missing" in self.faults.active:
            return "torque_des missing (u_des = 0)"
        return ""

    def _diagnose_pass_through(self, t_ns: int) -> None:
        """rta off: OK while torque_des passes through, WARN while it is rejected (not passed through)."""
        trouble = self._desired_trouble()
        level, text = (WARN, f"{trouble}: not passed through") if trouble else (OK, "passing torque_des through")
        self.diagnostics.update(level, text, {"t_s": self.sim_s(t_ns), **self._input_values()}, t_ns)

    def _controller_gone(self) -> bool:
        """The controller was heard and its torque_des publisher has left (no match any more)."""
        sub = self.subs.get(topics.TORQUE_DES)
        return self.heard_controller and sub is not None and sub.get_publisher_count() == 0

    def on_peer_lost(self, peer: str) -> None:
        if peer == topics.PLANT:  # no command for a dead plant: what waits for torque_des is dropped
            self.counts["unpaired_dropped"] += len(self.states) + len(self.inputs)
            self.states.clear()
            self.inputs.clear()
            self.desired.clear()

    def on_live_parameters(self, changes: dict[str, Any]) -> None:
        """A failed wheel set while running (`ros2 param set <ns>/asif_filter spacecraft.failed_wheels wheel_x`):
        the filter leaves it out from the next state on and says so."""
        self.filter.fail_wheels(self.cfg)
        self.status_builder.wheels = self.cfg.spacecraft.control_lost
        self._say_wheels(changed=True)

    def _say_wheels(self, changed: bool = False) -> None:
        """One log line: what the failed wheels take away (an ERROR), or, after a change, that all work."""
        if self.cfg.spacecraft.control_lost:
            self.get_logger().error(f"{self.cfg.spacecraft.control_lost}: the filter holds what the others can")
        elif changed:
            self.get_logger().info("every wheel working")

    def on_clock_jump(self) -> None:
        """A replay started over: every stamp is new again; what waited for a partner is of the old pass."""
        self.state_order.reset()
        self.desired_order.reset()
        self.counts["unpaired_dropped"] += len(self.states) + len(self.desired) + len(self.inputs)
        self.states.clear()
        self.inputs.clear()
        self.desired.clear()
        self.answered_ns = -1

    def _expire(self) -> None:
        """States without torque_des past desired_timeout_s (or with the controller gone): u_des = 0."""
        if not self.states or not self.heard_controller or self.stopping:
            return
        gone = self._controller_gone()
        now = self.wall_now_s()
        timeout = self.knobs["desired_timeout_s"]
        for t_ns, (x, since) in sorted(self.states.items()):
            if not gone and now - since <= timeout:
                continue
            del self.states[t_ns]
            if t_ns < self.answered_ns:  # a newer state was answered already: this one is of no use
                self.counts["unpaired_dropped"] += 1
                continue
            why = "the controller's publisher is gone" if gone else f"none within {timeout:g} s"
            self.faults.fault("torque_des_missing", f"no torque_des for t = {self.sim_s(t_ns):g} s ({why}); "
                              "filtering u_des = 0")
            self._filter(t_ns, x, np.zeros(3), SOURCE_MISSING)

    def _trim(self) -> None:
        for pending in (self.states, self.desired):
            while len(pending) > MAX_PENDING:
                del pending[min(pending)]
                self.counts["unpaired_dropped"] += 1

    # ------------------------------------------------------------------ the call
    def _filter(self, t_ns: int, x: np.ndarray, tau_des: np.ndarray, source: str) -> None:
        p = self.filter.record["plant"]  # the torque interface: u_des = A^-1 tau_des / D, tau_cmd = D A u
        res = self.filter.filter(x, torque_to_wheels(tau_des, p), self.sim_s(t_ns))  # t from the state's stamp
        res = self._guard(res)
        self.answered_ns = max(self.answered_ns, t_ns)
        self.out[topics.TORQUE_CMD].publish(convert.torque_cdr(wheels_to_torque(res.u, p), t_ns))
        self.out[topics.FILTER_STATUS].publish(self.status_builder.build_cdr(
            res, t_ns, self.filter.counters, self.cfg.filter.preset, self.slacked, self.counts, source,
            self.rejection))
        level, text = filter_level(str(res.status), str(res.fallback), bool((res.record["slack"] > 0.0).any()))
        trouble = self._desired_trouble()
        if trouble:  # the command filtered is not the controller's: say so, at least as a warning
            level, text = max(level, WARN), f"{text}; {trouble}"
        if self.cfg.spacecraft.control_lost:  # a failed wheel: one ERROR line, the filter holds what it can
            level, text = ERROR, f"{self.cfg.spacecraft.control_lost}; {text}"
        c = self.filter.counters
        self.diagnostics.update(level, text, {"preset": self.cfg.filter.preset, "calls": c.calls, "solved": c.solved,
                                              "fallbacks": c.fallbacks, "t_s": self.sim_s(t_ns),
                                              **self._input_values()}, t_ns)
        if res.fallback and res.fallback not in ("non_finite_u_des", "invalid_state"):
            self.faults.fault("qp_fallback", f"t = {self.sim_s(t_ns):g} s: QP {res.solver_status}, "
                              f"fallback {res.fallback}")
        else:
            self.faults.clear("qp_fallback")

    def _guard(self, res: FilterResult) -> FilterResult:
        """The last check before a command leaves the node: finite and inside U, else u = 0 (counted)."""
        u = res.u
        if u.shape == (3,) and np.all(np.isfinite(u)) and np.all(np.abs(u) <= self.filter.u_max * (1 + U_RTOL)):
            return res
        self.faults.fault("output_guard", f"filter output {u!r} is not a finite command inside U; sending u = 0")
        record = res.record.copy()
        record["u"] = record["u_held"] = 0.0
        record["status"], record["fallback"] = outcome.FALLBACK, outcome.OUTPUT_GUARD
        return FilterResult(record, res.policy, res.levels, res.names)

    def close(self) -> None:
        super().close()
        if self.rta:
            c = self.filter.counters
            self.get_logger().info(f"filter calls {c.calls}: fast path {c.fast_path}, solved {c.solved}, "
                                   f"fallbacks {c.fallbacks} (invalid states {c.invalid_states})")


def main(args: Sequence[str] | None = None) -> None:
    """Console script `asif_filter_node` (`ros2 run rta_attitude asif_filter_node --ros-args ...`)."""
    spin.main(FilterNode, args, topics.NODE_NAMES[topics.FILTER])


if __name__ == "__main__":
    main()
