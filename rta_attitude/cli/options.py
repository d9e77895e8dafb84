"""The configuration options every subcommand that loads one shares: `--config FILE` (a whole parameter file
or an overlay of the package's) and `-p KEY=VALUE` (one dotted key on top, file units), read by `load`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rta_attitude.config.schema import Config

CONFIG_HELP = ("parameter YAML: a whole file or an overlay holding only what differs from the package's "
               "config/rta_attitude.yaml (default: $RTA_ATTITUDE_CONFIG or the package's)")
PARAM_HELP = ("set one parameter on top of the file, dotted key and YAML value in the file's units "
              "(e.g. -p constraints.omega.k1=0.3); repeatable")


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """`--config FILE` and `-p/--param KEY=VALUE`."""
    parser.add_argument("--config", type=Path, default=None, help=CONFIG_HELP)
    parser.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE", help=PARAM_HELP)


def load(args: argparse.Namespace, preset: str | None = None) -> Config:
    """The configuration of `--config` with the `-p` overrides, validated as one.

    Raises:
        ConfigError: a missing or invalid file, a malformed or invalid override.
    """
    from rta_attitude import config

    return config.load(args.config, preset=preset, overrides=config.parse_overrides(args.param))


__all__ = ["CONFIG_HELP", "PARAM_HELP", "add_config_arguments", "load"]
