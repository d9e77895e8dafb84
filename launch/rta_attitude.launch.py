"""Launch the rta_attitude closed loop on a stock ROS 2 Jazzy install.

    ros2 launch rta_attitude rta_attitude.launch.py scenario:=paper_example bag:=/tmp/run.mcap
    ros2 launch rta_attitude rta_attitude.launch.py stepping:=realtime real_time_factor:=50.0
    ros2 launch rta_attitude rta_attitude.launch.py --show-args

Starts plant_node, pd_controller_node (not with controller:=none: then the plant waits for a node of
yours that publishes torque_des, e.g. examples/my_controller_node.py), asif_filter_node (pass-through with
rta:=false), bag_recorder_node and scene_node (the 3D view, off the control path; scene:=false leaves it
out) under `namespace`, all with the package's parameter file (`params_file`), use_sim_time (except the
plant, which publishes /clock) and exit_with_parent (a SIGTERM to `ros2 launch` leaves its processes
running; with it they notice that the launch is gone and stop cleanly).

Every argument is checked before any node starts (rta_attitude.ros.launch_file.validate): a bad one
is one error line and exit code 1. The launch ends with the run: when the plant is done and the
recorder has closed the bag (record:=false: when the plant is done), the others are stopped by
SIGINT and exit cleanly; if any node fails (non-zero exit, or ends before the run), the rest are
shut down and the launch exits 1 (rta_attitude.ros.launch_file.RunEnd). Same behaviour as
`rta-attitude launch`, which needs no ROS launch installation and also prints the run summary.

Isolation, as `rta-attitude launch`: the nodes run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
(`discovery_range:=SUBNET` lifts it) on `domain_id` (default: $ROS_DOMAIN_ID, else 0).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch_ros.actions import Node

from launch import LaunchDescription
from rta_attitude import topics
from rta_attitude.ros.launch_file import ARGUMENTS, NODE_PARAMETERS, SIGTERM_TIMEOUT_S, RunEnd, node_roles, validate


def _nodes(context, *args, **kwargs):
    """Validate the arguments (raises before any node starts), then the nodes and their exit wiring."""
    share = get_package_share_directory("rta_attitude")
    names = {arg.name for arg in ARGUMENTS}
    a = validate({k: v for k, v in context.launch_configurations.items() if k in names},
                 default_params=os.path.join(share, "config", "rta_attitude.yaml"))
    for key, value in (("ROS_DOMAIN_ID", str(a["domain_id"])), ("ROS_AUTOMATIC_DISCOVERY_RANGE", a["discovery_range"]),
                       ("ROS_STATIC_PEERS", "")):
        os.environ[key] = value  # inherited by every node started below
    # the scene: hosted by the recorder when there is one (it draws from what the recorder receives), else a
    # scene_node process of its own
    scene = (topics.SCENE_OFF if not a["scene"] else topics.SCENE_RECORDER if a["record"] else topics.SCENE_NODE)
    common = {"config_file": a["params_file"], "scenario": a["scenario"], "rta": a["rta"], "record": a["record"],
              "scene": scene, **NODE_PARAMETERS}

    def node(executable: str, extra: dict, sim_time: bool = True) -> Node:
        return Node(package="rta_attitude", executable=executable, namespace=a["namespace"], output="screen",
                    parameters=[a["params_file"], {**common, **extra, "use_sim_time": sim_time}],
                    sigterm_timeout=str(SIGTERM_TIMEOUT_S))

    # controller:=none: no pd_controller_node; the plant waits for a node of the user's that publishes torque_des
    plant = {"stepping": a["stepping"], "real_time_factor": a["real_time_factor"],
             "external_controller": a["controller"] == "none"}
    extra = {topics.PLANT: plant, topics.RECORDER: {"bag_path": a["bag"], "bag_overwrite": a["bag_overwrite"]}}
    exe = topics.EXECUTABLES
    # readers first; the plant and a scene_node of its own draw by the stamps (no /clock reader)
    nodes = {exe[role]: node(exe[role], extra.get(role, {}), sim_time=role not in (topics.PLANT, topics.SCENE))
             for role in node_roles(a)}
    end = RunEnd(record=a["record"])

    def on_exit(name: str):
        def handler(event, context):
            if context.is_shutdown and end.decided is None:  # the user stopped the launch (Ctrl-C)
                return None
            verdict, reason = end.exited(name, event.returncode)
            if verdict == "failed":
                raise RuntimeError(reason)  # ros2 launch: one error line, shutdown of the rest, exit 1
            if verdict == "done":
                return [EmitEvent(event=Shutdown(reason=reason))]
            return None
        return handler

    return [*nodes.values(), *(RegisterEventHandler(OnProcessExit(target_action=n, on_exit=on_exit(name)))
                               for name, n in nodes.items())]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        *(DeclareLaunchArgument(a.name, default_value=a.default, description=a.description) for a in ARGUMENTS),
        OpaqueFunction(function=_nodes),
    ])
