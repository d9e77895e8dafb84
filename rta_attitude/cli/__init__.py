"""`rta-attitude`, the command line: argument parsing and one module per subcommand; the launcher
(process management of the ROS nodes) apart from parsing."""
