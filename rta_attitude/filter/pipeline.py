"""One filter call, compiled: the one pipeline every path runs (simulate, the filter node, the Monte
Carlo).

    delayed_state  with a transport delay, the state at the delay's end, where the answer takes over (`drive`)
    drive_box    what the wheel drive can hold this call (`drive`)
    answer       the ASIF's QP (`qp`)
    gate_call    with a backup law (`filter.backup_law`), the gatekeeper (`gatekeeper`): u is applied only if
                 it, held for a sample, then the backup law, is safe over the horizon on the filter's model;
                 else the backup law of its committed plan (the workspace keeps the plan)
    finish       BC_i at the final u, which box bounds clipped u
    drive_command  the command whose held mean is the answer (`drive`); the answer in flight remembered

Parameters travel as one FILTER_DTYPE record, scratch as WORKSPACE_DTYPE records, the result is one
RESULT_DTYPE record (`records`; `filter.asif` reads it). `filter_many` runs the same call over a batch.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import (
    MAX_ROWS,
)
from rta_attitude.dynamics.spacecraft import delay_time
from rta_attitude.filter.drive import delayed_state, drive_box, drive_command, remember_inflight
from rta_attitude.filter.gatekeeper.plans import gate_call
from rta_attitude.filter.outcome import (
    GATE_TOWARD_BACKUP,
)
from rta_attitude.filter.qp import answer, finish
from rta_attitude.jit import JIT

Array = NDArray[np.float64]
M = MAX_ROWS


@numba.njit(**JIT)
def filter_state(x: Array, u_des: Array, t_s: float, f: np.void, wsa: NDArray[np.void], r: np.void) -> None:
    """One whole filter call: state x (19,) at time t_s (s from the run's start), desired wheel accelerations
    u_des (3,) -> result record r (its answer u_held, the command u that makes the drive hold it:
    `drive_command`); wsa: the filter's workspaces (`new_workspace`). With a transport delay the call plans
    from the state at t_s + delay (`drive.delayed_state`): consecutive calls are consecutive samples."""
    g = wsa[0].gate
    if delayed_state(x, f, g):  # a transport delay: plan from the state where the answer takes over
        _plan(g.x_delay, u_des, t_s + delay_time(f.backup.dt_s, f.backup.substeps, f.plant.delay_substeps), f,
              wsa, r)
    else:
        _plan(x, u_des, t_s, f, wsa, r)
    remember_inflight(f, g, r)


@numba.njit(**JIT)
def _plan(x: Array, u_des: Array, t_s: float, f: np.void, wsa: NDArray[np.void], r: np.void) -> None:
    """`filter_state` from the state its answer takes over at: the drive's box, the answer, the gate, the
    drive's command."""
    ws = wsa[0]
    drive_box(f, wsa)
    if answer(x, u_des, t_s, f, ws, r):
        _gate_and_finish(x, u_des, t_s, f, wsa, r)
    for a in range(3):
        r.u_held[a] = r.u[a]
    drive_command(f, ws.gate, r)


@numba.njit(**JIT)
def _gate_and_finish(x: Array, u_des: Array, t_s: float, f: np.void, wsa: NDArray[np.void], r: np.void) -> None:
    """`filter_state` of a valid state after its answer: the gatekeeper, then `finish`."""
    ws = wsa[0]
    r.gate = gate_call(x, u_des, t_s, f, wsa, r)
    if r.gate == GATE_TOWARD_BACKUP:
        # nothing verified, and a variant of the backup law stayed safe longer than the answer: the ASIF's
        # answer to that variant's command instead of u_des (docs/backup.md, "When nothing verifies")
        # (r.u_des stays the primary's command; iterations and solves count both answers' QPs)
        iterations, solves = r.iterations, r.solves
        answer(x, ws.gate.longest_u, t_s, f, ws, r)
        r.gate = GATE_TOWARD_BACKUP
        r.iterations += iterations
        r.solves += solves
        for a in range(3):
            r.u_des[a] = u_des[a]
    finish(f.constraints.n_rows, ws, r)


@numba.njit(**JIT)
def filter_many(X: Array, U_des: Array, T: Array, f: NDArray[np.void], ws: NDArray[np.void], R: NDArray[np.void]
                ) -> None:
    """`filter_state` of states X (N, 19) at times T (N,) with commands U_des (N, 3) into results R (N,)."""
    for k in range(X.shape[0]):
        filter_state(X[k], U_des[k], T[k], f[0], ws, R[k])
