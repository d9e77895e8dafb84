"""What the wheels do with the filter's commands, in the filter's model:

- the drive's first-order lag, compensated (robust preset with sensor errors on, `filter.actuator_lag:
  compensate`): the box the filter's answer keeps to (`drive_box`) and the command whose held mean is the
  answer (`drive_command`); docs/noise.md;
- the transport delay (`spacecraft.transport_delay_s`): the wheels hold the previous answer until the delay is
  over, so the call plans from the state at that time (`delayed_state`), which it predicts with its model from
  the state it receives and the answer in flight (`remember_inflight`); docs/delay.md.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import (
    MAX_ROWS,
)
from rta_attitude.dynamics.spacecraft import delay_time, rk4_hold, torque_round_trip
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter.qp import usable_quaternion_norm
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


@numba.njit(**LEAF)
def delayed_state(x: Array, f: np.void, g: np.void) -> bool:
    """With a transport delay (the filter's plant model has delay_substeps m > 0): the state the wheels'
    next command starts from, x held under the answer in flight (g.inflight) for the delay's m RK4 substeps of
    the filter's model, into g.x_delay. The plant switches commands on the same substep grid
    (`spacecraft.rk4_delayed`), so where the model is the plant's and the state exact the prediction is the
    plant's state. Returns False (nothing written) without a delay, or for a state the filter will refuse
    (`qp.usable_quaternion_norm`: `qp.prepare` answers it)."""
    m = f.plant.delay_substeps
    if m == 0 or usable_quaternion_norm(x) == 0.0:
        return False
    b = f.backup
    rk4_hold(x, g.inflight, delay_time(b.dt_s, b.substeps, m), m, f.plant, g.subs[:m], g.work)
    for i in range(STATE_SIZE):
        g.x_delay[i] = g.subs[m - 1, i]
    return True


@numba.njit(**LEAF)
def remember_inflight(f: np.void, g: np.void, r: np.void) -> None:
    """The answer r.u_held as the wheels will hold it over the next call's delay (across the torque
    interface, as the plant receives it): g.inflight."""
    torque_round_trip(r.u_held, f.plant, g.inflight)
