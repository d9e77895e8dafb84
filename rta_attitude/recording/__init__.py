"""Runs on disk: MCAP bags in rosbag2's conventions (writer and reader), analysis of a recorded run,
figures."""
