"""plant_node: the spacecraft simulator. Publishes /clock, the state as the flight software receives it
(`topics.STATE_INPUTS`: odometry, joint_states, temperature, battery, sun_vector; their fields from
`dynamics.sensors.encode`) and the packed `state` the recorder and the scene read,
takes body torques and integrates the core model (`dynamics.spacecraft.integrate`) one sample at a time,
or Basilisk with `plant.simulator:=basilisk` (`dynamics.plant.make_plant`; the same step interface).

Stepping (`stepping` parameter):

- lockstep (default): publish state(t_k), wait for the command stamped t_k, integrate to t_k+1,
  repeat; a run over DDS equals `ClosedLoop.run()` of the same scenario. After the final state
  the plant also waits for the chain's answer to it, so every message count of the run is known
  and goes into the final `run_status`. No command within `command_timeout_s` (wall) is a deadline
  miss: the plant applies `deadline_fallback` for that step and goes on (a dead filter never stalls
  the loop; the first command of the run may take `startup_timeout_s`, up to four times that while a
  writer of the command topic is alive, and if none comes the run fails). In a run without faults
  the timeout never fires, so lockstep stays deterministic.
- realtime: a steady wall-clock timer with period dt / real_time_factor. At tick k+1 the plant
  applies the command stamped t_k if it has arrived (zero-order hold over [t_k, t_k+1)), else it
  counts a deadline miss and applies `deadline_fallback`. The loop never waits.

`deadline_fallback`: `hold` repeats the last applied torque for up to `hold_max_steps` consecutive
misses, then applies zero; `zero` applies zero at once.

Commands are validated (topics.PLANT_COUNTERS, in run_status; each kind logged once per episode):
not finite or wrong frame: rejected; stamp older than the current step: late, equal to the last
applied: duplicate, newer: future; all dropped. A command outside the admissible set U is counted
(`outside_u`; the plant is the spacecraft and applies it: without RTA the paper's PD law does exceed
U); one beyond the actuator limit is applied saturated, as `dynamics.spacecraft.integrate` does (`saturated`).
When a fault episode starts or ends the plant republishes run_status (`running`, with the counters).

Start: the first state is published only after every writer of the plant matched the run's
readers (topics.expected_readers). With `external_controller` (no pd_controller_node: `rta-attitude
launch --controller none`) the controller is whichever node publishes torque_des on the run's
namespace: the run starts once such a node also reads the state (any of the plant's topics), and its
readers are waited for like the run's own. A reader (or a node of the chain, for the first command)
that is alive and still starting extends every start-up wait (`RtaNode.peers_starting`). End:
run_status `done` (or `failed: reason`, or `interrupted: SIGINT` on a signal), wait until all readers
acknowledged, exit when `exit_when_done` (always after a signal).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from rta_attitude import topics
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.plant import make_plant
from rta_attitude.dynamics.sensors import Instruments, message_fields
from rta_attitude.dynamics.state import ENERGY
from rta_attitude.errors import MessageError
from rta_attitude.kernel_cache import drop_stale_caches
from rta_attitude.ros import convert, interface, spin
from rta_attitude.ros.diagnostics import DiagnosticsPublisher, run_level
from rta_attitude.ros.spin import RtaNode

STARTUP_POLL_S = 0.005
WATCHDOG_PERIOD_S = 0.1
"""Longest period of the lockstep command watchdog (shorter for a short command_timeout_s) [s]."""
FIRST_COMMAND_EXTENSIONS = 3
"""The first command may take startup_timeout_s, and that again this many times while a writer of the
command topic is alive and matched (the chain discovers itself: on a loaded machine the first answer
crosses three hops of endpoint discovery); a chain that hangs still ends the run, bounded."""
LIMIT_RTOL = 1e-9
"""A command counts as beyond a limit when |u_i| > limit (1 + LIMIT_RTOL) (tau = D u and back rounds)."""
FINAL_STATUS_ACK_S = 10.0
"""Longest wait for the readers' acknowledgement of the final run_status before exiting [s] (at least
stop_timeout_s; the wait ends as soon as every reader acknowledged)."""
NOT_STATE = (topics.RUN_STATUS, topics.CLOCK)
"""The plant's topics that do not carry the state: a controller node that reads only these cannot answer yet."""
QUIET_KINDS = ("outside_u", "saturated")
"""Counted and logged once per episode, but do not republish run_status: without RTA they happen in
fault-free runs (the paper's PD law exceeds U), and saturation is the actuator's normal behaviour."""


class PlantNode(RtaNode):
    """The simulated spacecraft; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(topics.PLANT, **kwargs)
        self.counts.update({k: 0 for k in topics.PLANT_COUNTERS})
        self.dt_s = self.cfg.filter.sample_time_s
        self.steps = round(self.scenario.duration_s / self.dt_s)
        self.lockstep = self.knobs["stepping"] == "lockstep"
        self.u_admissible = self.cfg.u_max_rad_s2  # U (3,): the box the filter keeps u in
        self.u_actuator = self.cfg.limits.wheel_accel_max_rad_s2  # where the wheels saturate
        self.x = self.scenario.x0.copy()
        self.k = 0
        # compile (or load from numba's cache) the integrator before the first step needs it
        self.plant = spacecraft.plant_record(self.cfg)
        self.D = self.cfg.spacecraft.wheel_inertia_kgm2
        t0 = self.wall_now_s()
        drop_stale_caches()
        with spin.interruptible():
            spacecraft.integrate(self.x, np.zeros(3), self.dt_s, self.plant, self.cfg.substeps)  # compile it now
            spacecraft.saturated(np.zeros(3), self.plant)  # and the actuator's clip
        self.simulator = make_plant(self.cfg, self.x, self.dt_s)
        self.instruments = Instruments(self.cfg)  # measured state, actuated command (exact when sensors: off)
        self.get_logger().info(f"plant integrator ({self.cfg.plant.simulator}) ready in "
                               f"{self.wall_now_s() - t0:.2f} s")
        self.held_tau = np.zeros(3)
        self.wheel_effort_Nm = np.zeros(3)
        """The motor torque on each rotor over the last hold (-s D u, saturated): joint_states' effort."""
        self.misses_in_a_row = 0
        self.last_command_ns = -1
        self.pending: tuple[int, np.ndarray] | None = None
        self.latency_s: list[float] = []
        self.published: dict[str, int] = {}
        self.pubs = {spec.name: self.create_publisher(interface.msg_class(spec.type_name), spec.name,
                                                      self.qos(spec.name))
                     for spec in topics.published(topics.PLANT, True, self.truth)}  # fmt: skip
        self.diagnostics = DiagnosticsPublisher(self, "run")
        self.command_topic = topics.TORQUE_CMD
        self._command_sub = self.subscribe(self.command_topic, self._on_command, raw=True)
        self._sent_s = 0.0
        self._progress_s = self.wall_now_s()
        self._ended = False
        self._running = False
        self._started_s = 0.0
        self.startup_extensions = 0
        """How often startup_timeout_s ran out while a peer was alive but still starting (then: wait on)."""
        self._chain = (topics.FILTER,) if self.knobs["external_controller"] else (topics.FILTER, topics.CONTROLLER)
        """The roles whose answers make the command of a step (the first command waits while one is starting)."""
        self.first_command_extensions = 0
        """How often startup_timeout_s ran out without a first command while its writer was alive."""
        self._startup = self.wall_timer(STARTUP_POLL_S, self._check_ready)
        self.get_logger().info(f"scenario {self.scenario.name}: {self.steps} steps of {self.dt_s:g} s, "
                               f"{self.knobs['stepping']}, rta={'on' if self.rta else 'off'}; waiting for readers"
                               + (" and a controller node (one that publishes "
                                  f"{self.resolve_topic_name(topics.TORQUE_DES)} and reads the state)"
                                  if self.knobs["external_controller"] else ""))

    # ------------------------------------------------------------------ start
    def _readers_starting(self) -> list[str]:
        """The run's reader nodes, not subscribed yet to a topic they read, that are alive and still
        starting (`RtaNode.peers_starting`: in the graph, without endpoints on the run's topics; a first
        start compiles the filter's kernels for tens of seconds). Empty if none is (a reader not in the
        graph at all counts against startup_timeout_s)."""
        pending: set[str] = set()
        for n, pub in self.pubs.items():
            pending.update(self.missing_readers(n, pub))
        return self.peers_starting(pending)

    def _controller_readers(self) -> dict[str, int]:
        """external_controller: how many readers of each of our topics the controller adds, i.e. the nodes
        that publish torque_des on our namespace and subscribe to that topic ({} while no node that
        publishes torque_des reads the state)."""
        writers = {(i.node_name, i.node_namespace) for i in self.get_publishers_info_by_topic(
            self.resolve_topic_name(topics.TORQUE_DES))}
        if not writers:
            return {}
        extra = {n: sum((i.node_name, i.node_namespace) in writers
                        for i in self.get_subscriptions_info_by_topic(pub.topic_name)) for n, pub in self.pubs.items()}
        # it reads the state once it reads a topic that carries it: run_status and /clock do not (a controller
        # that watches run_status from its start, as the template does, is not ready to answer yet)
        return extra if any(v for n, v in extra.items() if n not in NOT_STATE) else {}

    def _missing(self) -> list[tuple[str, int, int]]:
        """(topic, readers matched, readers expected) of our topics still short of readers; with
        external_controller, once the run's own are there, also the controller's, or a line for torque_des
        while no controller node is there (the graph is asked only then: this runs every STARTUP_POLL_S)."""
        external = self.knobs["external_controller"]

        def short(extra: dict[str, int]) -> list[tuple[str, int, int]]:
            return [(self.pubs[n].topic_name, self.pubs[n].get_subscription_count(), want)
                    for n in self.pubs
                    if (want := topics.expected_readers(n, self.rta, self.record, self.truth, self.scene,
                                                        external) + extra.get(n, 0))
                    and self.pubs[n].get_subscription_count() < want]  # fmt: skip

        missing = short({})
        if missing or not external:
            return missing
        extra = self._controller_readers()
        return short(extra) if extra else [(self.resolve_topic_name(topics.TORQUE_DES), 0, 1)]

    def _check_ready(self) -> None:
        missing = self._missing()
        if missing:
            if self.wall_now_s() - self._progress_s > self.knobs["startup_timeout_s"]:
                starting = self._readers_starting()
                if starting:  # alive in the graph, not subscribed yet (compiling kernels): wait as long as it takes
                    self.get_logger().info(f"waiting for {', '.join(starting)} to finish starting (alive, no "
                                           f"endpoints after {self.knobs['startup_timeout_s']:g} s)")
                    self._progress_s = self.wall_now_s()
                    self.startup_extensions += 1
                    return
                self.destroy_timer(self._startup)
                torque_des = self.resolve_topic_name(topics.TORQUE_DES)
                if self.knobs["external_controller"] and not self._controller_readers():
                    # no controller in the graph is the cause to name, whichever of the run's readers is also late
                    missing = [(torque_des, 0, 1)]
                name, have, want = missing[0]
                if name == torque_des:
                    self._end(topics.RUN_FAILED + f": no node publishes {name} and reads the state after "
                              f"{self.knobs['startup_timeout_s']:g} s (external_controller: start your "
                              "controller node on this namespace)")
                else:
                    self._end(topics.RUN_FAILED + f": {name} has {have} of {want} readers after "
                              f"{self.knobs['startup_timeout_s']:g} s")
            return
        self.destroy_timer(self._startup)
        self._started_s = self.wall_now_s()
        self._publish(topics.RUN_STATUS, convert.run_status_msg(self._t_ns(0), topics.RUN_RUNNING,
                                                                self._status_values()))
        self.get_logger().info("readers matched; running")
        self._running = True
        self._publish_sample()
        if self.lockstep:
            period = min(WATCHDOG_PERIOD_S, self.knobs["command_timeout_s"] / 4)
            self._watchdog = self.wall_timer(period, self._check_stall)
        else:
            self._ticker = self.wall_timer(self.dt_s / self.knobs["real_time_factor"], self._tick)

    # ------------------------------------------------------------------ stepping
    def _t_ns(self, k: int) -> int:
        return self.epoch_ns + convert.seconds_to_ns(k * self.dt_s)

    def _publish(self, topic: str, msg: Any) -> None:
        self.pubs[topic].publish(msg)
        self.published[topic] = self.published.get(topic, 0) + 1

    def _publish_sample(self) -> None:
        """/clock(t_k) first (a reader's sim time reaches t_k before the state stamped t_k arrives, so
        `ros2 topic delay --use-sim-time` reads >= 0), then state(t_k) as measured, the true state (sensor
        errors on) and the inspection views (measured)."""
        t_ns = self._t_ns(self.k)
        x = self.instruments.measure(self.x, self.k) if self.truth else self.x
        fields = message_fields(x, self.instruments.record)
        V = self.cfg.power.bus_voltage_V
        current_A = float(spacecraft.state_derivative(x, np.zeros(3), self.plant)[ENERGY]) / V
        inputs = convert.state_messages_cdr(fields, t_ns, V, current_A, self.wheel_effort_Nm,
                                           self.cfg.spacecraft.wheel_names)
        self._publish(topics.CLOCK, convert.clock_cdr(t_ns))
        self._sent_s = self.wall_now_s()
        self._progress_s = self._sent_s
        for name in topics.STATE_INPUTS:
            self._publish(name, inputs[name])
        self._publish(topics.STATE, convert.state_cdr(x, t_ns))
        if self.truth:
            self._publish(topics.STATE_TRUE, convert.state_cdr(self.x, t_ns))
        self._diagnose(topics.RUN_RUNNING)  # after the state: the chain works on it meanwhile

    def on_live_parameters(self, changes: dict[str, Any]) -> None:
        """A wheel fails (or is repaired) while running, `ros2 param set <ns>/plant spacecraft.failed_wheels
        wheel_x`: from the next step its drive gives no torque (the fault injection; the filter is told the same
        way)."""
        for record in (self.plant, self.simulator.record):
            record[0]["wheel_failed"] = self.cfg.spacecraft.wheel_failed
        self.get_logger().warning(f"wheels failed: {', '.join(self.cfg.spacecraft.failed_wheels) or 'none'}")

    def _step(self, tau_Nm: np.ndarray) -> None:
        """Hold tau over [t_k, t_k+1) through the actuator (the core saturates and integrates), publish the
        new sample; torque_applied is what the wheels held (before saturation)."""
        self.held_tau = tau_Nm
        u = spacecraft.torque_to_wheels(tau_Nm, self.plant)
        if self.truth:
            u = self.instruments.actuate(u, self.k)
            tau_Nm = spacecraft.wheels_to_torque(u, self.plant)
        u_held = spacecraft.saturated(u, self.plant)
        self.wheel_effort_Nm = -self.cfg.spacecraft.torque_sign * spacecraft.wheel_accel_to_torque(u_held, self.D)
        x_next, _ = self.simulator.step(u)
        t_ns = self._t_ns(self.k)
        self.k += 1
        self.x = x_next
        self._publish_sample()
        self._publish(topics.TORQUE_APPLIED, convert.torque_cdr(tau_Nm, t_ns))

    def _on_command(self, msg: Any) -> None:
        if self._ended or not self._running:
            return
        if self.counts["commands"] == 0:  # the chain's first sign of life: its command timeout starts now
            self._progress_s = self.wall_now_s()
        self.counts["commands"] += 1
        try:
            t_ns, tau = convert.torque_from_msg(msg)
        except MessageError as exc:
            self.faults.fault("rejected", f"{self.command_topic}: {exc}; dropped")
            return
        self.faults.clear("rejected")
        expected = self._t_ns(self.k)
        if t_ns != expected or (self.pending is not None and self.pending[0] == t_ns):
            if t_ns == self.last_command_ns or t_ns == expected:  # (== expected here: already pending)
                kind = "duplicate"
            else:
                kind = "late" if t_ns < expected else "future"
            self.faults.fault(kind, f"{self.command_topic} stamped t = {self.sim_s(t_ns):g} s at step "
                              f"t = {self.sim_s(expected):g} s; dropped")
            return
        self.faults.clear("duplicate", "late", "future")
        u = np.abs(spacecraft.torque_to_wheels(tau, self.plant))
        for kind, limit, what in (("outside_u", self.u_admissible, "is outside U; applied"),
                                  ("saturated", self.u_actuator, "is beyond the actuator limit; saturated")):
            if np.any(u > limit * (1 + LIMIT_RTOL)):
                self.faults.fault(kind, f"{self.command_topic} at t = {self.sim_s(t_ns):g} s (|u| = "
                                  f"{np.round(u, 3).tolist()} rad/s^2) {what}")
            else:
                self.faults.clear(kind)
        if not self.lockstep:
            self.pending = (t_ns, tau)
            return
        self.last_command_ns = t_ns
        self.latency_s.append(self.wall_now_s() - self._sent_s)
        self._in_time()
        if self.k == self.steps:  # the chain's answer to the final state: counts are now known
            self._end(topics.RUN_DONE)
        else:
            self._step(tau)

    def _in_time(self) -> None:
        self.misses_in_a_row = 0
        self.faults.clear("deadline_misses")

    def _fallback(self, why: str) -> np.ndarray:
        """A deadline miss: count it and return the torque `deadline_fallback` applies."""
        self.misses_in_a_row += 1
        hold = self.knobs["deadline_fallback"] == "hold" and self.misses_in_a_row <= self.knobs["hold_max_steps"]
        self.counts["fallback_hold" if hold else "fallback_zero"] += 1
        self.faults.fault("deadline_misses", f"no {self.command_topic} for t = {self.k * self.dt_s:g} s {why}; "
                          f"applying {'the last torque' if hold else 'zero torque'} "
                          f"({self.knobs['deadline_fallback']} fallback)")
        return self.held_tau if hold else np.zeros(3)

    def _tick(self) -> None:
        if self._ended:
            return
        expected = self._t_ns(self.k)
        if self.pending is not None and self.pending[0] == expected:
            tau = self.pending[1]
            self.last_command_ns = expected
            self.latency_s.append(0.0)
            self._in_time()
        else:
            tau = self._fallback("by the next tick")
        self.pending = None
        self._step(tau)
        if self.k == self.steps:
            self.destroy_timer(self._ticker)
            self._end(topics.RUN_DONE)

    def _command_writers(self) -> list[str]:
        """The nodes that write the command topic, alive in the ROS graph and matched with our reader."""
        if self._command_sub.get_publisher_count() == 0:
            return []
        return sorted({info.node_name for info in self.get_publishers_info_by_topic(
            self._command_sub.topic_name)})

    def _check_stall(self) -> None:
        if self._ended:
            return
        waited = self.wall_now_s() - self._progress_s
        if self.counts["commands"] == 0:  # the chain has not answered yet: it may still be discovering
            if waited > self.knobs["startup_timeout_s"]:
                starting = self.peers_starting(self._chain)
                if starting:  # a node of the chain is alive and still starting (compiling): wait as long as it takes
                    self.startup_extensions += 1
                    self.get_logger().info(f"no {self.command_topic} yet after {waited:.0f} s; waiting for "
                                           f"{', '.join(starting)} to finish starting (alive, no endpoints)")
                    self._progress_s = self.wall_now_s()
                    return
                writers = self._command_writers()
                if writers and self.first_command_extensions < FIRST_COMMAND_EXTENSIONS:
                    # a writer of the command topic is alive and matched: the chain is still discovering
                    # itself (each of its nodes bounds that by its own startup_timeout_s); wait on, bounded
                    self.first_command_extensions += 1
                    self.get_logger().info(f"no {self.command_topic} yet after {waited:.0f} s; its writer "
                                           f"{', '.join(writers)} is alive: waiting on "
                                           f"({self.first_command_extensions} of {FIRST_COMMAND_EXTENSIONS})")
                    self._progress_s = self.wall_now_s()
                    return
                total = self.knobs["startup_timeout_s"] * (1 + self.first_command_extensions)
                self._end(topics.RUN_FAILED + f": no {self.command_topic} for t = {self.k * self.dt_s:g} s "
                          f"within {total:g} s (startup_timeout_s x {1 + self.first_command_extensions}, "
                          + ("its writer alive)" if writers else "no writer alive)"))
            return
        timeout = self.knobs["command_timeout_s"]
        if waited <= timeout:
            return
        tau = self._fallback(f"within {timeout:g} s")
        if self.k == self.steps:  # no answer to the final state: nothing left to apply
            self._end(topics.RUN_DONE)
        else:
            self._step(tau)

    def on_fault_change(self, kind: str, active: bool) -> None:
        if self._running and not self._ended and kind not in QUIET_KINDS:
            self._publish(topics.RUN_STATUS, convert.run_status_msg(self._t_ns(self.k), topics.RUN_RUNNING,
                                                                    self._status_values()))

    def on_stop(self) -> None:
        """SIGINT/SIGTERM: end the run as `interrupted` (final run_status with this node's counts), then exit."""
        if self._ended:  # the run had ended already (exit_when_done false, or a stop while flushing)
            self.finish()
            return
        self._end(f"{topics.RUN_INTERRUPTED}: {self.stopping}")

    # ------------------------------------------------------------------ end
    def _status_values(self) -> dict[str, Any]:
        values: dict[str, Any] = {
            "scenario": self.scenario.name, "rta": self.rta, "stepping": self.knobs["stepping"],
            "steps": self.steps, "step": self.k, "dt_s": self.dt_s, **self.counts,
        }  # fmt: skip
        if self._started_s:
            values["wall_time_s"] = self.wall_now_s() - self._started_s
        if self.lockstep and self.latency_s:
            lat = np.asarray(self.latency_s)
            values.update(latency_median_s=float(np.median(lat)), latency_p99_s=float(np.percentile(lat, 99)),
                          latency_max_s=float(lat.max()))
        return values

    def close(self) -> None:
        """Release the simulator, then log as every node does."""
        self.simulator.close()
        super().close()

    def _diagnose(self, state: str) -> None:
        """The run's summary on /diagnostics (at ~1 Hz and on every change of level or message)."""
        level, text = run_level(state, len(self.faults.active))
        self.diagnostics.update(level, text, {"step": self.k, "steps": self.steps, **{k: v for k, v in
                                self.counts.items() if v}}, self._t_ns(self.k))

    def _end(self, state: str) -> None:
        """Publish the final run_status with the message counts, wait for acks, finish."""
        if self._ended:
            return
        self._ended = True
        values = self._status_values()
        counts = dict(self.published)
        counts[topics.RUN_STATUS] = counts.get(topics.RUN_STATUS, 0) + 1
        faults = sum(self.counts[k] for k in ("rejected", "late", "duplicate", "future", "deadline_misses"))
        if self.lockstep and state == topics.RUN_DONE and not faults:
            # the filter answers every torque_des with one torque_cmd (and, with RTA, one filter_status);
            # after a fault these counts are not known here, and the recorder waits for quiet instead
            counts[topics.TORQUE_CMD] = counts[topics.TORQUE_DES] = self.counts["commands"]
            if self.rta:
                counts[topics.FILTER_STATUS] = self.counts["commands"]
        for topic, n in counts.items():
            values[topics.EXPECTED_PREFIX + self.resolve_topic_name(topic)] = n
        self._publish(topics.RUN_STATUS, convert.run_status_msg(self._t_ns(self.k), state, values))
        self._diagnose(state)
        interrupted = state.startswith(topics.RUN_INTERRUPTED)
        if self.knobs["exit_when_done"] or interrupted:
            # the final status is what the recorder closes on: under load a lost reliable sample is repaired
            # only at the writer's next heartbeat (`ros.transport`), and a writer that has exited repairs nothing
            # (found by the flake hunt: a bag ended with run_status `running`); it waits only if an ack is owed
            # the other streams only while the recorder is there: it closes the bag once it holds every
            # message, and no other reader needs them after the run (found: with the scene node reading
            # `state`, the acknowledgements of the last states came only with Fast DDS's periodic heartbeat,
            # and every run ended ~2.5 s late)
            self.flush(max(self.knobs["stop_timeout_s"], FINAL_STATUS_ACK_S), needed=self._recorder_present)
        if state.startswith(topics.RUN_FAILED):
            self.fail(f"run failed at step {self.k}: {state[len(topics.RUN_FAILED) + 2:]}")
            return
        self.get_logger().info(f"run {state}: {self.k} steps; counters: {self.faults.summary()}")
        if self.knobs["exit_when_done"] or interrupted:
            self.finish()

    def _recorder_present(self) -> bool:
        """The run's recorder still reads run_status (it leaves once the bag is closed)."""
        recorder = topics.NODE_NAMES[topics.RECORDER]
        return self.record and any(i.node_name == recorder for i in
                                   self.get_subscriptions_info_by_topic(self.pubs[topics.RUN_STATUS].topic_name))

    def published_counts(self) -> dict[str, int]:
        return dict(self.published)

    def own_publishers(self) -> list[Any]:
        return list(self.pubs.values())


def main(args: Sequence[str] | None = None) -> None:
    """Console script `plant_node` (`ros2 run rta_attitude plant_node --ros-args ...`)."""
    spin.main(PlantNode, args, topics.NODE_NAMES[topics.PLANT])


if __name__ == "__main__":
    main()
