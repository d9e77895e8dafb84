"""rta_attitude: run time assurance (an ASIF safety filter over control barrier functions) for
spacecraft attitude, after McQuinn et al., IEEE Aerospace 2024.

The core (every subpackage but `ros`) imports without rclpy:

    from rta_attitude import config
    from rta_attitude.simulation import simulate
    traj = simulate(config.load(), "paper-example")

Layers, lowest first (docs/architecture.md): config, dynamics, constraints, filter, simulation,
montecarlo, recording, ros (the only one that imports rclpy), cli. Importing the package does
nothing but define these names.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from rta_attitude.errors import BagError, ConfigError, MessageError, OutputError, RtaError, SolverError

try:
    __version__ = version("rta_attitude")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+source"

__all__ = ["BagError", "ConfigError", "MessageError", "OutputError", "RtaError", "SolverError", "__version__"]
