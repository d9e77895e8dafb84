"""The DDS transport settings of the run's nodes: a reliable writer repairs a lost sample within 0.1 s.

Fast DDS (the default RMW of ROS 2 Jazzy) sends a reliable writer's periodic heartbeat every 3 s. Under load
a sample is now and then lost on its way to a reader (a full shared-memory port); the reader asks for it
again only when the next heartbeat comes, and every later sample of that writer waits behind the gap
(in-order delivery). With 3 s, a recorder stopped by SIGINT could give up (`stop_timeout_s`) on a stream
still waiting for its repair and close the bag without the states published before the signal, and every
stop waited 1-3 s for the last acknowledgements. `fastdds_profile.xml` (package data) sets the heartbeat to
0.1 s and nothing else; rmw_fastrtps takes every QoS policy ROS names from the node's own profile.

A user's own Fast DDS profile wins: the file is used only when neither FASTDDS_DEFAULT_PROFILES_FILE nor
FASTRTPS_DEFAULT_PROFILES_FILE is set (Fast DDS 2.x reads the latter when the first participant is made,
i.e. at rclpy.init). Other RMWs ignore it.
"""

from __future__ import annotations

import os
from importlib import resources

PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
"""The variable Fast DDS 2.x (ROS 2 Jazzy) reads its XML profiles file from."""
PROFILE_ENVS = (PROFILE_ENV, "FASTDDS_DEFAULT_PROFILES_FILE")
"""Either set by the user: their profile is used instead of ours."""
PROFILE_FILE = "fastdds_profile.xml"


def profile_path() -> str:
    """The path of the package's Fast DDS profile."""
    return str(resources.files(__package__).joinpath(PROFILE_FILE))


def use_profile() -> bool:
    """Point Fast DDS at the package's profile unless the user named one. Call before rclpy.init.
    Returns True if ours is set."""
    if any(os.environ.get(k) for k in PROFILE_ENVS):
        return False
    os.environ[PROFILE_ENV] = profile_path()
    return True


__all__ = ["PROFILE_ENV", "PROFILE_ENVS", "profile_path", "use_profile"]
