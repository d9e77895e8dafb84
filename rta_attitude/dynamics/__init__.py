"""The spacecraft: state layout, quaternion algebra, the plant model and its integrator, the primary
controller. Nothing here knows about constraints, the filter or ROS."""
