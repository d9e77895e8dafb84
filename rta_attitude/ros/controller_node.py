"""pd_controller_node: odometry -> torque_des, the paper's primary controller (controller.pd_command),
which reads the attitude and the body rates only.

Reference q_c: the scenario's command schedule (from the parameter file, evaluated at the state's
stamp, as ClosedLoop does), unless an `attitude_command` arrived: an operator command is in force
from its stamp on (a stamp in the future waits until sim time reaches it) and replaces the
schedule from then on. Scenarios with `controller: none` publish zero torque.

The torque crosses DDS: tau_des = D u_des (`wheel_accel_to_torque`), stamped with the state's
stamp.

Bad input (each kind counted, logged once per episode; the counts are in the node's exit line):
a state with an invalid stamp, a duplicate or older stamp, or (use_sim_time) older than the /clock
time by more than `max_state_age_s` is dropped (not answered); a state whose values are unusable
(NaN/inf, wrong length or names, quaternion norm off by more than `quaternion_tolerance`) is
answered with zero torque, so the filter is not left waiting (it sees the same bad state and answers
with its invalid-state fallback); a quaternion off by less is renormalised. An attitude_command that
is not a unit quaternion within `quaternion_tolerance` is rejected.

Live parameters: `controller.kp` and `controller.kd` may be changed while the node runs (`ros2 param set`);
the core loader validates the new value (finite, >= 0), the node logs it and answers the next
state with the new gains. (A run whose gains change is no longer the one `simulate` reproduces.)
"""

from __future__ import annotations

import bisect
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from rta_attitude import topics
from rta_attitude.dynamics.controller import controller_record, desired_command
from rta_attitude.dynamics.sensors import F_OMEGA, F_Q, FIELD_SIZE
from rta_attitude.dynamics.spacecraft import wheel_accel_to_torque
from rta_attitude.dynamics.state import OMEGA, STATE_SIZE, Q
from rta_attitude.errors import MessageError
from rta_attitude.ros import convert, interface, spin
from rta_attitude.ros.faults import StampOrder
from rta_attitude.ros.spin import RtaNode


class ControllerNode(RtaNode):
    """The PD attitude controller; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(topics.CONTROLLER, **kwargs)
        self.law = controller_record(self.cfg, pd=self.scenario.controller == "pd")
        self.overrides: list[tuple[int, np.ndarray]] = []  # (stamp ns, q_c), sorted by stamp
        self.order = StampOrder()
        t0 = time.perf_counter()
        with spin.interruptible():
            desired_command(self.scenario.x0, self.scenario.command_at(0.0), self.law)  # loaded before we subscribe
        self.get_logger().info(f"controller ready in {time.perf_counter() - t0:.2f} s")
        spec = topics.TOPICS[topics.TORQUE_DES]
        pub = self.create_publisher(interface.msg_class(spec.type_name), spec.name, self.qos(topics.TORQUE_DES))
        self.out = self.gate(topics.TORQUE_DES, pub)
        self.subscribe(topics.ODOMETRY, self._on_state, peer=topics.PLANT, raw=True)
        self.subscribe(topics.ATTITUDE_COMMAND, self._on_command)
        self.get_logger().info(f"scenario {self.scenario.name}: controller {self.scenario.controller}")

    def on_clock_jump(self) -> None:
        self.order.reset()

    def on_live_parameters(self, changes: dict[str, Any]) -> None:
        """New gains (`ros2 param set <ns>/pd_controller controller.kp 0.3`): the next state is answered with them."""
        self.law = controller_record(self.cfg, pd=self.scenario.controller == "pd")

    def reference(self, t_ns: int) -> np.ndarray:
        """q_c (4,) in force at t: the latest operator command stamped <= t, else the schedule."""
        i = bisect.bisect_right([s for s, _ in self.overrides], t_ns)
        if i > 0:
            return self.overrides[i - 1][1]
        return self.scenario.command_at(self.sim_s(t_ns))

    def _on_command(self, msg: Any) -> None:
        try:
            t_ns, q = convert.quaternion_from_msg(msg, self.knobs["quaternion_tolerance"])
        except MessageError as exc:
            self.faults.fault("attitude_command_rejected", str(exc))
            return
        self.faults.clear("attitude_command_rejected")
        bisect.insort(self.overrides, (t_ns, q), key=lambda item: item[0])
        self.get_logger().info(f"attitude command {np.round(q, 4).tolist()} from t = {self.sim_s(t_ns):g} s")

    def _on_state(self, msg: Any) -> None:
        """odometry(t_k): the attitude and the rates are all the PD law reads (`pd_command`)."""
        if self.stopping:
            return
        t_ns = self.message_stamp(msg, "state_rejected")
        if t_ns is None or not self.admit_state_stamp(t_ns, self.order):
            return
        try:
            f = np.zeros(FIELD_SIZE)
            convert.odometry_fields(msg, f)
            x = np.zeros(STATE_SIZE)
            x[Q], x[OMEGA] = f[F_Q:F_Q + 4], f[F_OMEGA:F_OMEGA + 3]
            x = self.unit_state(x, t_ns)
        except MessageError as exc:
            self.faults.fault("state_rejected", f"{exc}; answered with zero torque")
            self.out.publish(convert.torque_cdr(np.zeros(3), t_ns))
            return
        self.faults.clear("state_rejected")
        u_des = desired_command(x, self.reference(t_ns), self.law)
        self.out.publish(convert.torque_cdr(wheel_accel_to_torque(u_des, self.cfg.spacecraft.wheel_inertia_kgm2), t_ns))


def main(args: Sequence[str] | None = None) -> None:
    """Console script `pd_controller_node` (`ros2 run rta_attitude pd_controller_node --ros-args ...`)."""
    spin.main(ControllerNode, args, topics.NODE_NAMES[topics.CONTROLLER])


if __name__ == "__main__":
    main()
