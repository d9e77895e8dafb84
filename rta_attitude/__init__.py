"""rta_attitude: run time assurance (an ASIF safety filter over control barrier functions) for
spacecraft attitude, after McQuinn et al., IEEE Aerospace 2024.

The core (this package without `rta_attitude.nodes`) imports without rclpy:

    from rta_attitude import config
    from rta_attitude.simulation import simulate
    traj = simulate(config.load(), "paper-example")

Modules: config, params, state, model, constraints/, asif, controller, simulation, metrics, plots,
montecarlo, batch, bag, analysis; compiled kernels: barrier_rows, active_set, filter_kernel
(kernel_cache keeps numba's cache of them consistent); ROS adapters: nodes/, launcher, replay, topic_tools; cli.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from .errors import BagError, ConfigError, MessageError, RtaError, SolverError
from .kernel_cache import drop_stale_caches

drop_stale_caches()  # before any numba kernel reads its cache (see kernel_cache)

try:
    __version__ = version("rta_attitude")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+source"

__all__ = ["BagError", "ConfigError", "MessageError", "RtaError", "SolverError", "__version__"]
