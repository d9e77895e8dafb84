"""The ordered constraint set of one state, compiled: every barrier row, the box, the safety values.

`rows` evaluates the constraints in row order into a TABLE_DTYPE record (the cone table, `cones`, then
temperature, battery, the rates and the wheel speeds) and then the box lo <= u <= hi: U, intersected in the
`robust` preset with the one-step-ahead zero-order-hold intervals of the enabled rate and wheel-speed
constraints (with the gyrostat model the rate's are coupled rows instead, `angular_rate.zoh_rows`); where
such an interval misses U entirely (a state already past a limit by more than one step of U can undo) the box
shrinks to the edge of U nearest to it. `safety_values` gives the physical h of every constraint (what the
plant is judged by, at samples and at RK4 substeps) without the derivatives. Both take the time t_s (s from
the run's start): a cone with windows applies only within them (`windows`).

A new pointing constraint is an entry of the configuration (`constraints.pointing`), nothing here. A new
*kind* of constraint: a module with `h` and `row` (docs/architecture.md), its row in `base.CONSTRAINT_DTYPE`
and `config.schema.FIXED_NAMES`, and one line in each function below.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints import angular_rate, battery, cones, temperature, wheel_speed
from rta_attitude.constraints.base import hold_interval, inertia_error, nan_max, nan_min
from rta_attitude.constraints.geometry import angle, context
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]


@numba.njit(**LEAF)
def rows(x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, t: np.void, lo0: Array, hi0: Array) -> None:
    """Barrier rows and box of one state x (19,, unit quaternion) at time t_s into table t (TABLE_DTYPE).

    Args:
        x: the state.
        t_s: the time, s from the run's start (the cones' windows).
        p: the filter's plant model (PLANT_DTYPE).
        c: the constraint parameters (CONSTRAINT_DTYPE).
        ctx: scratch CONTEXT_DTYPE record (filled here).
        t: the output table.
        lo0, hi0: the wheel accelerations the drive can hold this sample (3,): +-U, or where the filter
            compensates its drive's lag, the part of U its state reaches (`filter.drive.drive_box`).
    """
    context(x, p, True, ctx)
    for a in range(3):
        ctx.inertia_err[a] = inertia_error(c, p, ctx.omega, ctx.omega_drift, a)
    cones.rows(x, t_s, p, c, ctx, t)
    temperature.row(ctx, x, c, p, t)
    battery.row(ctx, x, c, p, t)
    for a in range(3):
        angular_rate.row(ctx, x, c, a, t)
        wheel_speed.row(ctx, x, c, a, t)
    robust_to_inertia(ctx, c, t)
    angular_rate.zoh_rows(ctx, x, c, p, t)
    box(ctx, x, c, t, lo0, hi0)


@numba.njit(**LEAF)
def robust_to_inertia(ctx: np.void, c: np.void, t: np.void) -> None:
    """With an inertia uncertainty (`base.inertia_error`): each row that u reaches through omega_dot (all but
    the wheel speeds', psi_dot = u whatever J is) keeps its condition for every omega_dot within ctx.inertia_err
    of the model's: its drift less sum_a |dBC/d omega_dot_a| e_a (a robust CBF for a bounded disturbance of the
    highest derivative), dBC/d omega_dot = G^-T gain (gain_a / G_a where G is diagonal)."""
    if c.inertia_error_gain == 0.0:
        return
    e, G, Gi = ctx.inertia_err, ctx.control_gain, c.control_inverse
    for i in range(c.n_rows):
        if c.row_psi <= i < c.row_psi + 3:
            continue
        worst = 0.0
        if ctx.diagonal:
            for a in range(3):
                worst += abs(t.gain[i, a] / G[a]) * e[a]
        else:
            for a in range(3):
                worst += abs(Gi[0, a] * t.gain[i, 0] + Gi[1, a] * t.gain[i, 1] + Gi[2, a] * t.gain[i, 2]) * e[a]
        t.drift[i] -= worst


@numba.njit(**LEAF)
def box(ctx: np.void, x: Array, c: np.void, t: np.void, lo0: Array, hi0: Array) -> None:
    """t.lo, t.hi (3,), rad/s^2: what the drive can hold (lo0, hi0: `rows`), and in the robust preset the
    one-step ZOH intervals of the enabled rate and wheel-speed constraints (the rate's only where no coupled
    rows, t.zoh_rows, replace them)."""
    rate_on = c.gains[c.row_omega].enabled and t.zoh_rows == 0
    wheel_on = c.gains[c.row_psi].enabled
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
            lo_a, hi_a = hold_interval(lo_a, hi_a, zlo, zhi)
        t.lo[a] = lo_a
        t.hi[a] = hi_a


@numba.njit(**LEAF, inline="always")
def _values(x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, rollout: bool, out: Array) -> None:
    context(x, p, False, ctx)
    cones.safety(x, t_s, p, c, ctx, rollout, out)
    out[c.row_temperature] = temperature.h(ctx, x, c)
    out[c.row_battery] = battery.h(ctx, x, c)
    for a in range(3):
        out[c.row_omega + a] = angular_rate.h(ctx, x, c, a)
        out[c.row_psi + a] = wheel_speed.h(ctx, x, c, a)


@numba.njit(**LEAF)
def safety_values(x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, out: Array) -> None:
    """Physical h of every constraint (row order, n_rows) of state x at time t_s into out; negative = violated
    (+inf: a cone outside its windows)."""
    _values(x, t_s, p, c, ctx, False, out)


@numba.njit(**LEAF)
def rollout_safety_values(x: Array, t_s: float, p: np.void, c: np.void, ctx: np.void, out: Array) -> None:
    """What the gatekeeper's rollouts keep: `safety_values` where a cone binds hard (`base.hard`), +inf for the
    others, not computed (a slacked cone's angle costs a rollout's substep more than the other rows); ahead of a
    window, the cone's ramped barrier h + rho(t) (`cones.cone_h`)."""
    _values(x, t_s, p, c, ctx, True, out)


BODY_ANGLE_NAMES: tuple[str, ...] = ("face_sun", "face_earth", "panel_sun")
"""`pointing_angles` after the cones': the thermal face's sun and Earth incidence angles, the panel's sun
incidence angle (rad)."""


@numba.njit(**LEAF)
def pointing_angles(x: Array, p: np.void, c: np.void, ctx: np.void, out: Array) -> None:
    """The angles the barriers act on into out (n_cones + 3,), rad: each cone's boresight to its target (time
    aside: windows do not change the geometry), then BODY_ANGLE_NAMES."""
    context(x, p, False, ctx)
    cones.angles(x, p, c, ctx, out)
    k = c.n_cones
    f = p.face_normal
    out[k] = angle(f[0], f[1], f[2], ctx.sun)
    out[k + 1] = angle(f[0], f[1], f[2], ctx.earth)
    e = p.panel_normal
    out[k + 2] = angle(e[0], e[1], e[2], ctx.sun)


__all__ = ["BODY_ANGLE_NAMES", "box", "pointing_angles", "robust_to_inertia", "rollout_safety_values", "rows",
           "safety_values"]
