"""The simulated spacecraft behind one step interface, whichever simulator integrates it
(`plant.simulator`): `CompiledPlant` (the package's RK4 of `dynamics.spacecraft`) or
`dynamics.basilisk.BasiliskPlant` (Basilisk, imported only when chosen).

    plant = make_plant(cfg, x0)          # x0 (16 + N,), the state layout of `dynamics.state` (19 with 3 wheels)
    x_next, subs = plant.step(u)         # u (N,) rad/s^2, saturated at the actuator, held over dt_s;
                                         # subs (substeps, 16 + N): the state after each substep, subs[-1] = x_next
    plant.close()                        # also a context manager

`CompiledPlant.step` is `spacecraft.integrate` of the plant's own state, so a loop over it equals the
compiled closed loop bit for bit (tested).
"""

from __future__ import annotations

from typing import Protocol, Self

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.spacecraft import integrate, plant_record, saturated
from rta_attitude.dynamics.state import state_size

Array = NDArray[np.float64]


class Plant(Protocol):
    """What the stepped closed loop, the Monte Carlo's stepped runs and the plant node ask of a plant."""

    x: Array
    """The state now (19,)."""
    dt_s: float
    """Hold time of one `step`, s."""

    @property
    def t_s(self) -> float:
        """Simulated time now, s."""
        ...

    def step(self, u: Array) -> tuple[Array, Array]:
        """Saturate u (N,) and hold it over dt_s (with `spacecraft.transport_delay_s`, from the delay on: the
        previous step's command holds before); returns (x(t + dt) (19,), substep states (substeps, 19))."""
        ...

    def close(self) -> None:
        """Release the simulator (idempotent)."""
        ...

    def __enter__(self) -> Self: ...

    def __exit__(self, *exc: object) -> None: ...


class CompiledPlant:
    """The package's own plant: `spacecraft.integrate` with the configuration's record.

    Args:
        cfg: configuration (spacecraft.model, environment, integrator.substeps).
        x0: initial state (19,).
        dt_s: hold time of one step, s (default filter.sample_time_s).
    """

    def __init__(self, cfg: Config, x0: Array, dt_s: float | None = None) -> None:
        self.record = plant_record(cfg)
        self.substeps = cfg.substeps
        self.dt_s = float(cfg.filter.sample_time_s if dt_s is None else dt_s)
        self.x = initial_state(cfg, x0)
        self.t_s = 0.0
        self.u_inflight = np.zeros(cfg.spacecraft.n_wheels)  # the last command as the wheels hold it (next delay)

    def step(self, u: Array) -> tuple[Array, Array]:
        """`spacecraft.integrate` from the current state; see `Plant.step`."""
        x_next, subs = integrate(self.x, u, self.dt_s, self.record, self.substeps, self.u_inflight)
        self.u_inflight = saturated(u, self.record)
        self.x = x_next
        self.t_s += self.dt_s
        return x_next, subs

    def close(self) -> None:
        """Nothing to release."""

    def __enter__(self) -> CompiledPlant:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def initial_state(cfg: Config, x0: Array) -> Array:
    """A copy of x0 as the plant's first state, checked to have the configured wheels' size (16 + N)."""
    x = np.array(x0, dtype=float)
    size = state_size(cfg.spacecraft.n_wheels)
    if x.shape != (size,):
        raise ValueError(f"a plant starts from one state ({size},), got {x.shape}")
    return x


def simulated_model(cfg: Config) -> NDArray[np.void]:
    """The PLANT_DTYPE record (1,) of the equations `plant.simulator` integrates: `spacecraft.model` on
    the compiled plant, the gyrostat on Basilisk (for the angular accelerations a run reports)."""
    if cfg.plant.simulator == "basilisk":
        from rta_attitude.dynamics.basilisk import truth_record

        return truth_record(cfg)
    return plant_record(cfg)


def make_plant(cfg: Config, x0: Array, dt_s: float | None = None) -> Plant:
    """The plant `plant.simulator` names, started at x0 (19,); dt_s defaults to filter.sample_time_s.

    Raises:
        ConfigError: basilisk chosen but its configuration cannot be built (see `BasiliskPlant`).
    """
    if cfg.plant.simulator == "basilisk":
        from rta_attitude.dynamics.basilisk import BasiliskPlant

        return BasiliskPlant(cfg, x0, dt_s)
    return CompiledPlant(cfg, x0, dt_s)


__all__ = ["CompiledPlant", "Plant", "make_plant", "simulated_model"]
