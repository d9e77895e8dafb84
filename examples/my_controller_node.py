"""Your own attitude controller as a ROS 2 node: a template to copy (plain rclpy and numpy).

    rta-attitude launch --controller none --bag run.mcap              # plant, safety filter, recorder
    python examples/my_controller_node.py --ros-args -r __ns:=/rta    # this node: the run starts with it

It reads the state as flight software receives it (`odometry`: attitude and body rates), computes a body
torque with its own law (here a PD to a fixed attitude; replace `control_law`) and publishes it on
`torque_des`; the safety filter pairs it with the state of the same stamp, keeps it safe and sends it to
the plant on `torque_cmd`. What the run expects of it (docs/ros_interface.md, rta_attitude/topics.py):

- QoS reliable, keep all, volatile on both topics: in lockstep a lost message stalls the loop;
- torque_des: geometry_msgs/Vector3Stamped, the torque in N m on the body axes, frame_id `body` (any other
  frame is rejected: the filter then flies u_des = 0 and `rta-attitude analyze` says so), stamped with the
  stamp of the state it answers, one answer per state;
- before the run starts, its publisher has matched the filter and the recorder (volatile: a reader that
  matches later misses what came before). It subscribes to the state only then, and the plant, which
  waits for a node that publishes torque_des and reads the state, starts the run after that.

It exits when the plant's run_status says the run has ended. Parameters: `kp` [N m], `kd` [N m s],
`target` (Hill -> body quaternion x y z w), `record` (false: the run has no recorder).
"""

import sys

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

STREAM_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)  # the run's topics (rta_attitude.topics.STREAM_QOS)
STATUS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)  # run_status: latched
BODY_FRAME = "body"
TORQUE_MAX_NM = 4e-3  # the law's own limit; the filter keeps the command inside what the vehicle allows


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b of quaternions (x, y, z, w), as ROS orientations compose."""
    return np.append(a[3] * b[:3] + b[3] * a[:3] + np.cross(a[:3], b[:3]), a[3] * b[3] - a[:3] @ b[:3])


def control_law(q: np.ndarray, omega: np.ndarray, q_target: np.ndarray, kp: float, kd: float) -> np.ndarray:
    """Body torque (3,) [N m] from the orientation q of the body in Hill (x, y, z, w, as odometry carries it)
    and the body rates omega [rad/s]: PD on the vector part of the error conj(q_target) q (the body's
    rotation from the target, in body axes; half the error angle times its axis for small errors)."""
    err = quat_mul(q_target * [-1.0, -1.0, -1.0, 1.0], q)
    dq = err[:3] if err[3] >= 0.0 else -err[:3]  # the shorter way round
    return np.clip(-kp * dq - kd * omega, -TORQUE_MAX_NM, TORQUE_MAX_NM)


class MyController(Node):
    def __init__(self) -> None:
        super().__init__("my_controller")
        self.kp = self.declare_parameter("kp", 2e-3).value
        self.kd = self.declare_parameter("kd", 1.5e-2).value
        q = np.array(self.declare_parameter("target", [0.0, 0.0, 0.0, 1.0]).value, dtype=float)
        self.q_target = q / np.linalg.norm(q)
        self.readers = 2 if self.declare_parameter("record", True).value else 1  # the filter (+ the recorder)
        self.pub = self.create_publisher(Vector3Stamped, "torque_des", STREAM_QOS)
        self.ended = False
        self.create_subscription(DiagnosticArray, "run_status", self.on_run_status, STATUS_QOS)
        self.wait = self.create_timer(0.05, self.start_when_matched)
        self.get_logger().info(f"waiting for {self.readers} readers of {self.pub.topic_name}")

    def start_when_matched(self) -> None:
        if self.pub.get_subscription_count() < self.readers:
            return  # wait as long as it takes: the filter may still be compiling its kernels
        self.destroy_timer(self.wait)
        self.create_subscription(Odometry, "odometry", self.on_state, STREAM_QOS)
        self.get_logger().info("matched; answering the state")

    def on_state(self, msg: Odometry) -> None:
        o, w = msg.pose.pose.orientation, msg.twist.twist.angular
        tau = control_law(np.array([o.x, o.y, o.z, o.w]), np.array([w.x, w.y, w.z]), self.q_target,
                          self.kp, self.kd)
        out = Vector3Stamped()
        out.header.stamp = msg.header.stamp  # the stamp of the state it answers: the filter pairs by it
        out.header.frame_id = BODY_FRAME
        out.vector.x, out.vector.y, out.vector.z = (float(t) for t in tau)
        self.pub.publish(out)

    def on_run_status(self, msg: DiagnosticArray) -> None:
        ended = [s.message for s in msg.status if s.message.startswith(("done", "failed", "interrupted"))]
        if ended and not self.ended:
            self.ended = True
            self.get_logger().info(f"the run ended: {ended[0]}")
            self.pub.wait_for_all_acked(Duration(seconds=5.0))  # the recorder has every answer before we go


def main() -> None:
    rclpy.init(args=sys.argv)
    node = MyController()
    try:
        while rclpy.ok() and not node.ended:
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # Ctrl-C
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
