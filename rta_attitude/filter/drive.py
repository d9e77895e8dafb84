"""The wheel drive's first-order lag, compensated (robust preset with sensor errors on,
`filter.actuator_lag: compensate`): the box the filter's answer keeps to (`drive_box`) and the command whose
held mean is the answer (`drive_command`); docs/noise.md."""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import (
    MAX_ROWS,
)
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]
M = MAX_ROWS


@numba.njit(**LEAF)
def drive_box(f: np.void, wsa: NDArray[np.void]) -> None:
    """The box of this call's answer (wsa[0].lo0, hi0) and of the answers inside rollouts (wsa[1]): without
    lag compensation +-U; with it, this sample's what the drive reaches from its state v by a command within
    U, [c v - (1 - c) U, c v + (1 - c) U] (`drive_command`), and a rollout's later samples +-(1 - 2c) U, what
    it reaches from any state (`constraints.base.drive_lag`)."""
    c = f.constraints
    k = f.lag_gain
    live, inner, v = wsa[0], wsa[1], wsa[0].gate.drive
    for a in range(3):
        U, reach = c.u_max_rad_s2[a], c.u_reach_rad_s2[a]
        inner.lo0[a], inner.hi0[a] = -reach, reach
        if k > 0.0:
            live.lo0[a], live.hi0[a] = k * v[a] - (1.0 - k) * U, k * v[a] + (1.0 - k) * U
        else:
            live.lo0[a], live.hi0[a] = -reach, reach


@numba.njit(**LEAF)
def drive_command(f: np.void, g: np.void, r: np.void) -> None:
    """The command r.u that makes the wheel drive hold the filter's answer r.u_held over the sample, and the
    drive's state after it (g.drive). The drive's first-order lag holds (1 - c) v_cmd + c v from its state v
    (`constraints.base.drive_lag`), so v_cmd = (u_held - c v) / (1 - c), within U wherever u_held is inside
    the box `drive_box` gave. Not compensated (c = 0): the answer itself."""
    c, e = f.lag_gain, f.lag_decay
    for a in range(3):
        if c > 0.0:
            v = g.drive[a]
            cmd = (r.u_held[a] - c * v) / (1.0 - c)
            r.u[a] = cmd
            g.drive[a] = cmd + (v - cmd) * e
        else:
            r.u[a] = r.u_held[a]
