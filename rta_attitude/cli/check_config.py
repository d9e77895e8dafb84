"""`rta-attitude check-config`: validate a parameter file and print what it sets."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude check-config`."""
    parser.add_argument("--config", type=Path, default=None,
                        help="parameter YAML (default: $RTA_ATTITUDE_CONFIG or the package's config/rta_attitude.yaml)")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude check-config`."""
    import numpy as np

    from rta_attitude import config as config_module

    cfg = config_module.load(args.config)
    print(f"{cfg.source}: ok")
    print(f"  preset {cfg.filter.preset}, fallback {cfg.filter.fallback}, dt {cfg.filter.sample_time_s} s, "
          f"{cfg.substeps} RK4 substeps")
    print(f"  plant model {cfg.spacecraft.model}, filter model {cfg.filter.model}")
    print(f"  admissible |u| <= {np.array2string(cfg.u_max_rad_s2, precision=2)} rad/s^2 (x, y, z)")
    print(f"  slacked: {', '.join(cfg.slacked_constraints) or 'none'}")
    print(f"  scenarios: {', '.join(s.replace('_', '-') for s in cfg.scenarios)}")
    return 0


__all__ = ["add_arguments", "run"]
