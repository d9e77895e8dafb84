"""The primary controller a Monte Carlo's runs fly, and the attitudes it is commanded to.

    none            u_des = 0 (the paper's protocol: the filter alone keeps the spacecraft safe)
    pd              the package's PD law (`dynamics.controller.pd_command`, the config's gains), slewing to
                    random targets: compiled, in the same loop as `none` (`montecarlo.runner.run_batch`)
    module:function a user's Python primary controller, u_des = function(y, q_c, t_s) in rad/s^2 (the
                    convention of `dynamics.controller`); runs through the Python-stepped loop
                    (`simulation.closed_loop.run_stepped`): ~0.2 s more CPU per 2,000 s run than the
                    compiled loop (1.2-1.4x the default configuration's run; docs/montecarlo.md)

Targets (`pd` and a user's function, which gets the target as q_c): uniformly random attitudes (unit
quaternions, scalar last and >= 0), one per run, or a new one every `retarget_s` seconds (the command in
force at sample t_k is the latest target drawn at or before t_k, as a scenario's command schedule). Run
r's targets come from their own random stream, `numpy.random.SeedSequence(seed, spawn_key=(TARGET_STREAM,
r))`: they depend only on the campaign's seed and the run's index (not on chunks, workers or backends),
and drawing them leaves the initial states' stream alone, so a seed gives the same initial states with
every controller. `RunController.scenario` is run r as a `Scenario`, which `simulate` runs to the same
numbers bit for bit (tested).

A user's function is imported by name in each worker process (`module:function`, the module found on
sys.path, with the working directory first as `python -m` does), so it must be importable there (on a
Dask cluster: on every worker). If it has an attribute `reset` (callable, no arguments), that is called
before each run, so a controller with memory (an integrator, a filter) starts every run afresh.
"""

from __future__ import annotations

import importlib
import math
import os
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Scenario
from rta_attitude.dynamics.controller import PrimaryController
from rta_attitude.errors import ConfigError

Array = NDArray[np.float64]

NONE, PD = "none", "pd"
BUILT_IN: tuple[str, ...] = (NONE, PD)
"""The controllers the package has; anything else is a user's `module:function`."""
TARGET_STREAM = 0x7461_7267
"""First spawn key of the targets' random streams ('targ'), apart from any other use of a campaign's seed."""


@dataclass(frozen=True)
class RunController:
    """Which primary controller a campaign's runs fly and where it points them (picklable: names and
    numbers only, so it travels to worker processes and Dask workers).

    Attributes:
        name: 'none', 'pd' or 'module:function'.
        seed: the campaign's seed (the targets' streams).
        retarget_s: a new random target every retarget_s seconds; None: one target per run.
    """

    name: str = NONE
    seed: int = 0
    retarget_s: float | None = None

    def __post_init__(self) -> None:
        if self.name not in BUILT_IN:
            module, sep, attr = self.name.partition(":")
            if not (sep and module and attr):
                raise ConfigError(f"--controller must be none, pd or module:function, got {self.name!r}")
        if self.retarget_s is not None:
            if self.name == NONE:
                raise ConfigError("--retarget needs a controller (--controller pd or module:function)")
            if not (self.retarget_s > 0 and math.isfinite(self.retarget_s)):
                raise ConfigError(f"--retarget must be > 0 s, got {self.retarget_s!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed!r}")

    @property
    def kind(self) -> str:
        """'none', 'pd' or 'python' (a user's function)."""
        return self.name if self.name in BUILT_IN else "python"

    def target_times(self, duration_s: float) -> Array:
        """When each target is commanded (K,), s: 0, retarget_s, 2 retarget_s, ... before duration_s."""
        if self.kind == NONE or self.retarget_s is None:
            return np.zeros(1)
        n = max(1, math.ceil(duration_s / self.retarget_s))
        times = self.retarget_s * np.arange(n, dtype=float)
        return times[times < duration_s] if n > 1 else times

    def targets(self, first_run: int, runs: int, duration_s: float) -> Array:
        """The targets of runs first_run ... first_run + runs - 1 (runs, K, 4): unit quaternions, scalar last
        and >= 0; zeros without a controller (u_des = 0 reads none)."""
        k = len(self.target_times(duration_s))
        out = np.zeros((runs, k, 4))
        if self.kind == NONE:
            return out
        for i in range(runs):
            rng = np.random.default_rng(np.random.SeedSequence(int(self.seed), spawn_key=(TARGET_STREAM,
                                                                                          first_run + i)))
            q = rng.normal(size=(k, 4))
            q /= np.linalg.norm(q, axis=1, keepdims=True)
            q[q[:, 3] < 0] *= -1.0
            out[i] = q
        return out

    def scenario(self, x0: Array, run: int, duration_s: float) -> Scenario:
        """Run `run` of the campaign as a scenario: its initial state x0 (19,), the PD law (`pd`) or none
        (`none` and a user's function, which `run_stepped` takes apart) and the run's targets as its command
        schedule. `rta-attitude simulate`'s loop (`ClosedLoop(cfg, scenario).run()`) runs it to the Monte
        Carlo's numbers bit for bit."""
        q = self.targets(run, 1, duration_s)[0]
        return Scenario(name=f"montecarlo-run-{run}", description=f"Monte Carlo run {run}, controller {self.name}",
                        duration_s=float(duration_s), x0=np.asarray(x0, dtype=float),
                        controller=PD if self.kind == PD else NONE,
                        schedule_s=tuple(float(t) for t in self.target_times(duration_s)),
                        schedule_q=tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in q))

    def function(self) -> PrimaryController:
        """The user's function (kind 'python'), imported.

        Raises:
            ConfigError: the module or the attribute is missing, or it is not callable (one line).
        """
        return load_function(self.name)

    def describe(self) -> str:
        """One phrase for reports: what flew and where it pointed."""
        if self.kind == NONE:
            return "none (u_des = 0)"
        where = (f"a new random target every {self.retarget_s:g} s" if self.retarget_s is not None
                 else "one random target per run")
        return f"{self.name}, {where}"

    def as_dict(self) -> dict[str, Any]:
        """The JSON-ready record of summary.json's setup."""
        return {"name": self.name, "kind": self.kind, "retarget_s": self.retarget_s,
                "target_seed": int(self.seed) if self.kind != NONE else None}


def load_function(spec: str) -> PrimaryController:
    """Import `module:function` (a dotted attribute path after the colon), with the working directory on
    sys.path.

    Raises:
        ConfigError: the module or the attribute is missing, or it is not callable (one line).
    """
    module_name, _, attr = spec.partition(":")
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as exc:
        raise ConfigError(f"--controller {spec}: cannot import {module_name!r} ({exc})") from None
    except Exception as exc:  # the user's module failed while importing: say so, in one line
        raise ConfigError(f"--controller {spec}: importing {module_name!r} raised {type(exc).__name__}: "
                          f"{' '.join(str(exc).split())}") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ConfigError(f"--controller {spec}: {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise ConfigError(f"--controller {spec}: {attr!r} is not callable")
    return obj  # type: ignore[no-any-return]


def attitude_error_deg(q: Array, q_c: Array) -> Array:
    """Angle of the rotation from attitude q_c to q (..., 4), deg (either sign of either quaternion)."""
    q = np.asarray(q, dtype=float)
    q_c = np.asarray(q_c, dtype=float)
    dot = np.abs(np.sum(q * q_c, axis=-1)) / (np.linalg.norm(q, axis=-1) * np.linalg.norm(q_c, axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


__all__ = ["BUILT_IN", "NONE", "PD", "TARGET_STREAM", "RunController", "attitude_error_deg", "load_function"]
