"""The gatekeeper: the filter applies its answer only while a verified way out exists (recursive
feasibility), after Agrawal & Panagou 2023 ("gatekeeper") and the backup-CBF idea. Compiled; the
plant's own derivative, saturation, torque interface and RK4 (`dynamics.spacecraft`) and the safety
values (`constraints.rows.safety_values`) on the filter's model of the plant (`f.plant`).

The backup law (`sun_safe_command`): towards the sun-safe attitude, rows of A in Hill

    k_B = r_S (the +k_B panel on the sun),   j_B = (r_E - (r_E . r_S) r_S) / |...| (the antenna on the
    Earth side; z_Hill x r_S at a Sun-Earth conjunction),   i_B = j_B x k_B (the sensor perpendicular
    to the sun; the -j_B face sees neither the sun nor the Earth),

a rate command w_ref = clip(-(kp/kd) dq_v, +-RATE_LIMIT_FRACTION w_max) (dq = q (x) q_c^-1 with
dq4 >= 0, kp, kd the primary controller's gains) tracked by a first-order rate loop with the plant's
drift cancelled:

    u_a = clip(((w_ref_a - w_a) / RATE_TIME_CONSTANT_S - w_dot_drift_a) / (d w_dot_a / d u_a), +-U_a),

w_dot_drift = `omega_drift` of the filter's model (Euler, the wheels' gyroscopic term -w x (-s D psi),
gravity gradient if on): the gyroscopic feed-forward of w x H, H = J w - s D psi, of the viability
oracle's `sun_safe_ff` law (`viability.laws`, which tests use as the independent twin).

The check (`rollout`) of a candidate u0 at state x: hold u0 for one sample, then the backup law (its
command at each sample, held), `integrator.substeps` RK4 steps per sample, for `backup_horizon_s`;
every enabled, non-slacked constraint must have h >= 0 at every substep, until the state is in the
terminal set (`settled`: near the sun-safe attitude with small rates and a wheel momentum the wheels
can hold there), which the backup law keeps (docs/backup.md). `verify` accepts a settled rollout,
and, only with a large momentum (|H| / D > psi_max - max J_a w_max / D), one whose horizon ends safe;
it tries the committed plan's variant of the law first, then the others (VARIANTS: sun-safe, momentum mode,
and with a large momentum the Earth-side target as it is, the tight tilt and the tight tilt on the sun's side
of a narrow corridor, reached through it).

The gate (`gate`), at each filter call with a backup law: the candidate (the ASIF's answer) passes
-> apply it, commit its plan; else, if the backup law's own command passes -> apply it, commit;
else, if a committed plan remains -> apply its variant's command (the plan's next command: verified
at an earlier sample); else apply the candidate unverified. The plan is the only memory of the
filter (`GATE_DTYPE`, in the workspace).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import BACKUP_LAWS, MAX_BACKUP_SUBSTEPS, MAX_NOMINAL_STEPS, Config
from rta_attitude.constraints.base import MAX_ROWS
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.rows import safety_values
from rta_attitude.constraints.wheel_speed import wheel_speed_error
from rta_attitude.dynamics.environment import EARTH_HILL, sun_hill
from rta_attitude.dynamics.quaternion import attitude_matrix, error_vector, from_matrix
from rta_attitude.dynamics.sensors import (
    ENERGY_RELATIVE_ERROR,
    FIELD_SIZE,
    SENSORS_DTYPE,
    deliver,
    interface_energy_error,
    sensors_record,
)
from rta_attitude.dynamics.spacecraft import (
    RK4_WORK_ROWS,
    net_power,
    omega_drift,
    rk4_hold,
    saturate,
    torque_round_trip,
)
from rta_attitude.dynamics.state import ENERGY, STATE_SIZE, TEMP, THETA_S
from rta_attitude.filter.outcome import GATE_BACKUP, GATE_OFF, GATE_TOWARD_BACKUP, GATE_UNVERIFIED, GATE_VERIFIED
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]
M = MAX_ROWS

NO_LAW, SUN_SAFE = (BACKUP_LAWS.index(n) for n in ("none", "sun_safe"))
"""Codes of the backup laws (`filter.backup_law`)."""
RATE_LIMIT_FRACTION = 0.9
"""The backup law commands |w_ref_a| <= this fraction of w_max (0.7 until 2026-11-25: the rollout checks the
rate limit at every substep, so the reserve only slowed the way out; the oracle's witnesses run the rates to
within 2e-6 rad/s of w_max)."""
RATE_TIME_CONSTANT_S = 2.0
"""Time constant of the backup law's rate loop, s."""
SETTLED_ANGLE_RAD = math.radians(5.0)
"""Terminal set: attitude error to the sun-safe attitude at most this, ..."""
SETTLED_RATE_FRACTION = 0.1
"""... every body rate at most this fraction of w_max, ..."""
# ... and every wheel can hold its share of the momentum at rest there (`_wheel_load`).
TILT_WHEEL_MARGIN = 0.002
"""The tilted sun-safe target keeps the panel-axis wheel this fraction of psi_max (1.2 rad/s) inside its limit
(0.01 until 2026-11-25: the rollout checks the wheel speeds at every substep; the oracle's witnesses of the
backup's failures keep the wheels 0.06 rad/s inside psi_max, and the smaller reserve saved two of them)."""
WHEEL_SPEED_RTOL = 1e-12
"""The backup law's command keeps each wheel at most (1 - this) psi_hold at its hold's end (`_rate_command`):
the rollout checks the speed at every substep, and the RK4 steps round in the last bits."""
CORRIDOR_HALF_WIDTH_RAD = math.radians(10.0)
"""Where H_body could cross the i_B-j_B plane only through corridors narrower than this either side of
the diagonal (a large momentum), the tilted target keeps the panel on its side of H."""
RESERVE_STEP_S = 10.0
"""Step of `energy_reserve`'s projection, s (the sun moves 0.6 deg in it; midpoint rule)."""
VARIANTS = ("sun_safe", "momentum", "earth_side", "tight", "cross")
"""The backup law's variants (its targets): the sun-safe attitude (rolled or tilted for a large momentum, the
momentum mode where the wheels could not hold the momentum there); the momentum mode always; the Earth-side
sun-safe attitude as it is, whatever the momentum; the tilted target with only the terminal set's rates
(SETTLED_RATE_FRACTION w_max) kept in its wheels; the same on the sun's side of a narrow corridor, reached
through it (`_cross`). The last four only with a large momentum. The gatekeeper
tries the committed plan's first, then the others in this order: each is a way out the rollout verifies, so
another variant adds ways out and only acts where the ones before it failed (docs/backup.md, "A portfolio of
targets")."""
SUN_SAFE_VARIANT, MOMENTUM, EARTH_SIDE, TIGHT, CROSS = range(len(VARIANTS))
FAILED, HORIZON, SETTLED = 0, 1, 2
"""What a rollout found: a violation; the horizon safe; the terminal set reached, safe till then."""

BACKUP_DTYPE = np.dtype([
    ("law", np.int8),                    # BACKUP_LAWS code (NO_LAW: no gatekeeper)
    ("horizon_steps", np.int64),         # samples of the backup law after the candidate's hold
    ("substeps", np.int64),              # RK4 steps per sample (integrator.substeps)
    ("kp", np.float64),                  # attitude gain of the rate command (controller.kp)
    ("kd", np.float64),                  # rate gain (controller.kd): w_ref = -(kp / kd) dq_v
    ("rate_limit_rad_s", np.float64),    # |w_ref_a| <= this
    ("rate_time_constant_s", np.float64),
    ("settled_sin_half_angle", np.float64),
    ("settled_rate_rad_s", np.float64),
    ("omega_max_rad_s", np.float64),
    ("psi_max_rad_s", np.float64),
    ("psi_limit_rad_s", np.float64),     # the wheel speed the law's targets may use (psi_max; less with sensor errors)
    ("psi_hold_rad_s", np.float64),      # the law keeps each wheel within this (psi_limit less one reading's error)
    ("momentum_variant_rad_s", np.float64),  # the MOMENTUM variant only where |J w - s D psi| / D exceeds this
    ("nominal_steps", np.int64),         # samples of the filter's own answers before the backup law (>= 1)
    ("reserve_steps", np.int64),         # steps of `energy_reserve`'s projection (0: off)
    ("reserve_step_s", np.float64),      # ... each this long
    ("margin", np.float64, (M,)),        # what each h must keep in a rollout (`check_margins`; 0 without sensor errors)
    ("candidate_margin", np.float64, (M,)),  # ... in a candidate's rollout (`apply_measurement_margins`)
    ("interface", SENSORS_DTYPE),        # how the filter receives a state (`sensors.deliver`): plans predict that
])  # fmt: skip
"""The gatekeeper's parameters (a field of the filter's record)."""

GATE_DTYPE = np.dtype([
    ("plan_steps", np.int64),            # samples the committed plan is still verified for (0: none)
    ("drive", np.float64, (3,)),         # the wheel drive's state as the filter's commands left it, rad/s^2
    # (`pipeline.drive_command`; 0 at rest, and where the lag is not compensated)
    ("plan_n", np.int64),                # samples of the committed nominal plan (0: none) ...
    ("plan_at", np.int64),               # ... the one the next call should be at
    ("plan_x", np.float64, (MAX_NOMINAL_STEPS, STATE_SIZE)),  # its states at the samples (as received)
    ("plan_u", np.float64, (MAX_NOMINAL_STEPS, 3)),           # the filter's answers there (candidates)
    ("nominal_wait", np.int64),          # calls to wait before the next nominal plan is tried
    ("filtered_wait", np.int64),         # calls to wait before the backup law through the filter is tried again
    ("filtered_backoff", np.int64),      # ... the wait after its next failure (doubles, to FILTERED_BACKOFF_MAX)
    ("filtered_tries", np.int64),        # calls that tried the backup law through the filter (since reset)
    ("next_x", np.float64, (STATE_SIZE,)),  # the committed plan's state at the next sample, as the filter will
    # receive it (`sensors.deliver` of the prediction)
    ("has_next", np.uint8),              # ... next_x is set
    ("plan_settled", np.uint8),          # the committed plan reaches the terminal set (holds for good)
    ("plan_weak", np.uint8),             # the committed plan is safe to its horizon but short of the energy reserve
    ("weak_law", np.int8),               # the last `verify`'s first variant safe to the horizon without the
    # energy reserve (-1: none), its command and its state after the first sample (`commit_weak`)
    ("weak_u", np.float64, (3,)),
    ("weak_x", np.float64, (STATE_SIZE,)),
    ("first_x", np.float64, (STATE_SIZE,)),  # the last rollout's state after its first sample
    ("x0", np.float64, (STATE_SIZE,)),   # the state the call's rollouts start from
    ("t_call", np.float64),              # the call's time, s from the run's start: where its rollouts start
    ("t", np.float64),                   # the rollout's clock at its sample's start (`hold_sample`)
    ("reused", np.int64),                # calls answered from a committed plan without a rollout (since reset)
    ("checked", np.int64),               # substeps the last rollout checked
    ("x", np.float64, (STATE_SIZE,)),    # the rollout's state at the samples
    ("u", np.float64, (3,)),             # the command of the rollout's sample
    ("us", np.float64, (3,)),            # the command across the torque interface, saturated
    ("u_backup", np.float64, (3,)),      # the backup law's command at the filter's state
    ("h", np.float64, (M,)),
    ("subs", np.float64, (MAX_BACKUP_SUBSTEPS, STATE_SIZE)),
    ("work", np.float64, (RK4_WORK_ROWS, STATE_SIZE)),
    ("ctx", CONTEXT_DTYPE),
    ("A", np.float64, (3, 3)),
    ("fields", np.float64, (FIELD_SIZE,)),  # scratch of `sensors.deliver`
    ("target", np.float64, (3, 3)),      # the sun-safe attitude, rows i_B, j_B, k_B in Hill
    ("Hh", np.float64, (3,)),            # the body's angular momentum J w - s D psi in Hill, N m s
    ("load", np.float64),                # `_wheel_load` of the sun-safe target
    ("momentum_mode", np.uint8),         # 1: the target is the momentum mode's; 2: the tilted sun-safe one;
    # 3: the Earth-side one with a large momentum (EARTH_SIDE); 0: a terminal set may apply (`settled`)
    ("law", np.uint8),                   # the variant the rollout and the command use (VARIANTS)
    ("plan_law", np.uint8),              # the variant of the committed plan
    ("q_c", np.float64, (4,)),
    ("dq", np.float64, (3,)),
    ("wd", np.float64, (3,)),
    ("candidate", np.uint8),             # the rollout checks a candidate: h >= candidate_margin (else margin)
    ("xm", np.float64, (STATE_SIZE,)),   # the law's state at the middle of its hold (`_rate_command`)
    ("answer_lasted", np.int64),         # this `gate` call: the most substeps a failed rollout of the answer checked
    ("backup_lasted", np.int64),         # ... of a failed rollout of a variant's own command, that command:
    ("longest_u", np.float64, (3,)),     # GATE_TOWARD_BACKUP's u_des
])  # fmt: skip
"""The gatekeeper's memory (plan_steps) and scratch (one per filter workspace)."""


def backup_record(cfg: Config) -> NDArray[np.void]:
    """The BACKUP_DTYPE record (1,) of a configuration."""
    rec = np.zeros(1, BACKUP_DTYPE)
    b = rec[0]
    o, L = cfg.filter, cfg.limits
    b["law"] = BACKUP_LAWS.index(o.backup_law)
    b["horizon_steps"] = max(1, round(o.backup_horizon_s / o.sample_time_s))
    b["substeps"] = cfg.substeps
    b["kp"], b["kd"] = cfg.controller.kp, cfg.controller.kd
    b["rate_limit_rad_s"] = RATE_LIMIT_FRACTION * L.omega_max_rad_s
    b["rate_time_constant_s"] = RATE_TIME_CONSTANT_S
    b["settled_sin_half_angle"] = math.sin(0.5 * SETTLED_ANGLE_RAD)
    b["settled_rate_rad_s"] = SETTLED_RATE_FRACTION * L.omega_max_rad_s
    b["omega_max_rad_s"], b["psi_max_rad_s"] = L.omega_max_rad_s, L.psi_max_rad_s
    b["psi_limit_rad_s"] = L.psi_max_rad_s
    b["psi_hold_rad_s"] = L.psi_max_rad_s
    sc = cfg.spacecraft
    b["momentum_variant_rad_s"] = L.psi_max_rad_s - float(np.max(sc.J)) * L.omega_max_rad_s / sc.wheel_inertia_kgm2
    b["nominal_steps"] = max(1, round(o.backup_nominal_s / o.sample_time_s))
    b["reserve_step_s"] = RESERVE_STEP_S
    b["reserve_steps"] = round(o.backup_energy_lookahead_s / RESERVE_STEP_S)
    b["interface"] = sensors_record(cfg)[0]
    return rec


# ----------------------------------------------------------------------------- the backup law


@numba.njit(**LEAF)
def large_momentum(x: Array, p: np.void, b: np.void) -> bool:
    """|J w - s D psi| / D of the state x (19,) above b.momentum_variant_rad_s (psi_max - max J_a w_max /
    D): a momentum the sun-safe attitude may not hold at rest (the gate's and the backup law's test)."""
    hh = 0.0
    for a in range(3):
        ha = (p.inertia_kgm2[a] * x[4 + a] - p.torque_sign * p.wheel_inertia_kgm2 * x[7 + a]) / p.wheel_inertia_kgm2
        hh += ha * ha
    return math.sqrt(hh) > b.momentum_variant_rad_s


@numba.njit(**LEAF)
def _wheel_load(T: Array, Hh: Array, p: np.void, b: np.void, share: float = 1.0) -> float:
    """The largest wheel speed the momentum Hh (Hill, 3) needs at rest in the attitude T (rows i_B, j_B,
    k_B in Hill), plus J_a share w_max / D (the rates the law may still command), minus psi_max: > 0 means
    the wheels cannot hold it."""
    worst = -np.inf
    for a in range(3):
        ha = abs(T[a, 0] * Hh[0] + T[a, 1] * Hh[1] + T[a, 2] * Hh[2])
        v = (ha + p.inertia_kgm2[a] * share * b.omega_max_rad_s) / p.wheel_inertia_kgm2
        worst = max(worst, v)
    return worst - b.psi_limit_rad_s


@numba.njit(**LEAF)
def _sun_across(hx: float, hy: float, hz: float, sx: float, sy: float, sz: float, sh: float
                ) -> tuple[float, float, float]:
    """The unit part of r_S = (sx, sy, sz) perpendicular to the unit vector h (sh = h . r_S); where r_S
    lies along h, a direction perpendicular to h."""
    ox, oy, oz = sx - sh * hx, sy - sh * hy, sz - sh * hz
    on = math.sqrt(ox * ox + oy * oy + oz * oz)
    if on < 1e-9:  # h along the sun: any perpendicular direction
        ox, oy, oz, on = -hy, hx, 0.0, math.sqrt(hx * hx + hy * hy)
        if on < 1e-9:
            ox, oy, oz, on = 1.0, 0.0, 0.0, 1.0
    return ox / on, oy / on, oz / on


@numba.njit(**LEAF)
def _toward(b0: float, b1: float, b2: float, t0: float, t1: float, t2: float, g: np.void) -> float:
    """dq_v := (b x t) / 2 into g.dq (the rate command turns the body about b x t, which moves the unit body
    momentum b straight towards t); returns dq4."""
    c0, c1, c2 = b1 * t2 - b2 * t1, b2 * t0 - b0 * t2, b0 * t1 - b1 * t0
    g.dq[0], g.dq[1], g.dq[2] = 0.5 * c0, 0.5 * c1, 0.5 * c2
    return math.sqrt(max(0.0, 1.0 - 0.25 * (c0 * c0 + c1 * c1 + c2 * c2)))


@numba.njit(**LEAF)
def _h_first(b0: float, b1: float, b2: float, t0: float, t1: float, t2: float, b: np.void, g: np.void) -> float:
    """First stage of a slew with a large momentum: while the unit body momentum (b0, b1, b2) is more
    than SETTLED_ANGLE_RAD from its place at the target (t0, t1, t2), dq_v := (b x t) / 2 into g.dq and
    returns dq4 (the rate command then turns the body about an axis perpendicular to H, which moves
    H_body straight towards t: dH_body/dt = H_body x w, so it does not wander past a wheel's limit);
    else returns -1 (the target's own attitude error applies; g.dq is then overwritten by the caller)."""
    dq4 = _toward(b0, b1, b2, t0, t1, t2, g)
    dq = g.dq
    if dq[0] * dq[0] + dq[1] * dq[1] + dq[2] * dq[2] > b.settled_sin_half_angle**2:
        return dq4
    return -1.0


@numba.njit(**LEAF)
def _cross(b0: float, b1: float, b2: float, t2: float, hb: float, share: float, p: np.void, b: np.void,
           g: np.void) -> float:
    """The CROSS variant's path while the unit body momentum (b0, b1, b2) is on the other side of the i_B-j_B
    plane from its place at the target (k_B part t2): through the corridor between the i_B and j_B wheels'
    caps, each less one reading's error (psi_limit - psi_hold: 0 without sensor errors; every call re-plans
    from a reading). The corridor's middle longitude phi (|H| cos phi <= c_1, |H| sin phi <= c_2 at rest,
    `_wheel_caps`); first along the latitude to it (while more than half the corridor's half-width off), then
    along that meridian to the target's latitude. Returns dq4 (g.dq set), or -1 where there is no corridor."""
    c1, c2, _ = _wheel_caps(p, b, share)
    room = (b.psi_limit_rad_s - b.psi_hold_rad_s) * p.wheel_inertia_kgm2  # one reading's error (0 without)
    c1, c2 = c1 - room, c2 - room
    lo = math.acos(min(1.0, c1 / hb))
    hi = math.asin(min(1.0, c2 / hb))
    if not hi > lo:
        return -1.0
    phi = 0.5 * (lo + hi)
    sx = 1.0 if b0 >= 0.0 else -1.0
    sy = 1.0 if b1 >= 0.0 else -1.0
    lon = math.atan2(abs(b1), abs(b0))
    if abs(lon - phi) > 0.25 * (hi - lo):  # along the latitude to the corridor's longitude
        r = math.sqrt(max(0.0, 1.0 - b2 * b2))
        return _toward(b0, b1, b2, sx * r * math.cos(phi), sy * r * math.sin(phi), b2, g)
    r = math.sqrt(max(0.0, 1.0 - t2 * t2))  # along the meridian to the target's latitude
    return _toward(b0, b1, b2, sx * r * math.cos(phi), sy * r * math.sin(phi), t2, g)


@numba.njit(**LEAF)
def _wheel_caps(p: np.void, b: np.void, share: float = 1.0) -> tuple[float, float, float]:
    """What each wheel (i_B, j_B, k_B) may hold at rest at the tilted target, N m s: (1 - TILT_WHEEL_MARGIN)
    psi_limit D, less its rates' share J_a share w_max (the rates the law may still command: all of w_max,
    or the terminal set's SETTLED_RATE_FRACTION in the TIGHT variant, `_rate_share`)."""
    top = (1.0 - TILT_WHEEL_MARGIN) * b.psi_limit_rad_s * p.wheel_inertia_kgm2
    w = share * b.omega_max_rad_s
    return top - p.inertia_kgm2[0] * w, top - p.inertia_kgm2[1] * w, top - p.inertia_kgm2[2] * w


@numba.njit(**LEAF)
def _tilt(hn: float, ca: float, hb2: float, p: np.void, b: np.void, share: float = 1.0, cross: bool = False) -> float:
    """cos beta of the tilted target (`_tilted_target`): the panel's angle to the momentum (|H| = hn, N m s)
    nearest alpha = angle(H, r_S) (ca = cos alpha) at which the wheels hold H at rest: the panel-axis wheel
    |H| |cos beta| <= cap, the i_B and j_B wheels |H| sin beta <= |(c_1, c_2)|; on the side of hb2 (H_body's
    k_B part) where the corridor between the sides is narrow, unless cross (the CROSS variant: the sun's
    side, reached through the corridor, `_cross`). 2.0 where no tilt is needed (the panel-axis wheel holds
    all of H), NaN where the wheels hold H at no beta. share: as `_wheel_caps`'s."""
    c1, c2, cap = _wheel_caps(p, b, share)
    if not cap > 0.0:
        return math.nan
    if not hn > cap:
        return 2.0
    cos_a = cap / hn
    # |cos beta| <= cos_a for the panel-axis wheel; the i_B and j_B wheels share |H| sin(beta) in
    # proportion to c_1, c_2: |cos beta| >= lo
    c12 = math.sqrt(c1 * c1 + c2 * c2)
    lo = math.sqrt(max(0.0, 1.0 - (c12 / hn) ** 2))
    if lo > cos_a:
        return math.nan
    side = 1.0 if ca >= 0.0 else -1.0
    if not cross and hn * math.cos(0.25 * math.pi - CORRIDOR_HALF_WIDTH_RAD) > min(c1, c2):
        side = 1.0 if hb2 >= 0.0 else -1.0  # a narrow corridor: keep the side (CROSS: the sun's side)
    return side * min(max(side * ca, lo), cos_a)


@numba.njit(**LEAF)
def _rate_share(g: np.void) -> float:
    """The fraction of w_max whose momentum (J_a share w_max) the tilted target leaves each wheel for the
    rates, in the variant g.law: all of it; in the TIGHT and CROSS variants the terminal set's rates only
    (SETTLED_RATE_FRACTION), the panel nearer the sun and the wheels nearer their limit."""
    return SETTLED_RATE_FRACTION if (g.law == TIGHT or g.law == CROSS) else 1.0


@numba.njit(**LEAF)
def _momentum(x: Array, p: np.void, g: np.void) -> tuple[float, float, float]:
    """The body's angular momentum H = J w - s D psi of the state x (19,): returned in body axes, N m s, and
    in Hill (A^T H) into g.Hh; g.A := A(q)."""
    A = g.A
    attitude_matrix(x[0], x[1], x[2], x[3], A)
    s, D = p.torque_sign, p.wheel_inertia_kgm2
    Hb0 = p.inertia_kgm2[0] * x[4] - s * D * x[7]
    Hb1 = p.inertia_kgm2[1] * x[5] - s * D * x[8]
    Hb2 = p.inertia_kgm2[2] * x[6] - s * D * x[9]
    for c in range(3):
        g.Hh[c] = A[0, c] * Hb0 + A[1, c] * Hb1 + A[2, c] * Hb2
    return Hb0, Hb1, Hb2


@numba.njit(**LEAF)
def energy_reserve(x: Array, p: np.void, c: np.void, b: np.void, g: np.void) -> bool:
    """From the state x (19,) (a rollout's end, a large momentum), the battery stays at or above E_min (plus
    the battery margin of the rollout it ends: a candidate's if g.candidate, else the backup law's) for
    b.reserve_steps steps of b.reserve_step_s with the panel held at the tilted target's angle to the sun
    (`_tilt`: as near the sun as the wheels can hold the momentum at rest)
    while the sun moves on: E_dot = `net_power` at that angle (midpoint rule). H is conserved in an inertial
    frame (no gravity gradient: its torque changes H by ~2 % an orbit), so in Hill it turns at -frame_rate
    about z_Hill as the sun turns at -n. A projection of what the backup law could keep, not a check of it:
    it makes the gate switch to the backup law while the battery can still afford the dark part of the
    orbit, instead of at the end of a horizon-only plan. False where the wheels hold H at no angle."""
    if b.reserve_steps <= 0:
        return True
    _, _, Hb2 = _momentum(x, p, g)
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
        cb = _tilt(hn, ca, Hb2, p, b)
        if cb > 1.0:
            cos_phi = 1.0
        elif abs(cb) <= 1.0:  # the panel in the plane of H and r_S, beta from H: cos(alpha - beta)
            cos_phi = ca * cb + math.sqrt(max(0.0, 1.0 - ca * ca)) * math.sqrt(max(0.0, 1.0 - cb * cb))
        else:
            return False
        E += dt * net_power(cos_phi, p)
        if not E >= floor:
            return False
    return True


@numba.njit(**LEAF)
def _tilted_target(sx: float, sy: float, sz: float, hb0: float, hb1: float, hb2: float, share: float, p: np.void,
                   b: np.void, g: np.void) -> bool:
    """Write into g.target the sun-safe attitude tilted off the sun just enough for the wheels to hold
    the momentum g.Hh (Hill): the panel k_B as near r_S = (sx, sy, sz) as the wheels allow.

    With the panel at angle beta from H the panel-axis wheel holds |H| cos beta: it can (at rest, with
    the rate margin of `_wheel_load` and TILT_WHEEL_MARGIN) while |cos beta| <= cos a. i_B and j_B
    share H's part perpendicular to k_B, |H| sin beta, in proportion to what their wheels can take
    (c_1, c_2): they can while |cos beta| >= lo. k_B goes to the beta in that band nearest
    alpha = angle(H, r_S), in the plane of H and r_S: the panel |alpha - beta| off the sun, and no
    attitude the wheels can hold puts it nearer (viability.rules.momentum_bands; a test holds it
    against an optimiser). Where H_body (hb0, hb1, hb2) could reach the other side of the i_B-j_B plane
    only through a corridor narrower than CORRIDOR_HALF_WIDTH_RAD (the i_B and j_B wheels must then
    hold all of |H|), k_B stays on its side of H (k_B . H keeps the sign of hb2). Of the four rolls:
    first one that keeps the signs of (hb0, hb1) (H_body need not cross an axis plane on the way, where
    one wheel would have to hold more), then one with the -j_B radiator off the sun (j_B . r_S >= 0),
    then the antenna j_B nearest the Earth. share: the rates' share kept in the wheels (`_rate_share`,
    `_wheel_caps`). Returns False (target untouched) where there is no
    momentum to tilt from or the wheels cannot hold it at any beta."""
    Hh = g.Hh
    hn = math.sqrt(Hh[0] * Hh[0] + Hh[1] * Hh[1] + Hh[2] * Hh[2])
    if not hn > 0.0:
        return False
    hx, hy, hz = Hh[0] / hn, Hh[1] / hn, Hh[2] / hn
    ca = hx * sx + hy * sy + hz * sz
    cb = _tilt(hn, ca, hb2, p, b, share, g.law == CROSS)
    if not abs(cb) <= 1.0:  # no tilt needed, or none the wheels can hold
        return False
    sb = math.sqrt(max(0.0, 1.0 - cb * cb))
    c1, c2, _ = _wheel_caps(p, b, share)
    c12 = math.sqrt(c1 * c1 + c2 * c2)
    ox, oy, oz = _sun_across(hx, hy, hz, sx, sy, sz, ca)
    kx, ky, kz = cb * hx + sb * ox, cb * hy + sb * oy, cb * hz + sb * oz
    px, py, pz = (hx - cb * kx) / sb, (hy - cb * ky) / sb, (hz - cb * kz) / sb  # H's part perpendicular to k
    mx, my, mz = ky * pz - kz * py, kz * px - kx * pz, kx * py - ky * px  # k x p
    ex, ey, ez = EARTH_HILL
    r1, r2 = c1 / c12, c2 / c12  # H_perp shared in proportion to what each wheel can take
    best = -np.inf
    ux = uy = uz = 0.0
    for sa, sg in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):
        ix, iy, iz = sa * r1 * px + sg * r2 * mx, sa * r1 * py + sg * r2 * my, sa * r1 * pz + sg * r2 * mz
        jx, jy, jz = ky * iz - kz * iy, kz * ix - kx * iz, kx * iy - ky * ix  # j = k x i
        score = jx * ex + jy * ey + jz * ez
        if jx * sx + jy * sy + jz * sz < -1e-12:  # the radiator would see the sun
            score -= 10.0
        if sa * hb0 >= 0.0 and -sg * hb1 >= 0.0:  # H . i = sa r1 |H_perp|, H . j = -sg r2 |H_perp|
            score += 20.0
        if score > best:
            best, ux, uy, uz = score, ix, iy, iz
    T = g.target
    T[0, 0], T[0, 1], T[0, 2] = ux, uy, uz
    T[1, 0], T[1, 1], T[1, 2] = ky * uz - kz * uy, kz * ux - kx * uz, kx * uy - ky * ux
    T[2, 0], T[2, 1], T[2, 2] = kx, ky, kz
    return True


@numba.njit(**LEAF)
def sun_safe_error(x: Array, p: np.void, b: np.void, g: np.void) -> float:
    """dq_v (3,) into g.dq of the state x (19,) towards the sun-safe attitude, sign fixed so that dq4 >= 0
    (g.target, g.q_c, g.A, g.Hh filled); returns dq4.

    The sun-safe attitude has k_B = r_S; its roll about r_S puts j_B on the Earth side, unless the
    wheels could not hold the body's momentum H there at rest (`_wheel_load` > 0): then i_B, j_B lie
    at 45 deg to H's part perpendicular to the sun (each wheel takes 1/sqrt(2) of it), the one of the
    four such rolls with j_B nearest the Earth. With a large momentum (|H| / D above
    b.momentum_variant_rad_s, as `verify`'s), or where the wheels could not hold H there either, the
    target the wheels can hold with the panel nearest the sun (`_tilted_target`, g.momentum_mode = 2),
    and H_body goes straight to its place at that target first (`_h_first`, as below); if the wheels
    could not hold H at any panel angle, or with the
    MOMENTUM variant (g.law), the momentum mode (g.momentum_mode = 1): the attitude with H on the body
    diagonal d = sign(H_body) / sqrt(3) (each wheel takes |H| / sqrt(3)) turned about H to bring k_B
    nearest the sun (k_B . H / |H| = d_3: k_B in the plane of H and r_S). While H_body is more than
    SETTLED_ANGLE_RAD from d, dq_v := (h x d) / 2 (h = H_body / |H_body|) instead: the rate command
    then turns the body about an axis perpendicular to H, which moves H_body straight towards d (first
    stage), then about H to the panel's roll. The EARTH_SIDE variant aims at the Earth-side attitude as it
    is (g.momentum_mode = 3, no terminal set: `verify` uses it with a large momentum only); the TIGHT
    variant tilts as above with only SETTLED_RATE_FRACTION w_max of the rates' momentum kept in the wheels
    (`_rate_share`); the CROSS variant as TIGHT, but with the panel on the sun's side of H where the corridor
    across the i_B-j_B plane is narrow, H_body taken through the corridor's middle first (`_cross`)."""
    sx, sy, sz = sun_hill(x[THETA_S], p.sun_cos_beta, p.sun_sin_beta)
    T = g.target
    Hb0, Hb1, Hb2 = _momentum(x, p, g)
    ex, ey, ez = EARTH_HILL
    d = ex * sx + ey * sy + ez * sz
    jx, jy, jz = ex - d * sx, ey - d * sy, ez - d * sz
    n = math.sqrt(jx * jx + jy * jy + jz * jz)
    if n < 1e-6:  # conjunction: z_Hill x r_S
        jx, jy, jz, n = -sy, sx, 0.0, math.sqrt(sx * sx + sy * sy) if sz != 0.0 else 1.0
    jx, jy, jz = jx / n, jy / n, jz / n
    T[1, 0], T[1, 1], T[1, 2] = jx, jy, jz
    T[2, 0], T[2, 1], T[2, 2] = sx, sy, sz
    T[0, 0], T[0, 1], T[0, 2] = jy * sz - jz * sy, jz * sx - jx * sz, jx * sy - jy * sx  # j x k
    if g.law == EARTH_SIDE:  # the Earth-side target as it is (used with a large momentum: no terminal set)
        g.momentum_mode = 3
        return _error_to(x, g)
    # a large momentum (as `verify`'s) is shared between the wheels even where one could hold it, and
    # H_body goes to its place at the target first: a straight slew can carry H_body past a wheel's limit
    large = large_momentum(x, p, b)
    rolled = large or _wheel_load(T, g.Hh, p, b) > 0.0
    if rolled:
        Hh = g.Hh
        hk = Hh[0] * sx + Hh[1] * sy + Hh[2] * sz
        px, py, pz = Hh[0] - hk * sx, Hh[1] - hk * sy, Hh[2] - hk * sz
        hp = math.sqrt(px * px + py * py + pz * pz)
        if hp > 0.0:
            px, py, pz = px / hp, py / hp, pz / hp
            mx, my, mz = sy * pz - sz * py, sz * px - sx * pz, sx * py - sy * px  # k x h
            best = -np.inf
            ux = uy = uz = 0.0
            r = 1.0 / math.sqrt(2.0)
            for sa, sb in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):
                ix, iy, iz = r * (sa * px + sb * mx), r * (sa * py + sb * my), r * (sa * pz + sb * mz)
                # j = k x i
                cx, cy, cz = sy * iz - sz * iy, sz * ix - sx * iz, sx * iy - sy * ix
                e = cx * ex + cy * ey + cz * ez
                if sa * Hb0 >= 0.0 and -sb * Hb1 >= 0.0:  # H stays in its quadrant of (i_B, j_B) on the way
                    e += 20.0
                if e > best:
                    best, ux, uy, uz = e, ix, iy, iz
            T[0, 0], T[0, 1], T[0, 2] = ux, uy, uz
            T[1, 0], T[1, 1], T[1, 2] = sy * uz - sz * uy, sz * ux - sx * uz, sx * uy - sy * ux
    share = _rate_share(g)
    g.load = _wheel_load(T, g.Hh, p, b, share)
    tilted = False
    if (large or g.load > 0.0) and g.law != MOMENTUM and _tilted_target(sx, sy, sz, Hb0, Hb1, Hb2, share, p, b, g):
        tilted = True
        g.load = _wheel_load(T, g.Hh, p, b, share)
    g.momentum_mode = 1 if (g.law == MOMENTUM or g.load > 0.0) else (2 if tilted else 0)
    if g.momentum_mode == 1:  # H_body on the body diagonal d, the panel as near the sun as that allows
        Hh = g.Hh
        hn = math.sqrt(Hh[0] * Hh[0] + Hh[1] * Hh[1] + Hh[2] * Hh[2])
        if hn > 0.0:
            hx, hy, hz = Hh[0] / hn, Hh[1] / hn, Hh[2] / hn
            r3 = 1.0 / math.sqrt(3.0)
            d0, d1, d2 = math.copysign(r3, Hb0), math.copysign(r3, Hb1), math.copysign(r3, Hb2)
            hb = math.sqrt(Hb0 * Hb0 + Hb1 * Hb1 + Hb2 * Hb2)
            b0, b1, b2 = Hb0 / hb, Hb1 / hb, Hb2 / hb
            dq4 = _h_first(b0, b1, b2, d0, d1, d2, b, g)  # first stage: H_body straight to d
            if dq4 >= 0.0:
                return dq4
            ox, oy, oz = _sun_across(hx, hy, hz, sx, sy, sz, hx * sx + hy * sy + hz * sz)
            ck = math.sqrt(1.0 - d2 * d2)
            kx, ky, kz = d2 * hx + ck * ox, d2 * hy + ck * oy, d2 * hz + ck * oz  # k . h = d2
            vx, vy, vz = hx - d2 * kx, hy - d2 * ky, hz - d2 * kz  # = d0 i + d1 j, |v| = ck
            vx, vy, vz = vx / ck, vy / ck, vz / ck
            wx, wy, wz = ky * vz - kz * vy, kz * vx - kx * vz, kx * vy - ky * vx  # k x v
            al, be = d0 / ck, -d1 / ck
            ix, iy, iz = al * vx + be * wx, al * vy + be * wy, al * vz + be * wz
            T[0, 0], T[0, 1], T[0, 2] = ix, iy, iz
            T[1, 0], T[1, 1], T[1, 2] = ky * iz - kz * iy, kz * ix - kx * iz, kx * iy - ky * ix  # k x i
            T[2, 0], T[2, 1], T[2, 2] = kx, ky, kz
    elif rolled:  # a target that shares H between the wheels: H_body goes there first (as above)
        hb = math.sqrt(Hb0 * Hb0 + Hb1 * Hb1 + Hb2 * Hb2)
        Hh = g.Hh
        t0 = (T[0, 0] * Hh[0] + T[0, 1] * Hh[1] + T[0, 2] * Hh[2]) / hb  # H_body at the target, unit
        t1 = (T[1, 0] * Hh[0] + T[1, 1] * Hh[1] + T[1, 2] * Hh[2]) / hb
        t2 = (T[2, 0] * Hh[0] + T[2, 1] * Hh[1] + T[2, 2] * Hh[2]) / hb
        if g.law == CROSS and Hb2 * t2 < 0.0:
            dq4 = _cross(Hb0 / hb, Hb1 / hb, Hb2 / hb, t2, hb, share, p, b, g)
            if dq4 >= 0.0:
                return dq4
        dq4 = _h_first(Hb0 / hb, Hb1 / hb, Hb2 / hb, t0, t1, t2, b, g)
        if dq4 >= 0.0:
            return dq4
    return _error_to(x, g)


@numba.njit(**LEAF)
def _error_to(x: Array, g: np.void) -> float:
    """dq_v of the state x (19,) towards the attitude g.target into g.dq (g.q_c its quaternion), sign fixed
    so that dq4 >= 0; returns dq4."""
    from_matrix(g.target, g.q_c)
    q, c = x, g.q_c
    error_vector(q[0:4], c, g.dq)
    dq4 = q[3] * c[3] + q[0] * c[0] + q[1] * c[1] + q[2] * c[2]
    if dq4 < 0.0:
        dq4 = -dq4
        for a in range(3):
            g.dq[a] = -g.dq[a]
    return dq4


@numba.njit(**LEAF)
def sun_safe_command(x: Array, p: np.void, c: np.void, b: np.void, g: np.void, out: Array) -> None:
    """The backup law's command (3,) at state x (19,) into out, rad/s^2, inside U; p the plant model
    (PLANT_DTYPE), c the constraints (the box U), b the BACKUP_DTYPE record, g GATE_DTYPE scratch."""
    sun_safe_error(x, p, b, g)
    _rate_command(x, p, c, b, g, out)


@numba.njit(**LEAF)
def _rate_command(x: Array, p: np.void, c: np.void, b: np.void, g: np.void, out: Array) -> None:
    """`sun_safe_command` with g.dq and g.A already those of x (`sun_safe_error` ran on it).

    Per axis, the wheel acceleration that turns the rate towards w_ref (|w_ref| <= rate_limit) with the
    time constant, cancelling the drift (Euler's and the wheels' gyroscopic terms) held over the sample:
    the drift at the hold's middle (one predictor step of the held command, from x; the attitude's part,
    gravity gradient, at x), not at its start. The command changes the rates, and with a large momentum the
    gyroscopic torque with them, within the hold: cancelling the drift at its start overshot w_ref by up
    to 0.08 deg/s in one sample (docs/backup.md, "Hysteresis and the law's hold"). Each wheel's acceleration
    keeps its speed within psi_hold at the hold's end (psi_dot = u: the speed is linear in the hold): the
    speed the rollout checks, psi_limit, less one reading's error (docs/backup.md, "The wheels within their
    checked speed")."""
    lim = b.rate_limit_rad_s
    top = (1.0 - WHEEL_SPEED_RTOL) * b.psi_hold_rad_s
    omega_drift(x, g.A, p, g.wd)
    for it in range(2):
        for a in range(3):
            w_ref = -(b.kp / b.kd) * g.dq[a]
            w_ref = -lim if w_ref < -lim else (lim if w_ref > lim else w_ref)
            v = ((w_ref - x[4 + a]) / b.rate_time_constant_s - g.wd[a]) / p.control_gain[a]
            hi, lo = (top - x[7 + a]) / c.dt_s, (-top - x[7 + a]) / c.dt_s  # the wheel within psi_hold
            v = lo if v < lo else (hi if v > hi else v)
            m = c.u_reach_rad_s2[a]  # (every drive state reaches it: the rollouts do not track the drive)
            out[a] = -m if v < -m else (m if v > m else v)
        if it == 1:
            return
        half = 0.5 * c.dt_s
        for i in range(STATE_SIZE):
            g.xm[i] = x[i]
        for a in range(3):
            g.xm[4 + a] = x[4 + a] + half * (g.wd[a] + p.control_gain[a] * out[a])
            g.xm[7 + a] = x[7 + a] + half * out[a]
        omega_drift(g.xm, g.A, p, g.wd)


@numba.njit(**LEAF)
def settled(x: Array, p: np.void, b: np.void, g: np.void) -> bool:
    """x (19,) is in the backup law's terminal set: within SETTLED_ANGLE_RAD of the sun-safe attitude,
    every body rate within SETTLED_RATE_FRACTION w_max, and the wheels can hold the momentum at rest
    there (`_wheel_load` <= 0). Never in the momentum mode, at the large-momentum targets (the tilted and
    the EARTH_SIDE one: g.momentum_mode 2, 3) or in the TIGHT and CROSS variants (the panel may not charge
    enough and the sun moves on: their rollouts run the whole horizon)."""
    sun_safe_error(x, p, b, g)
    dq = g.dq
    if math.sqrt(dq[0] * dq[0] + dq[1] * dq[1] + dq[2] * dq[2]) > b.settled_sin_half_angle:
        return False
    for a in range(3):
        if abs(x[4 + a]) > b.settled_rate_rad_s:
            return False
    if g.momentum_mode or g.law == TIGHT or g.law == CROSS:
        # not a terminal set: the panel may not charge, the sun moves on (TIGHT, CROSS: their wheels keep
        # less than the rates' margin the set needs)
        return False
    return g.load <= 0.0


# ----------------------------------------------------------------------------- the check


@numba.njit(**LEAF)
def check_margins(p: np.void, c: np.void, out: Array) -> None:
    """What each constraint's h must keep in a rollout (M,), in h's units: the measurement-robust error
    bounds of the constraint record (0 without sensor errors: then h >= 0), so that a rollout from the
    measured state that keeps them keeps the true h >= 0 over the first sample, where the gate checks
    again. Angles: the attitude error (err_att, with the actuator's drift over a hold); T and E: their
    errors; a rate (or wheel speed) with error e: w_max^2 - (|w| + e)^2 >= 0 needs h >= 2 w_max e + e^2,
    e = the gyro's (tachometer's) error plus the actuator's (|G_a| err_u,a dt; err_u,a dt)."""
    for j in range(c.n_cones):
        out[j] = c.err_att_rad
    out[c.row_temperature] = c.err_T_K
    out[c.row_battery] = c.err_E_J
    for a in range(3):
        e = c.err_omega_axis_rad_s + abs(p.control_gain[a]) * c.err_u_rad_s2[a] * c.dt_s
        out[c.row_omega + a] = 2.0 * c.omega_max_rad_s * e + e * e
        e = wheel_speed_error(c, a)
        out[c.row_psi + a] = 2.0 * c.psi_max_rad_s * e + e * e


@numba.njit(**LEAF)
def rollout_margin(b: np.void, g: np.void, i: int) -> float:
    """What constraint i's h must keep in the rollout g runs (and the energy reserve that ends it): a
    candidate's margin where g.candidate (the hand-over's, `apply_measurement_margins`), else the backup
    law's (`check_margins`); the two are equal without sensor errors."""
    return b.candidate_margin[i] if g.candidate else b.margin[i]


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
    for j in range(S):
        if record:
            for i in range(STATE_SIZE):
                traj[g.checked, i] = subs[j, i]
        g.checked += 1
        safety_values(subs[j], g.t + c.dt_s * (j + 1) / S, p, c, g.ctx, g.h)
        for i in range(c.n_rows):
            gi = c.gains[i]
            if gi.enabled != 0 and gi.slack_weight == 0.0 and not g.h[i] >= rollout_margin(b, g, i):
                return False
    for i in range(STATE_SIZE):
        x[i] = subs[S - 1, i]
    g.t += c.dt_s
    return True


@numba.njit(**LEAF)
def backup_tail(f: np.void, g: np.void, traj: Array, record: bool) -> int:
    """The backup law (variant g.law) from g.x, one held command per sample, for horizon_steps samples or
    until `settled`: FAILED, HORIZON or SETTLED (`hold_sample` checks each sample)."""
    p, c, b = f.plant, f.constraints, f.backup
    for _ in range(b.horizon_steps):
        if settled(g.x, p, b, g):
            return SETTLED
        _rate_command(g.x, p, c, b, g, g.u)  # settled's sun_safe_error filled g.dq and g.A
        if not hold_sample(g.u, f, g, traj, record):
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
def reset(g: np.void) -> None:
    """Forget the committed plan and the drive's state (a new run starts: the wheels' drive at rest): the
    filter's only memory."""
    g.plan_steps = 0
    for a in range(3):
        g.drive[a] = 0.0
    g.plan_law = SUN_SAFE_VARIANT
    g.plan_n = g.plan_at = 0
    g.nominal_wait = 0
    g.filtered_wait = g.filtered_backoff = g.filtered_tries = 0
    g.has_next = g.plan_settled = g.plan_weak = 0
    g.reused = 0
    g.weak_law = -1


@numba.njit(**LEAF)
def commit(first_x: Array, law: int, settled_: bool, weak: bool, b: np.void, g: np.void) -> None:
    """Commit a verified plan of variant law whose state after its first sample is first_x: next_x is that
    state as the filter will receive it, the plan runs horizon_steps samples (`verify`, `commit_weak`; the
    nominal plan adds its own)."""
    predict(first_x, b, g, g.next_x)
    g.has_next = 1
    g.plan_settled = settled_
    g.plan_weak = weak
    g.plan_law = law
    g.plan_steps = b.horizon_steps


@numba.njit(**LEAF)
def variant_at(t: int, plan_law: int, large: bool) -> int:
    """The t-th variant (0 <= t < len(VARIANTS)) the gate tries: the committed plan's first, then the others in
    VARIANTS order; -1 for one it does not try (all but the sun-safe one only with a large momentum: the
    sun-safe attitude holds a small momentum, and the panel charges there)."""
    law = plan_law if t == 0 else (t - 1 if t - 1 < plan_law else t)
    return law if (law == SUN_SAFE_VARIANT or large) else -1


@numba.njit(**LEAF)
def verify(x: Array, u: Array, candidate: bool, f: np.void, g: np.void) -> bool:
    """Roll out from x with each variant of the backup law in turn, the committed plan's first, then the
    others in VARIANTS order (all but the sun-safe one only with a momentum |H| / D above psi_max - max
    J_a w_max / D: below it the sun-safe attitude holds H and the panel charges there, where the
    momentum mode may drain the battery into a dead end): the candidate u (candidate True) or the
    variant's own command at x (into u). With a small momentum the rollout must reach the terminal set
    (SETTLED: invariant, so the plan holds for good); with a large one, where the sun-safe attitude may not
    hold H, a horizon safe to its end with the battery's reserve at its end (`energy_reserve`) is accepted
    (HORIZON: the plan holds for the horizon only). On success the plan is committed (plan_law, plan_steps)
    and u holds the command to apply. The first variant safe to the horizon but short of the reserve is kept
    (weak_law, weak_u, weak_x: `commit_weak` commits it)."""
    b = f.backup
    p = f.plant
    large = large_momentum(x, p, b)
    g.weak_law = -1
    g.candidate = candidate
    for t in range(len(VARIANTS)):
        law = variant_at(t, g.plan_law, large)
        if law < 0:
            continue
        g.law = law
        if not candidate:
            sun_safe_command(x, f.plant, f.constraints, b, g, u)
        found = rollout(x, u, f, g, g.subs, False)
        if found == FAILED:  # how long it stayed safe (`gate`: where nothing verifies)
            if candidate:
                g.answer_lasted = max(g.answer_lasted, g.checked)
            elif g.checked > g.backup_lasted:
                g.backup_lasted = g.checked
                for a in range(3):
                    g.longest_u[a] = u[a]
        if found == SETTLED or (found == HORIZON and large):
            if found == HORIZON and not energy_reserve(g.x, p, f.constraints, b, g):
                if g.weak_law < 0:
                    g.weak_law = g.law
                    for i in range(STATE_SIZE):
                        g.weak_x[i] = g.first_x[i]
                    for a in range(3):
                        g.weak_u[a] = u[a]
                continue
            commit(g.first_x, g.law, found == SETTLED, False, b, g)
            return True
    return False


@numba.njit(**LEAF)
def commit_weak(g: np.void, b: np.void, u: Array) -> bool:
    """Commit the last `verify`'s plan that is safe to its horizon but short of the energy reserve, if it
    found one (its command into u); False if it found none."""
    if g.weak_law < 0:
        return False
    commit(g.weak_x, g.weak_law, False, True, b, g)
    for a in range(3):
        u[a] = g.weak_u[a]
    return True


@numba.njit(**LEAF)
def predict(x: Array, b: np.void, g: np.void, out: Array) -> None:
    """A predicted state x (19,) as the filter will receive it (`sensors.deliver`) into out: what a later
    call's state is compared with (`predicted`)."""
    deliver(x, b.interface, g.A, g.fields, out)


PREDICTION_RTOL = 1e-13
"""How far a received T, theta_S or CW entry may be from the plan's prediction (relative; theta_S: rad, modulo
2 pi) and still be on the plan: the interface's roundings (theta_S through atan2, a few ulps; the CW velocity
through A(q) and back) reach the prediction, which starts from a received state, and the true state's
reading, by different paths; measured differences are ulps (1e-16 relative), this is 1,000x that and far
below anything a barrier resolves. The attitude, rates and wheel speeds cross exactly and must match bit for
bit; E within two float32 ulps (`predicted`)."""
ANSWER_RTOL = 1e-12
"""How far (relative to the actuator limit) the filter's answer may be from the plan's answer for the same
sample and still be the plan's: the same ulp-level roundings reach the answer through the rows of the sun's
and the battery's constraints. The plan's own, verified answer is then applied (`pipeline.gate_call`)."""


@numba.njit(**LEAF)
def predicted(x: Array, pred: Array) -> bool:
    """The received state x (19,) is the plan's prediction pred (`predict`): the attitude, rates and wheel
    speeds bit for bit; the energy, which crosses the interface as a float32 (`sensors.encode`), the same
    float32 or the next one either side; T, theta_S (modulo 2 pi) and CW to PREDICTION_RTOL. A prediction
    starts from a received state, so it carries that reading's roundings (E: at most `interface_energy_error`
    where it matters, which the rollouts keep as the battery's margin; E's dynamics do not depend on E, so the
    offset stays what it was), and a reading on the other side of a rounding boundary is no departure from
    the plan."""
    for i in range(STATE_SIZE):
        d = x[i] - pred[i]
        if i == ENERGY:
            if not abs(d) <= 2.0 * ENERGY_RELATIVE_ERROR * abs(pred[i]):
                return False
        elif i == THETA_S:
            if not abs(d - 2.0 * math.pi * round(d / (2.0 * math.pi))) <= PREDICTION_RTOL:
                return False
        elif i >= TEMP:
            if not abs(d) <= PREDICTION_RTOL * (1.0 + abs(pred[i])):
                return False
        elif not (x[i] == pred[i] and math.copysign(1.0, x[i]) == math.copysign(1.0, pred[i])):
            return False
    return True


@numba.njit(**LEAF)
def same_answer(u: Array, v: Array, u_max: Array) -> bool:
    """u and v (3,) are the same answer to ANSWER_RTOL of the box u_max (3,) (NaN never)."""
    for a in range(3):
        if not abs(u[a] - v[a]) <= ANSWER_RTOL * u_max[a]:
            return False
    return True


@numba.njit(**LEAF)
def _follow_plan(x: Array, f: np.void, g: np.void, u: Array) -> None:
    """The committed plan's next command at x (its backup law) into u, and next_x := one sample of it from x
    (the state the plan predicts at the next call)."""
    g.law = g.plan_law
    sun_safe_command(x, f.plant, f.constraints, f.backup, g, g.u_backup)
    for i in range(STATE_SIZE):
        g.x[i] = x[i]
    g.checked = 0
    g.candidate = 0
    g.has_next = hold_sample(g.u_backup, f, g, g.subs, False)
    predict(g.x, f.backup, g, g.next_x)
    g.plan_steps -= 1
    for a in range(3):
        u[a] = g.u_backup[a]


@numba.njit(**LEAF)
def gate(x: Array, f: np.void, g: np.void, u: Array) -> int:
    """The gatekeeper at the state x (19,) with the candidate u (3,) (the ASIF's answer, replaced in place
    by the command to apply). Returns the GATE_NAMES code of what it did; g (GATE_DTYPE) carries the
    committed plan from call to call. Where the candidate fails at x, the committed plan reaches the
    terminal set and x is its predicted state (`predicted`, next_x: the filter's model is the plant's),
    the plan's next command (its backup law at x) is applied without a new rollout: its rollout verified
    it; next_x then becomes one sample of it from x. With a large momentum, plans safe to the horizon but
    short of the energy reserve (`energy_reserve`) come after those with it, in order: the backup law's
    (committed, `plan_weak`), the candidate's; at its predicted states a weak plan is followed without a
    rollout for nominal_steps samples (docs/backup.md, "The energy reserve"). Where nothing verifies and
    GATE_TOWARD_BACKUP is returned, u is left as it was: the caller answers g.longest_u (`_weak_candidate`)."""
    b = f.backup
    if b.law == NO_LAW:
        return GATE_OFF
    g.answer_lasted = g.backup_lasted = 0
    if (g.plan_weak and g.plan_steps > b.horizon_steps - b.nominal_steps and g.has_next
            and predicted(x, g.next_x)):
        # on a plan short of the energy reserve (the backup law, charging as well as the wheels allow): it
        # goes on, checked afresh every nominal_steps samples (a candidate is a sample off the same path)
        _follow_plan(x, f, g, u)
        return GATE_BACKUP
    if verify(x, u, True, f, g):
        return GATE_VERIFIED
    candidate_weak = g.weak_law >= 0  # safe to the horizon, short of the energy reserve
    if g.plan_steps > 0:  # the plan verified earlier: its next command is its backup law's, here
        on_plan = g.has_next and predicted(x, g.next_x)
        # a settled plan holds for good on its own trajectory; else a fresh plan from here (any variant),
        # one short of the energy reserve if that is all there is (the backup law charges best)
        if not (on_plan and g.plan_settled) and (verify(x, g.u_backup, False, f, g) or commit_weak(g, b, g.u_backup)):
            for a in range(3):
                u[a] = g.u_backup[a]
            return GATE_BACKUP
        if not on_plan:
            # off the plan (sensor errors, a model other than the plant's): its command is verified from a
            # state the spacecraft is not in; the candidate (its rows robust to the errors) instead
            g.plan_steps = 0
            g.has_next = 0
            return _weak_candidate(x, u, candidate_weak, f, g)
        if g.plan_settled:
            g.reused += 1
        _follow_plan(x, f, g, u)
        return GATE_BACKUP
    if verify(x, g.u_backup, False, f, g) or commit_weak(g, b, g.u_backup):
        for a in range(3):
            u[a] = g.u_backup[a]
        return GATE_BACKUP
    return _weak_candidate(x, u, candidate_weak, f, g)


@numba.njit(**LEAF)
def _weak_candidate(x: Array, u: Array, weak: bool, f: np.void, g: np.void) -> int:
    """The gate's last resort: the candidate u, committed as a plan safe to its horizon if it was one short of
    the energy reserve only (weak: verified again, now to commit it); else, where a variant's own command
    stayed safe longer in its rollout than the candidate in any of its (`verify` counted the substeps),
    GATE_TOWARD_BACKUP (the caller, `pipeline.filter_state`, answers that command, g.longest_u, instead of
    u_des); else the candidate, unverified."""
    if weak and (verify(x, u, True, f, g) or commit_weak(g, f.backup, u)):
        return GATE_VERIFIED
    if g.backup_lasted > g.answer_lasted:
        return GATE_TOWARD_BACKUP
    return GATE_UNVERIFIED


# ----------------------------------------------------------------------------- Python faces


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
        b["psi_limit_rad_s"] = math.sqrt(max(0.0, psi_max * psi_max - speed_margin))
        e = max(wheel_speed_error(c, a) for a in range(3))
        b["psi_hold_rad_s"] = max(0.0, float(b["psi_limit_rad_s"][0]) - e)


@numba.njit(**LEAF)
def _command(x: Array, fa: NDArray[np.void], ga: NDArray[np.void], out: Array) -> None:
    f = fa[0]
    sun_safe_command(x, f.plant, f.constraints, f.backup, ga[0], out)


@numba.njit(**LEAF)
def _rollout(x: Array, u0: Array, fa: NDArray[np.void], ga: NDArray[np.void], traj: Array) -> int:
    return rollout(x, u0, fa[0], ga[0], traj, True)


@numba.njit(**LEAF)
def _settled(x: Array, fa: NDArray[np.void], ga: NDArray[np.void]) -> bool:
    f = fa[0]
    return settled(x, f.plant, f.backup, ga[0])


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


__all__ = [
    "ANSWER_RTOL", "BACKUP_DTYPE", "CROSS", "EARTH_SIDE", "FAILED", "GATE_DTYPE", "HORIZON", "MOMENTUM", "NO_LAW",
    "PREDICTION_RTOL", "RATE_LIMIT_FRACTION", "RATE_TIME_CONSTANT_S", "RESERVE_STEP_S", "SETTLED", "SETTLED_ANGLE_RAD",
    "SETTLED_RATE_FRACTION", "SUN_SAFE", "SUN_SAFE_VARIANT", "TIGHT", "VARIANTS", "apply_measurement_margins",
    "backup_command", "backup_record", "backup_rollout", "backup_tail", "check_margins", "commit", "commit_weak",
    "energy_reserve", "gate", "hold_sample", "is_settled", "large_momentum", "predict", "predicted", "reset",
    "rollout", "rollout_margin", "same_answer", "settled", "sun_safe_command", "sun_safe_error", "variant_at", "verify",
]  # fmt: skip
