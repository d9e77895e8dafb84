"""The ordered constraint set of one state, compiled: every barrier row, the box, the safety values.

`rows` evaluates each constraint's module in CONSTRAINT_NAMES order into a TABLE_DTYPE record and
then the box lo <= u <= hi: U, intersected in the `robust` preset with the one-step-ahead
zero-order-hold intervals of the enabled rate and wheel-speed constraints (with the gyrostat model the
rate's are coupled rows instead, `angular_rate.zoh_rows`); where such an interval
misses U entirely (a state already past a limit by more than one step of U can undo) the box shrinks
to the edge of U nearest to it. `safety_values` gives the physical h of every constraint (what the
plant is judged by, at samples and at RK4 substeps) without the derivatives.

Adding a constraint: a module here with `h` and `row` (docs/architecture.md has the worked example),
its name in `config.schema.CONSTRAINT_NAMES`, and one line in each function below.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints import (
    angular_rate,
    battery,
    communication,
    exclusion_zone,
    temperature,
    wheel_speed,
)
from rta_attitude.constraints.base import (
    BATTERY,
    COMMUNICATION,
    EXCLUSION_ZONE,
    OMEGA_X,
    PSI_X,
    TEMPERATURE,
    nan_max,
    nan_min,
)
from rta_attitude.constraints.geometry import angle, context
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]


@numba.njit(**LEAF)
def rows(x: Array, p: np.void, c: np.void, ctx: np.void, t: np.void, lo0: Array, hi0: Array) -> None:
    """Barrier rows and box of one state x (19,, unit quaternion) into table t (TABLE_DTYPE).

    Args:
        x: the state.
        p: the filter's plant model (PLANT_DTYPE).
        c: the constraint parameters (CONSTRAINT_DTYPE).
        ctx: scratch CONTEXT_DTYPE record (filled here).
        t: the output table.
        lo0, hi0: the wheel accelerations the drive can hold this sample (3,): +-U, or where the filter
            compensates its drive's lag, the part of U its state reaches (`filter.pipeline.drive_box`).
    """
    context(x, p, True, ctx)
    exclusion_zone.row(ctx, x, c, t)
    communication.row(ctx, x, c, t)
    temperature.row(ctx, x, c, p, t)
    battery.row(ctx, x, c, p, t)
    for a in range(3):
        angular_rate.row(ctx, x, c, a, t)
        wheel_speed.row(ctx, x, c, a, t)
    angular_rate.zoh_rows(ctx, x, c, p, t)
    box(ctx, x, c, t, lo0, hi0)


@numba.njit(**LEAF)
def box(ctx: np.void, x: Array, c: np.void, t: np.void, lo0: Array, hi0: Array) -> None:
    """t.lo, t.hi (3,), rad/s^2: what the drive can hold (lo0, hi0: `rows`), and in the robust preset the
    one-step ZOH intervals of the enabled rate and wheel-speed constraints (the rate's only where no coupled
    rows, t.zoh_rows, replace them)."""
    rate_on = c.gains[OMEGA_X].enabled and t.zoh_rows == 0
    wheel_on = c.gains[PSI_X].enabled
    for a in range(3):
        lo_a, hi_a = lo0[a], hi0[a]
        if c.robust:
            zlo, zhi = -np.inf, np.inf
            if rate_on:
                wlo, whi = angular_rate.zoh_interval(ctx, x, c, a)
                zlo, zhi = nan_max(zlo, wlo), nan_min(zhi, whi)
            if wheel_on:
                plo, phi = wheel_speed.zoh_interval(ctx, x, c, a)
                zlo, zhi = nan_max(zlo, plo), nan_min(zhi, phi)
            new_lo, new_hi = nan_max(lo_a, zlo), nan_min(hi_a, zhi)
            if new_lo > new_hi:  # the ZOH interval misses U: the edge of U nearest to it
                edge = lo_a if zhi < lo_a else hi_a
                lo_a, hi_a = edge, edge
            else:
                lo_a, hi_a = new_lo, new_hi
        t.lo[a] = lo_a
        t.hi[a] = hi_a


@numba.njit(**LEAF)
def safety_values(x: Array, p: np.void, c: np.void, ctx: np.void, out: Array) -> None:
    """Physical h of every constraint (CONSTRAINT_NAMES order) of state x into out; negative = violated."""
    context(x, p, False, ctx)
    out[EXCLUSION_ZONE] = exclusion_zone.h(ctx, x, c)
    out[COMMUNICATION] = communication.h(ctx, x, c)
    out[TEMPERATURE] = temperature.h(ctx, x, c)
    out[BATTERY] = battery.h(ctx, x, c)
    for a in range(3):
        out[OMEGA_X + a] = angular_rate.h(ctx, x, c, a)
        out[PSI_X + a] = wheel_speed.h(ctx, x, c, a)


ANGLE_NAMES: tuple[str, ...] = ("sensor_sun", "antenna_earth", "face_sun", "face_earth", "panel_sun")
"""`pointing_angles`: theta_EZ (+i_B to the sun), theta_GS (+j_B to the Earth), the -j_B face's sun and
Earth incidence angles, the +k_B panel's sun incidence angle (rad)."""


@numba.njit(**LEAF)
def pointing_angles(x: Array, p: np.void, ctx: np.void, out: Array) -> None:
    """The ANGLE_NAMES angles of state x into out (5,), rad (the geometry the barriers act on)."""
    context(x, p, False, ctx)
    e = exclusion_zone.AXIS_BODY
    out[0] = angle(e[0], e[1], e[2], ctx.sun)
    e = communication.AXIS_BODY
    out[1] = angle(e[0], e[1], e[2], ctx.earth)
    e = temperature.AXIS_BODY
    out[2] = angle(e[0], e[1], e[2], ctx.sun)
    out[3] = angle(e[0], e[1], e[2], ctx.earth)
    e = battery.AXIS_BODY
    out[4] = angle(e[0], e[1], e[2], ctx.sun)


__all__ = ["ANGLE_NAMES", "box", "pointing_angles", "rows", "safety_values"]
