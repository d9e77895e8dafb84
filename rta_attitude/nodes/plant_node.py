"""plant_node: the spacecraft simulator. Publishes /clock, `state` and the inspection topics,
takes body torques and integrates the core model (simulation.integrate) one sample at a time.

Stepping (`stepping` parameter):

- lockstep (default): publish state(t_k), wait for the command stamped t_k, integrate to t_k+1,
  repeat; a run over DDS equals `ClosedLoop.run()` of the same scenario. After the final state
  the plant also waits for the chain's answer to it, so every message count of the run is known
  and goes into the final `run_status`. No command within `step_timeout_s` fails the run.
- realtime: a steady wall-clock timer with period dt / real_time_factor. At tick k+1 the plant
  applies the command stamped t_k if it has arrived (zero-order hold over [t_k, t_k+1)), else it
  counts a deadline miss and applies `deadline_fallback` (hold the last applied torque, or zero).
  Commands for an older step are counted as late and dropped. The loop never waits.

Start: the first state is published only after every writer of the plant matched the run's
readers (topics.expected_readers). End: run_status `done` (or `failed: reason`), wait until all
readers acknowledged, exit when `exit_when_done`.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
from rclpy.duration import Duration

from .. import model, simulation
from ..errors import ConfigError, MessageError
from . import convert, topics
from .spin import RtaNode, run

ACK_TIMEOUT_S = 5.0
"""At the end: longest wait for readers to acknowledge the last messages [s]."""
STARTUP_POLL_S = 0.005
WATCHDOG_PERIOD_S = 0.1


class PlantNode(RtaNode):
    """The simulated spacecraft; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(topics.PLANT, **kwargs)
        self.dt_s = self.cfg.filter.sample_time_s
        self.steps = round(self.scenario.duration_s / self.dt_s)
        self.lockstep = self.knobs["stepping"] == "lockstep"
        if not self.lockstep and self.knobs["real_time_factor"] <= 0:
            raise ConfigError(f"real_time_factor must be > 0, got {self.knobs['real_time_factor']!r}")
        self.x = self.scenario.x0.copy()
        self.k = 0
        self.held_tau = np.zeros(3)
        self.pending: tuple[int, np.ndarray] | None = None
        self.counts = {"commands": 0, "rejected": 0, "unexpected": 0, "deadline_misses": 0, "late": 0}
        self.latency_s: list[float] = []
        self.published: dict[str, int] = {}
        self.pubs = {name: self.create_publisher(topics.msg_class(spec.type_name), spec.name,
                                                 topics.qos_profile(spec.qos))
                     for name, spec in topics.TOPICS.items() if spec.publisher == topics.PLANT}  # fmt: skip
        self.command_topic = topics.TORQUE_CMD
        spec = topics.TOPICS[self.command_topic]
        self.create_subscription(topics.msg_class(spec.type_name), spec.name, self._on_command,
                                 topics.qos_profile(spec.qos))
        self._sent_s = 0.0
        self._progress_s = self.wall_now_s()
        self._ended = False
        self._started_s = 0.0
        self._startup = self.wall_timer(STARTUP_POLL_S, self._check_ready)
        self.get_logger().info(f"scenario {self.scenario.name}: {self.steps} steps of {self.dt_s:g} s, "
                               f"{self.knobs['stepping']}, rta={'on' if self.rta else 'off'}; waiting for readers")

    # ------------------------------------------------------------------ start
    def _check_ready(self) -> None:
        missing = [(self.pubs[n].topic_name, self.pubs[n].get_subscription_count(), want)
                   for n in self.pubs if (want := topics.expected_readers(n, self.rta, self.record))
                   and self.pubs[n].get_subscription_count() < want]  # fmt: skip
        if missing:
            if self.wall_now_s() - self._progress_s > self.knobs["startup_timeout_s"]:
                self.destroy_timer(self._startup)
                name, have, want = missing[0]
                self._end(topics.RUN_FAILED + f": {name} has {have} of {want} readers after "
                          f"{self.knobs['startup_timeout_s']:g} s")
            return
        self.destroy_timer(self._startup)
        self._started_s = self.wall_now_s()
        self._publish(topics.RUN_STATUS, convert.run_status_msg(0, topics.RUN_RUNNING, self._status_values()))
        self.get_logger().info("readers matched; running")
        self._publish_sample()
        if self.lockstep:
            self._watchdog = self.wall_timer(WATCHDOG_PERIOD_S, self._check_stall)
        else:
            self._ticker = self.wall_timer(self.dt_s / self.knobs["real_time_factor"], self._tick)

    # ------------------------------------------------------------------ stepping
    def _t_ns(self, k: int) -> int:
        return convert.seconds_to_ns(k * self.dt_s)

    def _publish(self, topic: str, msg: Any) -> None:
        self.pubs[topic].publish(msg)
        self.published[topic] = self.published.get(topic, 0) + 1

    def _publish_sample(self) -> None:
        """state(t_k) first (the loop waits on it), then /clock and the inspection views."""
        t_ns, x = self._t_ns(self.k), self.x
        self._sent_s = self.wall_now_s()
        self._progress_s = self._sent_s
        self._publish(topics.STATE, convert.state_msg(x, t_ns))
        self._publish(topics.CLOCK, convert.clock_msg(t_ns))
        if self.k % max(self.knobs["inspection_every"], 1) == 0 or self.k == self.steps:
            self._publish(topics.ODOMETRY, convert.odometry_msg(x, t_ns))
            self._publish(topics.TEMPERATURE, convert.temperature_msg(x, t_ns))
            self._publish(topics.BATTERY, convert.battery_msg(x, t_ns, self.cfg, self.knobs["battery_voltage_V"]))
            self._publish(topics.SUN_VECTOR, convert.sun_vector_msg(x, t_ns))

    def _step(self, tau_Nm: np.ndarray) -> None:
        """Hold tau over [t_k, t_k+1) (the core saturates and integrates), publish the new sample."""
        u = model.torque_to_wheel_accel(tau_Nm, self.cfg)
        x_next, _ = simulation.integrate(self.x, u, self.dt_s, self.cfg)
        t_ns = self._t_ns(self.k)
        self.k += 1
        self.x = x_next
        self._publish_sample()
        self._publish(topics.TORQUE_APPLIED, convert.torque_msg(tau_Nm, t_ns))

    def _on_command(self, msg: Any) -> None:
        if self._ended:
            return
        self.counts["commands"] += 1
        try:
            t_ns, tau = convert.torque_from_msg(msg)
        except MessageError as exc:
            self.counts["rejected"] += 1
            self.get_logger().warning(f"{self.command_topic}: rejected ({exc})", throttle_duration_sec=5.0)
            return
        expected = self._t_ns(self.k)
        if not self.lockstep:
            if t_ns == expected:
                self.pending = (t_ns, tau)
            else:
                self.counts["late"] += 1
            return
        if t_ns != expected:
            self.counts["unexpected"] += 1
            self.get_logger().warning(f"{self.command_topic}: stamp {t_ns} ns, expected {expected} ns; ignored",
                                      throttle_duration_sec=5.0)
            return
        self.latency_s.append(self.wall_now_s() - self._sent_s)
        if self.k == self.steps:  # the chain's answer to the final state: counts are now known
            self._end(topics.RUN_DONE)
        else:
            self._step(tau)

    def _tick(self) -> None:
        expected = self._t_ns(self.k)
        if self.pending is not None and self.pending[0] == expected:
            tau = self.pending[1]
            self.latency_s.append(0.0)
        else:
            self.counts["deadline_misses"] += 1
            tau = self.held_tau if self.knobs["deadline_fallback"] == "hold" else np.zeros(3)
        self.pending = None
        self.held_tau = tau
        self._step(tau)
        if self.k == self.steps:
            self.destroy_timer(self._ticker)
            self._end(topics.RUN_DONE)

    def _check_stall(self) -> None:
        waited = self.wall_now_s() - self._progress_s
        if not self._ended and waited > self.knobs["step_timeout_s"]:
            self._end(topics.RUN_FAILED + f": no {self.command_topic} for t = {self.k * self.dt_s:g} s "
                      f"within {self.knobs['step_timeout_s']:g} s")

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

    def _end(self, state: str) -> None:
        """Publish the final run_status with the message counts, wait for acks, finish."""
        if self._ended:
            return
        self._ended = True
        values = self._status_values()
        counts = dict(self.published)
        counts[topics.RUN_STATUS] = counts.get(topics.RUN_STATUS, 0) + 1
        if self.lockstep and state == topics.RUN_DONE:
            # the filter answers every torque_des with one torque_cmd (and, with RTA, one filter_status)
            counts[topics.TORQUE_CMD] = counts[topics.TORQUE_DES] = self.counts["commands"]
            if self.rta:
                counts[topics.FILTER_STATUS] = self.counts["commands"]
        for topic, n in counts.items():
            values[topics.EXPECTED_PREFIX + self.resolve_topic_name(topic)] = n
        self._publish(topics.RUN_STATUS, convert.run_status_msg(self._t_ns(self.k), state, values))
        if self.knobs["exit_when_done"]:
            for pub in self.pubs.values():
                pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        if state.startswith(topics.RUN_FAILED):
            self.fail(f"run failed at step {self.k}: {state[len(topics.RUN_FAILED) + 2:]}")
            return
        self.get_logger().info(f"run done: {self.k} steps; deadline misses {self.counts['deadline_misses']}, "
                               f"rejected {self.counts['rejected']}, unexpected {self.counts['unexpected']}")
        if self.knobs["exit_when_done"]:
            self.finish()


def main(args: Sequence[str] | None = None) -> None:
    """Console script `plant_node` (`ros2 run rta_attitude plant_node --ros-args ...`)."""
    sys.exit(run(PlantNode, args, topics.NODE_NAMES[topics.PLANT]))

if __name__ == "__main__":
    main()
