"""ROS 2 nodes of rta_attitude: the only subpackage that imports rclpy.

Thin adapters over the core (validate, convert, one core call, convert back, publish):

- plant_node (`plant_node`): dynamics.spacecraft.integrate stepping, /clock, state, inspection topics;
- controller_node (`pd_controller_node`): controller.pd_command;
- filter_node (`asif_filter_node`): asif.AsifFilter.filter;
- recorder_node (`bag_recorder_node`): bag.BagWriter.

Shared pieces: interface (QoS profiles and message classes of rta_attitude.topics' vocabulary),
convert (messages <-> numpy), parameters (the core YAML as ROS parameters), spin (base node, startup
gate, main), launch_file (the launch file's argument checks and run-end rules).
Importing this package does not import rclpy; its modules do.
"""

__all__: list[str] = []
