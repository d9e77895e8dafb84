"""The check: a rollout of a candidate on the filter's model, every configured constraint at every substep.

`rollout` of a candidate u0 at state x: hold u0 for one sample, then the backup law (its command at each
sample, held), `integrator.substeps` RK4 steps per sample (the plant's own derivative, saturation, torque
interface and RK4: `dynamics.spacecraft`), for `backup_horizon_s`; every enabled, non-slacked constraint must
have h >= its margin at every substep (`constraints.rows.rollout_safety_values` at the substep's time: a
cone's windows apply when the rollout reaches them, and ahead of a window its ramped barrier), until the
state is in the law's terminal set (`law.settled`). With a large momentum a rollout may end safe at its
horizon, with the battery's reserve for the orbit after it (`energy_reserve`). The margins (`check_margins`)
are 0 without sensor errors; with them, the bounds on what the filter reads (docs/noise.md).

Python faces for tests and benches: `backup_command`, `is_settled`, `backup_rollout`.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.base import MAX_ROWS, hard
from rta_attitude.constraints.rows import rollout_safety_values
from rta_attitude.constraints.wheel_speed import wheel_speed_error
from rta_attitude.dynamics.environment import sun_hill, sunlit
from rta_attitude.dynamics.sensors import (
    interface_energy_error,
)
from rta_attitude.dynamics.spacecraft import (
    control_error,
    net_power,
    rk4_hold,
    saturate,
    torque_round_trip,
)
from rta_attitude.dynamics.state import ENERGY, STATE_SIZE, THETA_S
from rta_attitude.filter.gatekeeper.law import (
    RATE_LIMIT_FRACTION,
    VARIANTS,
    _momentum,
    _tilt,
    at_rest,
    continue_command,
    law_state,
    settled,
    sun_safe_command,
)
from rta_attitude.filter.gatekeeper.records import GATE_DTYPE
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]
M = MAX_ROWS


FAILED, HORIZON, SETTLED = 0, 1, 2
"""What a rollout found: a violation (or, with `filter.backup_horizon_at_rest`, a horizon that ends in a slew);
the horizon safe; the terminal set reached, safe till then."""


@numba.njit(**LEAF)
def check_margins(p: np.void, c: np.void, out: Array) -> None:
    """What each constraint's h must keep in a rollout (M,), in h's units: the measurement-robust error
    bounds of the constraint record (0 without sensor errors: then h >= 0), so that a rollout from the
    measured state that keeps them keeps the true h >= 0 over the first sample, where the gate checks
    again. Angles: the attitude error (err_att, with the actuator's drift over a hold); T and E: their
    errors; a rate (or wheel speed) with error e: w_max^2 - (|w| + e)^2 >= 0 needs h >= 2 w_max e + e^2,
    e = the gyro's (tachometer's) error plus the actuator's (|G_a| err_u,a dt; err_u,a dt). With an inertia
    uncertainty the truth departs from the rollout's model over the sample by at most e_a dt in a rate and
    |e| dt^2 / 2 in the attitude (`inertia_accel_rad_s2`), which the rates' and the cones' margins add."""
    dt = c.dt_s
    ia = c.inertia_accel_rad_s2
    inertia_turn = math.sqrt(ia[0] * ia[0] + ia[1] * ia[1] + ia[2] * ia[2]) * dt * dt / 2.0
    for j in range(c.n_cones):
        out[j] = c.err_att_rad + inertia_turn
    out[c.row_temperature] = c.err_T_K
    out[c.row_battery] = c.err_E_J
    for a in range(3):
        e = c.err_omega_axis_rad_s + control_error(p, c.err_u_rad_s2, a) * dt + ia[a] * dt
        out[c.row_omega + a] = 2.0 * c.omega_max_rad_s * e + e * e
        e = wheel_speed_error(c, a)
        out[c.row_psi + a] = 2.0 * c.psi_limit_rad_s * e + e * e


@numba.njit(**LEAF)
def rollout_margin(b: np.void, g: np.void, i: int) -> float:
    """What constraint i's h must keep in the rollout g runs (and the energy reserve that ends it): a
    candidate's margin where g.candidate (the hand-over's, `apply_measurement_margins`), else the backup
    law's (`check_margins`); the two are equal without sensor errors."""
    return b.candidate_margin[i] if g.candidate else b.margin[i]


@numba.njit(**LEAF)
def energy_reserve(x: Array, p: np.void, c: np.void, b: np.void, g: np.void) -> bool:
    """From the state x (19,) (a rollout's end, a large momentum), the battery stays at or above E_min (plus
    the battery margin of the rollout it ends: a candidate's if g.candidate, else the backup law's) for
    b.reserve_steps steps of b.reserve_step_s with the panel held at the tilted target's angle to the sun
    (`_tilt`: as near the sun as the wheels can hold the momentum at rest)
    while the sun moves on (through the Earth's shadow, with the eclipse on): E_dot = `net_power` at that
    angle (midpoint rule). H is conserved in an inertial
    frame (no gravity gradient: its torque changes H by ~2 % an orbit), so in Hill it turns at -frame_rate
    about z_Hill as the sun turns at -n. A projection of what the backup law could keep, not a check of it:
    it makes the gate switch to the backup law while the battery can still afford the dark part of the
    orbit, instead of at the end of a horizon-only plan. False where the wheels hold H at no angle."""
    if b.reserve_steps <= 0:
        return True
    law_state(x, b, g)  # (H's part along the sun axis, in the law's frame)
    _, _, Hb2 = _momentum(g.xl, b.law_plant, g)
    hx, hy, hz = g.Hh[0], g.Hh[1], g.Hh[2]
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if not hn > 0.0:
        return True
    E = x[ENERGY]
    floor = c.energy_min_J + rollout_margin(b, g, c.row_battery)  # the floor of the rollout it ends
    dt = b.reserve_step_s
    for k in range(b.reserve_steps):
        t = (k + 0.5) * dt
        sx, sy, sz = sun_hill(x[THETA_S] - p.mean_motion_rad_s * t, p.sun_cos_beta, p.sun_sin_beta)
        cf, sf = math.cos(p.frame_rate_rad_s * t), math.sin(p.frame_rate_rad_s * t)
        ca = ((cf * hx + sf * hy) * sx + (cf * hy - sf * hx) * sy + hz * sz) / hn  # H turned by -frame_rate t
        cb = _tilt(hn, ca, Hb2, b.law_plant, b)
        if cb > 1.0:
            cos_phi = 1.0
        elif abs(cb) <= 1.0:  # the panel in the plane of H and r_S, beta from H: cos(alpha - beta)
            cos_phi = ca * cb + math.sqrt(max(0.0, 1.0 - ca * ca)) * math.sqrt(max(0.0, 1.0 - cb * cb))
        else:
            return False
        E += dt * net_power(cos_phi, sunlit(sx, p.shadow_sx), p)
        if not E >= floor:
            return False
    return True


@numba.njit(**LEAF)
def hold_sample(u: Array, f: np.void, g: np.void, traj: Array, record: bool) -> bool:
    """One sample of a rollout from g.x (19,) at time g.t: u (3,) held (across the torque interface, saturated,
    as the loop applies it), `substeps` RK4 steps of the filter's model, every enabled, non-slacked constraint
    checked at each substep at its time (h >= b.margin, `check_margins`: 0 without sensor errors;
    b.candidate_margin where g.candidate; NaN fails). g.x becomes the state at the sample's end and g.t its
    time; g.checked counts the substeps (with record, their states go to traj). Returns False at the first
    violation."""
    p, c, b = f.plant, f.constraints, f.backup
    S = b.substeps
    subs = g.subs[:S]
    x = g.x
    torque_round_trip(u, p, g.us)
    saturate(g.us, p, g.us)
    rk4_hold(x, g.us, c.dt_s, S, p, subs, g.work)
    n = 0
    for i in range(c.n_rows):  # the rows to check, once a sample
        if hard(c, i):
            g.hard_rows[n] = i
            g.hard_margin[n] = rollout_margin(b, g, i)
            n += 1
    for j in range(S):
        if record:
            for i in range(STATE_SIZE):
                traj[g.checked, i] = subs[j, i]
        g.checked += 1
        rollout_safety_values(subs[j], g.t + c.dt_s * (j + 1) / S, p, c, g.ctx, g.h)
        for k in range(n):
            if not g.h[g.hard_rows[k]] >= g.hard_margin[k]:
                return False
    for i in range(STATE_SIZE):
        x[i] = subs[S - 1, i]
    g.t += c.dt_s
    return True


@numba.njit(**LEAF)
def backup_tail(f: np.void, g: np.void, traj: Array, record: bool) -> int:
    """The backup law (variant g.law) from g.x, one held command per sample, for horizon_steps samples or
    until `settled`: FAILED, HORIZON (safe to the horizon; with `filter.backup_horizon_at_rest` also at
    rest there: every body rate within the terminal set's) or SETTLED (`hold_sample` checks each sample)."""
    c, b = f.constraints, f.backup
    for _ in range(b.horizon_steps):
        if settled(g.x, b, g):
            return SETTLED
        continue_command(c, b, g, g.u)  # from what settled found at g.x
        if not hold_sample(g.u, f, g, traj, record):
            return FAILED
    if b.horizon_at_rest and not at_rest(g.x, b):
        # a plan that holds for its horizon only must end at rest, as the terminal set asks: one that ends in
        # the middle of a slew (the law's target moved as the sun moved on) is safe up to its last sample and
        # no further, and where nothing verifies from there the spacecraft is handed over moving toward a cone
        return FAILED
    return HORIZON


@numba.njit(**LEAF)
def rollout(x0: Array, u0: Array, f: np.void, g: np.void, traj: Array, record: bool) -> int:
    """Check candidate u0 (3,) at state x0 (19,) on the filter's model: hold u0 for one sample
    (`hold_sample`), then the backup law (`backup_tail`), each sample held over `substeps` RK4 steps, for
    horizon_steps samples or until `settled`. Returns FAILED (an enabled, non-slacked constraint has
    h < 0 (or NaN) at a substep), HORIZON or SETTLED. g.checked: the substeps checked; with record,
    their states go to traj ((horizon_steps + 1) substeps, 19). f: FILTER_DTYPE record; g: GATE_DTYPE
    scratch."""
    for i in range(STATE_SIZE):
        g.x[i] = x0[i]
    for a in range(3):
        g.u[a] = u0[a]
    g.checked = 0
    g.t = g.t_call
    if not hold_sample(g.u, f, g, traj, record):
        return FAILED
    for i in range(STATE_SIZE):
        g.first_x[i] = g.x[i]
    return backup_tail(f, g, traj, record)


@numba.njit(**LEAF)
def _margins_of(fa: NDArray[np.void], out: Array) -> None:
    f = fa[0]
    check_margins(f.plant, f.constraints, out)


def apply_measurement_margins(rec: NDArray[np.void], cfg: Config) -> None:
    """The rollouts' measurement margins (`check_margins`, once: they depend on the record only) into the
    backup record, and the backup law kept inside what the rollouts then accept (sensor errors on): its rate
    command at RATE_LIMIT_FRACTION of the rate the margins leave (sqrt(w_max^2 - margin)), its targets'
    wheel speeds within the wheel speed they leave. rec: the FILTER_DTYPE record (1,) of cfg, changed in
    place; without rate and wheel-speed errors (their margins 0: no sensor errors) the law is unchanged.

    A candidate's rollout keeps the errors of the keep-out cone's angle, the temperature and the charge
    three times (candidate_margin; docs/backup.md, "Hysteresis and the law's hold"): the gate falls back to
    the backup law at the next sample, from the next reading, and that path sits below the candidate's by the
    two readings' errors, up to twice one (E's and nearly T's dynamics do not depend on them: the path moves by
    the offset); the backup law's own check then needs its one error on top. Without sensor errors the two
    margins are equal.

    Likewise the law's command holds each wheel within psi_hold = psi_limit less one reading's error (the
    tachometer's and the actuator's over a hold, as in `check_margins`): a plan that parks a wheel at
    psi_limit leaves the next reading above it half the time, and from there no rollout passes
    (docs/backup.md, "The wheels within their checked speed")."""
    m = np.zeros(M)
    _margins_of(rec, m)
    b = rec["backup"]
    b["margin"][0] = m
    c = rec["constraints"][0]
    extra = np.zeros(M)  # two readings' errors: the candidate's (above the truth) and the next (below it)
    extra[: int(c["n_cones"])] = 2.0 * float(c["err_att_rad"])
    extra[int(c["row_temperature"])] = 2.0 * float(c["err_T_K"])
    extra[int(c["row_battery"])] = 2.0 * max(0.0, float(c["err_E_J"]) - (interface_energy_error(cfg) if c["robust"]
                                                                         else 0.0))
    b["candidate_margin"][0] = m + extra
    w_max, psi_max = float(b["omega_max_rad_s"][0]), float(b["psi_max_rad_s"][0])
    omega_x, psi_x = int(c["row_omega"]), int(c["row_psi"])
    rate_margin, speed_margin = float(np.max(m[omega_x:omega_x + 3])), float(np.max(m[psi_x:psi_x + 3]))
    if rate_margin > 0.0:
        w_left = math.sqrt(max(0.0, w_max * w_max - rate_margin))
        b["rate_limit_rad_s"] = min(float(b["rate_limit_rad_s"][0]), RATE_LIMIT_FRACTION * w_left)
    if speed_margin > 0.0:
        top = math.sqrt(max(0.0, psi_max * psi_max - speed_margin))  # |v| within it keeps h's margin
        reach = cfg.spacecraft.wheel_rate_reach  # |a_i . omega| <= w_max reach
        b["psi_limit_rad_s"] = max(0.0, top - w_max * reach) if c["wheel_speed_relative"] else top  # v = psi + a.w
        e = max(wheel_speed_error(c, a) for a in range(3))
        b["psi_hold_rad_s"] = max(0.0, float(b["psi_limit_rad_s"][0]) - e)


@numba.njit(**LEAF)
def _rollout(x: Array, u0: Array, fa: NDArray[np.void], ga: NDArray[np.void], traj: Array) -> int:
    return rollout(x, u0, fa[0], ga[0], traj, True)


def backup_rollout(x: Array, u0: Array, f: NDArray[np.void], variant: str = "sun_safe",
                   candidate: bool = False, t_s: float = 0.0) -> tuple[str, Array]:
    """`rollout` of candidate u0 (3,) at state x (19,) and time t_s with filter record f (1,) and a variant of
    the backup law (VARIANTS); candidate: it checks a candidate's margins (b.candidate_margin), as `verify` does
    for the filter's answer.

    Returns:
        (what it found: 'failed', 'horizon' or 'settled'; the substep states it checked (K, 19): the
        samples' substeps in order, up to the violation if it failed).
    """
    b = f[0]["backup"]
    traj = np.empty(((int(b["horizon_steps"]) + 1) * int(b["substeps"]), STATE_SIZE))
    g = _scratch(variant)
    g[0]["candidate"] = candidate
    g[0]["t_call"] = t_s
    found = _rollout(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(u0, dtype=float), f, g, traj)
    return ("failed", "horizon", "settled")[found], traj[:int(g[0]["checked"])]


@numba.njit(**LEAF)
def _command(x: Array, fa: NDArray[np.void], ga: NDArray[np.void], out: Array) -> None:
    f = fa[0]
    sun_safe_command(x, f.constraints, f.backup, ga[0], out)


@numba.njit(**LEAF)
def _settled(x: Array, fa: NDArray[np.void], ga: NDArray[np.void]) -> bool:
    f = fa[0]
    return settled(x, f.backup, ga[0])


def _scratch(variant: str) -> NDArray[np.void]:
    if variant not in VARIANTS:
        raise ValueError(f"unknown backup variant {variant!r}; known: {', '.join(VARIANTS)}")
    g = np.zeros(1, GATE_DTYPE)
    g[0]["law"] = VARIANTS.index(variant)
    return g


def backup_command(x: Array, f: NDArray[np.void], variant: str = "sun_safe") -> Array:
    """The backup law's command (3,), rad/s^2, at state x (19,) with filter record f (1,) (FILTER_DTYPE),
    variant one of VARIANTS."""
    out = np.empty(3)
    _command(np.ascontiguousarray(x, dtype=float), f, _scratch(variant), out)
    return out


def is_settled(x: Array, f: NDArray[np.void], variant: str = "sun_safe") -> bool:
    """x (19,) is in the backup law's terminal set."""
    return bool(_settled(np.ascontiguousarray(x, dtype=float), f, _scratch(variant)))
