"""ROS 2 nodes of rta_attitude: the only subpackage that imports rclpy.

Thin adapters over the core (validate, convert, one core call, convert back, publish):

- plant_node (`plant_node`): dynamics.spacecraft.integrate stepping, /clock, the state messages
  (odometry, joint_states, temperature, battery, sun_vector; dynamics.sensors.encode) and the packed state;
- controller_node (`pd_controller_node`): odometry -> controller.pd_command;
- filter_node (`asif_filter_node`): the five state messages (dynamics.sensors.decode) -> asif.AsifFilter.filter;
- recorder_node (`bag_recorder_node`): bag.BagWriter.

Shared pieces: interface (QoS profiles and message classes of rta_attitude.topics' vocabulary),
convert (messages <-> numpy), parameters (the core YAML as ROS parameters), spin (base node, startup
gate, main), launch_file (the launch file's argument checks and run-end rules).
Importing this package does not import rclpy; its modules do.
"""

__all__: list[str] = []
