"""The one parameter source: config/rta_attitude.yaml, validated once into a frozen `Config`.

- `schema`: the typed, frozen parameter sets (model units: SI, rad, K), each checked on construction;
- `loader`: YAML -> Config (`load`, `read_parameters`, `from_parameters`); deg and degC become rad and K
  there and nowhere else.
"""

from __future__ import annotations

from rta_attitude.config.loader import (
    CELSIUS_OFFSET_K,
    CONFIG_ENV,
    apply_overrides,
    default_config_path,
    from_parameters,
    load,
    merge,
    package_config_path,
    parse_overrides,
    read_parameters,
)
from rta_attitude.config.schema import Config, Scenario

__all__ = ["CELSIUS_OFFSET_K", "CONFIG_ENV", "Config", "Scenario", "apply_overrides", "default_config_path",
           "from_parameters", "load", "merge", "package_config_path", "parse_overrides", "read_parameters"]
