"""Launch the rta_attitude closed loop on a stock ROS 2 Jazzy install.

    ros2 launch rta_attitude rta_attitude.launch.py scenario:=paper_example rta:=true bag:=/tmp/run.mcap
    ros2 launch rta_attitude rta_attitude.launch.py stepping:=realtime real_time_factor:=50.0 bag:=/tmp/rt.mcap

Starts plant_node, pd_controller_node, asif_filter_node (pass-through with rta:=false) and
bag_recorder_node under `namespace`, all with the package's parameter file (`params_file`) and
use_sim_time (except the plant, which publishes /clock). The launch shuts down when the recorder has
closed the bag and exited (the plant exits after the scenario, the recorder once every message is
in); with record:=false, when the plant exits. Same behaviour as `rta-attitude launch`, which needs
no ROS launch installation and also prints the run summary.

Isolation, as `rta-attitude launch`: the nodes run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
(`discovery_range:=SUBNET` lifts it) on `domain_id` (default: $ROS_DOMAIN_ID, else 0).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler, SetEnvironmentVariable
from launch.conditions import IfCondition, UnlessCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import EnvironmentVariable, LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory("rta_attitude")
    default_params = os.path.join(share, "config", "rta_attitude.yaml")
    args = {
        "namespace": ("/rta", "namespace of every topic (except /clock)"),
        "params_file": (default_params, "the parameter YAML (the one the core reads)"),
        "scenario": ("paper_example", "scenario name in params_file"),
        "rta": ("true", "false: the filter node passes torque_des through"),
        "record": ("true", "start bag_recorder_node (writers wait for its subscriptions)"),
        "bag": ("rta_attitude_run.mcap", "MCAP file the recorder writes"),
        "bag_overwrite": ("false", "replace an existing bag file"),
        "stepping": ("lockstep", "lockstep or realtime"),
        "real_time_factor": ("1.0", "realtime stepping: sim seconds per wall second"),
        "domain_id": (EnvironmentVariable("ROS_DOMAIN_ID", default_value="0"), "ROS_DOMAIN_ID of the nodes"),
        "discovery_range": ("LOCALHOST", "ROS_AUTOMATIC_DISCOVERY_RANGE of the nodes (LOCALHOST, SUBNET, OFF)"),
    }
    cfg = {name: LaunchConfiguration(name) for name in args}
    params_file = cfg["params_file"]
    common = {
        "config_file": params_file,
        "scenario": cfg["scenario"],
        "rta": ParameterValue(cfg["rta"], value_type=bool),
        "record": ParameterValue(cfg["record"], value_type=bool),
    }

    def node(executable: str, extra: dict, sim_time: bool = True, **kwargs) -> Node:
        return Node(
            package="rta_attitude", executable=executable, namespace=cfg["namespace"], output="screen",
            parameters=[params_file, {**common, **extra, "use_sim_time": sim_time}], **kwargs,
        )

    plant = node("plant_node", {
        "stepping": cfg["stepping"],
        "real_time_factor": ParameterValue(cfg["real_time_factor"], value_type=float),
    }, sim_time=False)
    recorder = node("bag_recorder_node", {
        "bag_path": cfg["bag"],
        "bag_overwrite": ParameterValue(cfg["bag_overwrite"], value_type=bool),
    }, condition=IfCondition(cfg["record"]))
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=text)
          for name, (default, text) in args.items()),
        SetEnvironmentVariable("ROS_DOMAIN_ID", cfg["domain_id"]),
        SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE", cfg["discovery_range"]),
        SetEnvironmentVariable("ROS_STATIC_PEERS", ""),
        recorder,
        node("asif_filter_node", {}),
        node("pd_controller_node", {}),
        plant,
        # the run ends when the bag is closed (or, without a recorder, when the plant is done)
        RegisterEventHandler(OnProcessExit(target_action=recorder, on_exit=[EmitEvent(event=Shutdown())]),
                             condition=IfCondition(cfg["record"])),
        RegisterEventHandler(OnProcessExit(target_action=plant, on_exit=[EmitEvent(event=Shutdown())]),
                             condition=UnlessCondition(cfg["record"])),
    ])
