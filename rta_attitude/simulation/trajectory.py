"""One run's record: the time series `simulate` returns and `analyze` rebuilds from a bag."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass
class Trajectory:
    """One run's time series; step arrays have N rows, sample arrays N + 1.

    Attributes:
        names: constraint names (m,).
        t_s: sample times (N + 1,), s.
        x: states at the samples (N + 1, 19), model units.
        q_c: commanded quaternion at each step (N, 4).
        u_des, u: desired and applied wheel accelerations (N, 3), rad/s^2 (u after saturation).
        omega_dot: body angular acceleration at the start of each step (N, 3), rad/s^2.
        h: physical constraint values at the samples (N + 1, m).
        h_substep_min: minimum of h over each step's start and its RK4 substeps (N, m).
        h_substep_argmin_s: time of that minimum (N, m), s.
        bc, slack, intervening: filter records per step (N, m); zeros without RTA.
        box_active: (N, 3); status, fallback: (N,) strings ('off' without RTA); iterations (N,);
        solve_time_s (N,).
        y: the measured states the controller and the filter read (N, 19) (None: the exact states x).
    """

    names: tuple[str, ...]
    t_s: Array
    x: Array
    q_c: Array
    u_des: Array
    u: Array
    omega_dot: Array
    h: Array
    h_substep_min: Array
    h_substep_argmin_s: Array
    bc: Array
    slack: Array
    intervening: Array
    box_active: Array
    status: NDArray[np.str_]
    fallback: NDArray[np.str_]
    iterations: NDArray[np.int64]
    solve_time_s: Array
    rta: bool
    preset: str
    scenario: str
    meta: dict[str, object] = field(default_factory=dict)
    y: Array | None = None

    @property
    def steps(self) -> int:
        return len(self.u)


def substep_minima(h_start: Array, h_substeps: Array, t_s: Array, dt_s: Array | float) -> tuple[Array, Array]:
    """Minimum of h over each step (its start sample and its RK4 substeps) and when it occurs.

    Args:
        h_start: h at the start of each step (..., m).
        h_substeps: h at the substeps (substeps, ..., m); the last one is the next sample.
        t_s: start time of each step (...), s.
        dt_s: length of each step (...) or a scalar, s.

    Returns:
        (h_min (..., m), time of the minimum (..., m) in s).
    """
    n_sub = h_substeps.shape[0]
    j = np.argmin(h_substeps, axis=0)
    hs_min = np.take_along_axis(h_substeps, j[None], axis=0)[0]
    frac = np.arange(1, n_sub + 1) / n_sub
    t = np.asarray(t_s, dtype=float)[..., None]
    dt = np.asarray(dt_s, dtype=float)
    dt = dt[..., None] if dt.ndim else dt
    return np.minimum(hs_min, h_start), np.where(hs_min < h_start, t + dt * frac[j], t)


__all__ = ["Trajectory", "substep_minima"]
