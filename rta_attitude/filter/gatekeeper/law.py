"""The backup law: towards the sun-safe attitude, compiled (a rate command tracked by a first-order loop).

The backup attitude, rows of A in Hill: the panel (`power.panel_normal_body`, the paper's +k_B) on the sun,
k_B = r_S; the secondary axis toward the component of its target perpendicular to the sun (the paper's
antenna +j_B toward the Earth: j_B = (r_E - (r_E . r_S) r_S) / |...|, z_Hill x r_S at a Sun-Earth
conjunction); i_B = j_B x k_B. The law's frame is the body frame (the wheels on its axes).

A rate command w_ref = clip(-(kp/kd) dq_v, +-RATE_LIMIT_FRACTION w_max) (dq = q (x) q_c^-1 with dq4 >= 0, kp,
kd the primary controller's gains) is tracked by a first-order rate loop with the plant's drift cancelled:

    u_a = clip(((w_ref_a - w_a) / RATE_TIME_CONSTANT_S - w_dot_drift_a) / (d w_dot_a / d u_a), +-U_a),

w_dot_drift = `omega_drift` of the filter's model (Euler, the wheels' gyroscopic term -w x (-s D psi),
gravity gradient if on): the gyroscopic feed-forward of w x H, H = J w - s D psi, of the viability
oracle's `sun_safe_ff` law (`viability.laws`, which tests use as the independent twin).

With a large momentum (|H| / D > psi_max - max J_a w_max / D) the target is rolled or tilted so that the
wheels can hold H at rest (VARIANTS: sun-safe, momentum mode, and with a large momentum the Earth-side target as
it is, the tight tilt and the tight tilt on the sun's side of a narrow corridor, reached through it). The
terminal set (`settled`): near the sun-safe attitude with small rates and a wheel momentum the wheels can hold
there, which the law keeps (docs/backup.md).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.base import MAX_ROWS
from rta_attitude.constraints.battery import eclipse_floor
from rta_attitude.constraints.cones import signed_h
from rta_attitude.constraints.geometry import angle_between
from rta_attitude.constraints.windows import OFF, window_at
from rta_attitude.dynamics.environment import sun_hill, target_hill
from rta_attitude.dynamics.quaternion import attitude_matrix, error_vector, from_matrix, product
from rta_attitude.dynamics.spacecraft import (
    angular_momentum,
    control_accel,
    omega_drift,
    rate_momentum,
    wheel_rate_momentum,
)
from rta_attitude.dynamics.state import ENERGY, OMEGA, STATE_SIZE, THETA_S
from rta_attitude.jit import LEAF

Array = NDArray[np.float64]
M = MAX_ROWS


RATE_LIMIT_FRACTION = 0.9
"""The backup law commands |w_ref_a| <= this fraction of w_max. The rollout checks the rate limit at every
substep, so a larger reserve would only slow the way out (the viability oracle's witnesses run the rates to
within 2e-6 rad/s of w_max)."""


RATE_TIME_CONSTANT_S = 2.0
"""Time constant of the backup law's rate loop, s."""


SETTLED_ANGLE_RAD = math.radians(5.0)
"""Terminal set: attitude error to the sun-safe attitude at most this, ..."""


SETTLED_RATE_FRACTION = 0.1
"""... every body rate at most this fraction of w_max, ..."""


# ... and every wheel can hold its share of the momentum at rest there (`_wheel_load`).
TILT_WHEEL_MARGIN = 0.002
"""The tilted sun-safe target keeps the panel-axis wheel this fraction of psi_max inside its limit. The rollout
checks the wheel speeds at every substep, so the reserve only absorbs rounding (the viability oracle's
witnesses keep the wheels 0.06 rad/s inside psi_max; a reserve of 0.01 lost runs they keep)."""


WHEEL_SPEED_RTOL = 1e-12
"""The backup law's command keeps each wheel at most (1 - this) psi_hold at its hold's end (`_rate_command`):
the rollout checks the speed at every substep, and the RK4 steps round in the last bits."""


CORRIDOR_HALF_WIDTH_RAD = math.radians(10.0)
"""Where H_body could cross the i_B-j_B plane only through corridors narrower than this either side of
the diagonal (a large momentum), the tilted target keeps the panel on its side of H."""


RESERVE_STEP_S = 10.0
"""Step of `energy_reserve`'s projection, s (the sun moves 0.6 deg in it; midpoint rule)."""
CONE_CLEARANCE_RAD = math.radians(5.0)
"""The law's target keeps every hard pointing constraint at least this clear of its cone (`keep_cones`), and the
terminal set asks it over the horizon ahead (`_clear_ahead`): a margin for the slew that reaches it and for the
sun's motion between looks."""
TILT_STEPS_RAD = tuple(math.radians(d) for d in (10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 75.0, 90.0))
"""`keep_cones`' tilts of the sun axis off its target, smallest first."""
TILT_AZIMUTHS = 12
"""`keep_cones`' rolls about the sun line and directions of each tilt (every 30 deg)."""
LOOKAHEAD_STEP_S = 100.0
"""`_clear_ahead` looks at the law's target every this long over the horizon (the sun moves 5.9 deg in it)."""


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


@numba.njit(**LEAF)
def large_momentum(x: Array, p: np.void, b: np.void) -> bool:
    """|J w - s D psi| / D of the state x (19,) above b.momentum_variant_rad_s (psi_max - max J_a w_max /
    D): a momentum the sun-safe attitude may not hold at rest (the gate's and the backup law's test)."""
    hh = 0.0
    for a in range(3):
        ha = angular_momentum(p, x, a) / p.wheel_inertia_kgm2
        hh += ha * ha
    return math.sqrt(hh) > b.momentum_variant_rad_s


@numba.njit(**LEAF)
def _wheel_load(T: Array, Hh: Array, p: np.void, b: np.void, share: float = 1.0) -> float:
    """The largest wheel speed the momentum Hh (Hill, 3) needs at rest in the attitude T (rows i_B, j_B,
    k_B in Hill), plus J_a share w_max / D (the rates the law may still command), minus psi_max: > 0 means
    the wheels cannot hold it."""
    if not p.wheels_on_axes:
        return _general_wheel_load(T, Hh, p, b, share)
    worst = -np.inf
    for a in range(3):
        ha = abs(T[a, 0] * Hh[0] + T[a, 1] * Hh[1] + T[a, 2] * Hh[2])
        v = (ha + rate_momentum(p, a) * share * b.omega_max_rad_s) / p.wheel_inertia_kgm2
        worst = max(worst, v)
    return worst - b.psi_limit_rad_s


@numba.njit(**LEAF)
def _general_wheel_load(T: Array, Hh: Array, p: np.void, b: np.void, share: float) -> float:
    """`_wheel_load` with the wheels off the body axes: wheel i holds (A^-1 H_body)_i / D at rest, and
    `wheel_rate_momentum` share w_max / D for the rates."""
    Ai = p.wheel_axes_inverse
    H0 = T[0, 0] * Hh[0] + T[0, 1] * Hh[1] + T[0, 2] * Hh[2]
    H1 = T[1, 0] * Hh[0] + T[1, 1] * Hh[1] + T[1, 2] * Hh[2]
    H2 = T[2, 0] * Hh[0] + T[2, 1] * Hh[1] + T[2, 2] * Hh[2]
    worst = -np.inf
    for i in range(3):
        hi = abs(Ai[i, 0] * H0 + Ai[i, 1] * H1 + Ai[i, 2] * H2)
        worst = max(worst, (hi + wheel_rate_momentum(p, i) * share * b.omega_max_rad_s) / p.wheel_inertia_kgm2)
    return worst - b.psi_limit_rad_s


@numba.njit(**LEAF)
def _vertex(Hb0: float, Hb1: float, Hb2: float, hn: float, share: float, p: np.void, b: np.void
            ) -> tuple[float, float, float]:
    """The momentum mode's place for H_body (unit, body axes) with the wheels off the body axes: a vertex of the
    momentum the wheels hold at rest, {H : |(A^-1 H)_i| <= c_i}, c_i = psi_limit D less wheel i's rates' share
    (`_wheel_load`'s test): d = A (s c) / |A (s c)| for a sign s_i per wheel, which holds |H| (hn, N m s) up to
    |A (s c)|, every wheel at its limit together. On the body axes the vertices are the diagonals (the paper's
    choice, the nearest); a skewed array's differ (three wheels tilted 20 deg toward [1, 1, 1]: |A s| = 2.46 along
    the diagonal, 1.40 for a mixed pattern), so the nearest may not hold |H| where another does. The vertex of the
    wheels' own pattern s = sign(A^-1 H_body) where it holds |H|, else the one of those that do nearest H_body,
    else the one that holds the most."""
    A, Ai, D = p.wheel_axes, p.wheel_axes_inverse, p.wheel_inertia_kgm2
    top = b.psi_limit_rad_s * D
    w = share * b.omega_max_rad_s
    c0 = max(top - wheel_rate_momentum(p, 0) * w, 1e-12 * top)
    c1 = max(top - wheel_rate_momentum(p, 1) * w, 1e-12 * top)
    c2 = max(top - wheel_rate_momentum(p, 2) * w, 1e-12 * top)
    own0 = Ai[0, 0] * Hb0 + Ai[0, 1] * Hb1 + Ai[0, 2] * Hb2
    own1 = Ai[1, 0] * Hb0 + Ai[1, 1] * Hb1 + Ai[1, 2] * Hb2
    own2 = Ai[2, 0] * Hb0 + Ai[2, 1] * Hb1 + Ai[2, 2] * Hb2
    hb = math.sqrt(Hb0 * Hb0 + Hb1 * Hb1 + Hb2 * Hb2)
    best = -np.inf
    out0 = out1 = out2 = 0.0
    for pattern in range(8):
        s0 = 1.0 if pattern & 1 else -1.0
        s1 = 1.0 if pattern & 2 else -1.0
        s2 = 1.0 if pattern & 4 else -1.0
        v0 = A[0, 0] * s0 * c0 + A[0, 1] * s1 * c1 + A[0, 2] * s2 * c2
        v1 = A[1, 0] * s0 * c0 + A[1, 1] * s1 * c1 + A[1, 2] * s2 * c2
        v2 = A[2, 0] * s0 * c0 + A[2, 1] * s1 * c1 + A[2, 2] * s2 * c2
        n = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if hn <= n:  # it holds |H|: the wheels' own pattern first, then the nearest
            own = s0 * own0 >= 0.0 and s1 * own1 >= 0.0 and s2 * own2 >= 0.0
            score = (4.0 if own else 2.0) + (v0 * Hb0 + v1 * Hb1 + v2 * Hb2) / (n * hb)
        else:
            score = (n - hn) / hn  # < 0: the one that holds the most
        if score > best:
            best, out0, out1, out2 = score, v0 / n, v1 / n, v2 / n
    return out0, out1, out2


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
    return top - rate_momentum(p, 0) * w, top - rate_momentum(p, 1) * w, top - rate_momentum(p, 2) * w


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
    Hb0, Hb1, Hb2 = angular_momentum(p, x, 0), angular_momentum(p, x, 1), angular_momentum(p, x, 2)
    for c in range(3):
        g.Hh[c] = A[0, c] * Hb0 + A[1, c] * Hb1 + A[2, c] * Hb2
    return Hb0, Hb1, Hb2


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
    ex, ey, ez = b.secondary[0], b.secondary[1], b.secondary[2]
    rad = b.radiator  # the thermal face, in the law's frame (the paper's -j_B)
    r1, r2 = c1 / c12, c2 / c12  # H_perp shared in proportion to what each wheel can take
    best = -np.inf
    ux = uy = uz = 0.0
    for sa, sg in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):
        ix, iy, iz = sa * r1 * px + sg * r2 * mx, sa * r1 * py + sg * r2 * my, sa * r1 * pz + sg * r2 * mz
        jx, jy, jz = ky * iz - kz * iy, kz * ix - kx * iz, kx * iy - ky * ix  # j = k x i
        score = jx * ex + jy * ey + jz * ez
        sees = rad[0] * (ix * sx + iy * sy + iz * sz) + rad[1] * (jx * sx + jy * sy + jz * sz)
        if sees + rad[2] * (kx * sx + ky * sy + kz * sz) > 1e-12:  # the radiator would see the sun
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
    diagonal d = sign(H_body) / sqrt(3) (each wheel takes |H| / sqrt(3); with the wheels off the body axes the
    array's vertex that holds H, `_vertex`) turned about H to bring k_B nearest the sun (k_B . H / |H| = d_3:
    k_B in the plane of H and r_S). While H_body is more than
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
    ex, ey, ez = b.secondary[0], b.secondary[1], b.secondary[2]  # the secondary axis' target (the Earth)
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
        keep_cones(x, p, b, g)
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
            if p.wheels_on_axes:
                r3 = 1.0 / math.sqrt(3.0)
                d0, d1, d2 = math.copysign(r3, Hb0), math.copysign(r3, Hb1), math.copysign(r3, Hb2)
            else:
                d0, d1, d2 = _vertex(Hb0, Hb1, Hb2, hn, share, p, b)
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
    keep_cones(x, p, b, g)
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
def law_state(x: Array, b: np.void, g: np.void) -> None:
    """g.xl := the body-frame state x (19,) in the law's frame (`records.law_axes`: its rows the sun axis' and
    secondary axis' complement, the secondary axis, the sun axis, in body axes): q' = q_P (x) q, omega' =
    P omega, psi' = P psi where the wheels are on the body axes (else they keep their order, and the law's plant
    has their axes turned); a copy where the frames are the same."""
    for i in range(STATE_SIZE):
        g.xl[i] = x[i]
    if not b.permuted:
        return
    product(b.law_quat, x[0:4], g.xl[0:4])
    P = b.law_axes
    for a in range(3):
        g.xl[4 + a] = P[a, 0] * x[4] + P[a, 1] * x[5] + P[a, 2] * x[6]
        if b.permute_wheels:
            g.xl[7 + a] = P[a, 0] * x[7] + P[a, 1] * x[8] + P[a, 2] * x[9]


@numba.njit(**LEAF)
def _to_body(b: np.void, u: Array, out: Array) -> None:
    """out := the law-frame command u (3,) for the body's wheels (P^T u where they turned with the frame)."""
    P = b.law_axes
    for a in range(3):
        out[a] = (P[0, a] * u[0] + P[1, a] * u[1] + P[2, a] * u[2]) if b.permute_wheels else u[a]


@numba.njit(**LEAF)
def sun_safe_command(x: Array, c: np.void, b: np.void, g: np.void, out: Array) -> None:
    """The backup law's command (3,) at the body-frame state x (19,) into out, rad/s^2, inside U; c the
    constraints (the hold), b the BACKUP_DTYPE record (the law's plant model and frame), g GATE_DTYPE
    scratch (g.t: the time, for the cones' windows)."""
    law_state(x, b, g)
    sun_safe_error(g.xl, b.law_plant, b, g)
    _rate_command(g.xl, b.law_plant, c, b, g, g.ul)
    _to_body(b, g.ul, out)


@numba.njit(**LEAF)
def continue_command(c: np.void, b: np.void, g: np.void, out: Array) -> None:
    """`sun_safe_command` at the state `settled` just looked at (g.xl, g.dq, g.A are its)."""
    _rate_command(g.xl, b.law_plant, c, b, g, g.ul)
    _to_body(b, g.ul, out)


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
            g.ua[a] = (w_ref - x[4 + a]) / b.rate_time_constant_s - g.wd[a]  # the acceleration it asks of u
        for a in range(3):
            v = _wheel_for(g.ua, p, a)
            hi, lo = (top - x[7 + a]) / c.dt_s, (-top - x[7 + a]) / c.dt_s  # the wheel within psi_hold
            v = lo if v < lo else (hi if v > hi else v)
            m = b.u_reach_rad_s2[a]  # (every drive state reaches it: the rollouts do not track the drive)
            out[a] = -m if v < -m else (m if v > m else v)
        if it == 1:
            return
        half = 0.5 * c.dt_s
        for i in range(STATE_SIZE):
            g.xm[i] = x[i]
        for a in range(3):
            g.xm[4 + a] = x[4 + a] + half * control_accel(g.wd, out, p, a)
            g.xm[7 + a] = x[7 + a] + half * out[a]
        omega_drift(g.xm, g.A, p, g.wd)


@numba.njit(**LEAF, inline="always")
def _wheel_for(acc: Array, p: np.void, a: int) -> float:
    """Wheel a's acceleration of u = G^-1 acc (acc (3,): the body's angular acceleration asked of u), rad/s^2:
    acc_a / G_a where diagonal; in general G^-1 = A^-1 J / (s D)."""
    if p.diagonal:
        return acc[a] / p.control_gain[a]
    return _general_wheel_for(acc, p, a)


@numba.njit(**LEAF)
def _general_wheel_for(acc: Array, p: np.void, a: int) -> float:
    """`_wheel_for` in general."""
    J, Ai = p.inertia_matrix, p.wheel_axes_inverse
    v = 0.0
    for b in range(3):
        v += Ai[a, b] * (J[b, 0] * acc[0] + J[b, 1] * acc[1] + J[b, 2] * acc[2])
    return v / (p.torque_sign * p.wheel_inertia_kgm2)


@numba.njit(**LEAF)
def settled(x: Array, b: np.void, g: np.void) -> bool:
    """The body-frame state x (19,) is in the backup law's terminal set (`_terminal`; g.xl, g.dq, g.A are then
    x's in the law's frame: `continue_command` goes on from them)."""
    law_state(x, b, g)
    return _terminal(g.xl, b.law_plant, b, g)


@numba.njit(**LEAF)
def at_rest(x: Array, b: np.void) -> bool:
    """Every body rate of x (19) within the terminal set's, SETTLED_RATE_FRACTION w_max (a per-axis bound alike on
    every axis, so in the body's frame and the law's)."""
    for a in range(3):
        if abs(x[OMEGA.start + a]) > b.settled_rate_rad_s:
            return False
    return True


@numba.njit(**LEAF)
def _terminal(x: Array, p: np.void, b: np.void, g: np.void) -> bool:
    """x (19, the law's frame) is in the backup law's terminal set: within SETTLED_ANGLE_RAD of the sun-safe
    attitude, every body rate within SETTLED_RATE_FRACTION w_max, and the wheels can hold the momentum at rest
    there (`_wheel_load` <= 0); with an eclipse, E - E_min at or above the floor for the shadow ahead
    (`constraints.battery.eclipse_floor`: held at the sun-safe attitude, E gains on it in sunlight and keeps
    its distance in the shadow); and the law's targets keep every hard pointing constraint clear over the
    horizon ahead as the sun moves on (`_clear_ahead`). Never in the momentum mode, at the large-momentum
    targets (the tilted and the EARTH_SIDE one: g.momentum_mode 2, 3) or in the TIGHT and CROSS variants (the
    panel may not charge enough and the sun moves on: their rollouts run the whole horizon)."""
    sun_safe_error(x, p, b, g)
    dq = g.dq
    if math.sqrt(dq[0] * dq[0] + dq[1] * dq[1] + dq[2] * dq[2]) > b.settled_sin_half_angle:
        return False
    if not at_rest(x, b):
        return False
    if g.momentum_mode or g.law == TIGHT or g.law == CROSS:
        # not a terminal set: the panel may not charge, the sun moves on (TIGHT, CROSS: their wheels keep
        # less than the rates' margin the set needs)
        return False
    if not g.load <= 0.0:
        return False
    if p.eclipse_half_arc_rad > 0.0 and not x[ENERGY] - b.energy_min_J >= eclipse_floor(x[THETA_S], p)[0]:
        return False  # short of the shadow ahead: the panel on the sun gains on the floor only above it
    if b.n_keep == 0 or _clear_ahead(x, p, b, g):
        return True
    sun_safe_error(x, p, b, g)  # (g.dq, g.A and the target are x's again for `continue_command`)
    return False


@numba.njit(**LEAF)
def _cone_margin(x: Array, p: np.void, b: np.void, g: np.void, T: Array) -> float:
    """The smallest h (rad) of the hard pointing constraints in force at g.t with the body at the attitude T
    (rows: the law frame's axes in Hill), the targets where x (the law's frame) has them; +inf with none. A
    windowed one counts inside its windows, and ahead of one its ramped barrier h + rho(t) (what the filter and
    the rollouts keep there, `cones.cone_h`): the target turns into the cone as the window nears."""
    worst = math.inf
    for k in range(b.n_keep):
        e = b.cones[b.keep[k]]
        rho = 0.0
        if e.n_windows > 0:
            phase, rho, _ = window_at(e, g.t)
            if phase == OFF:
                continue
        r0, r1, r2, _, _, _, _, _, _ = target_hill(e.target, e.vector, x[THETA_S], p.sun_cos_beta, p.sun_sin_beta,
                                                   p.mean_motion_rad_s)
        a = b.keep_axes[k]  # the boresight in the law's frame
        bx = a[0] * T[0, 0] + a[1] * T[1, 0] + a[2] * T[2, 0]
        by = a[0] * T[0, 1] + a[1] * T[1, 1] + a[2] * T[2, 1]
        bz = a[0] * T[0, 2] + a[1] * T[1, 2] + a[2] * T[2, 2]
        h = signed_h(e, angle_between(bx, by, bz, r0, r1, r2))
        worst = min(worst, h + rho if e.n_windows > 0 else h)
    return worst


@numba.njit(**LEAF)
def _rotate_rows(T: Array, ax: float, ay: float, az: float, angle: float, out: Array) -> None:
    """out := the rows of T (3, 3) rotated by angle about the unit axis a (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    for r in range(3):
        vx, vy, vz = T[r, 0], T[r, 1], T[r, 2]
        d = ax * vx + ay * vy + az * vz
        cx, cy, cz = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
        out[r, 0] = vx * c + cx * s + ax * d * (1.0 - c)
        out[r, 1] = vy * c + cy * s + ay * d * (1.0 - c)
        out[r, 2] = vz * c + cz * s + az * d * (1.0 - c)


@numba.njit(**LEAF)
def keep_cones(x: Array, p: np.void, b: np.void, g: np.void) -> None:
    """Where the law's target g.target puts a hard pointing constraint within CONE_CLEARANCE_RAD of its cone
    (a star tracker the sun-safe attitude turns toward the Earth), the nearest attitude that keeps them all
    clear: first the target rolled about the sun line (the panel stays on the sun), then tilted off it by
    TILT_STEPS_RAD in TILT_AZIMUTHS directions, the smallest tilt that clears every cone (of those, the one
    nearest the body's attitude now, g.A); the one with the most margin where none clears. Unchanged where
    nothing is near."""
    if b.n_keep == 0:
        return
    T = g.target
    if _cone_margin(x, p, b, g, T) >= b.cone_clearance_rad:
        return
    sx, sy, sz = T[2, 0], T[2, 1], T[2, 2]  # (the sun axis' target: the sun, or where the momentum tilted it)
    # e1, e2: perpendicular to the sun axis' target
    if abs(sz) < 0.9:
        e1x, e1y, e1z = -sy, sx, 0.0
    else:
        e1x, e1y, e1z = 0.0, -sz, sy
    n1 = math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
    e1x, e1y, e1z = e1x / n1, e1y / n1, e1z / n1
    e2x, e2y, e2z = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    best_m = -math.inf  # the most margin of any candidate (where none clears)
    best_near = -math.inf  # the nearest clear candidate's closeness to the body's attitude (trace of T A^T)
    found = False
    trial, best, base = g.trial, g.best, g.base
    A = g.A  # the body's attitude now (the law's frame): among clear candidates, the nearest, so that the target
    # does not jump where the nominal one does (its roll flips as the sun crosses the Earth line)
    # the tilts turn the roll about the sun line nearest the body's attitude (a tilt cannot undo the nominal
    # target's roll flip: tilts of the flipped target would all be half a turn from the body)
    base_near = -math.inf
    for j in range(TILT_AZIMUTHS):
        _rotate_rows(T, sx, sy, sz, 2.0 * math.pi * j / TILT_AZIMUTHS, trial)
        near = 0.0
        for r in range(3):
            near += trial[r, 0] * A[r, 0] + trial[r, 1] * A[r, 1] + trial[r, 2] * A[r, 2]
        if near > base_near:
            base_near = near
            for r in range(3):
                for q in range(3):
                    base[r, q] = trial[r, q]
    for level in range(len(TILT_STEPS_RAD) + 1):
        for j in range(TILT_AZIMUTHS):
            phi = 2.0 * math.pi * j / TILT_AZIMUTHS
            if level == 0:  # a roll about the sun line
                _rotate_rows(T, sx, sy, sz, phi, trial)
            else:
                c, s = math.cos(phi), math.sin(phi)
                _rotate_rows(base, c * e1x + s * e2x, c * e1y + s * e2y, c * e1z + s * e2z,
                             TILT_STEPS_RAD[level - 1], trial)
            m = _cone_margin(x, p, b, g, trial)
            near = 0.0
            for r in range(3):
                near += trial[r, 0] * A[r, 0] + trial[r, 1] * A[r, 1] + trial[r, 2] * A[r, 2]
            if m >= b.cone_clearance_rad:
                if near > best_near:
                    best_near = near
                    found = True
                    for r in range(3):
                        for q in range(3):
                            best[r, q] = trial[r, q]
            elif not found and m > best_m:
                best_m = m
                for r in range(3):
                    for q in range(3):
                        best[r, q] = trial[r, q]
        if found:
            break
    for r in range(3):
        for q in range(3):
            T[r, q] = best[r, q]


@numba.njit(**LEAF)
def _clear_ahead(x: Array, p: np.void, b: np.void, g: np.void) -> bool:
    """The law's target (`sun_safe_error`, with `keep_cones`) keeps every hard pointing constraint clear (h >=
    CONE_CLEARANCE_RAD) at the times the sun reaches over the horizon ahead, every LOOKAHEAD_STEP_S (the
    momentum, fixed in inertial space, as now). Changes g's scratch (the caller restores it)."""
    t0 = g.t
    step = LOOKAHEAD_STEP_S
    k_max = int(b.horizon_steps * b.dt_s / step)
    ok = True
    for k in range(1, k_max + 1):
        for i in range(STATE_SIZE):
            g.xa[i] = x[i]
        g.xa[THETA_S] = x[THETA_S] - p.mean_motion_rad_s * step * k
        g.t = t0 + step * k
        sun_safe_error(g.xa, p, b, g)
        if not _cone_margin(g.xa, p, b, g, g.target) >= b.cone_clearance_rad:
            ok = False
            break
    g.t = t0
    return ok


def backup_attitude_conflicts(cfg: Config, samples: int = 720) -> list[tuple[str, float, list[tuple[float, float]]]]:
    """Where the backup attitude itself (small momentum: the sun axis on the sun, the secondary axis toward its
    target's part across the sun line) puts a hard pointing constraint inside its cone, over a full turn of the
    sun (theta_S in [0, 360) deg, every 360 / samples deg): [(name, the smallest h there in deg, the theta_S
    ranges in deg)]. There the law turns its target off the cone (`keep_cones`); check-config warns of it."""
    import numpy as np

    from rta_attitude.dynamics.environment import FIXED_HILL, target_direction, target_kind

    o = cfg.filter
    theta = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    k = target_direction(target_kind("sun")[0], np.zeros(3), theta, cfg.environment.sun_beta_rad)
    e = np.array(FIXED_HILL[o.backup_secondary_target])
    j = e - (k @ e)[:, None] * k
    j /= np.maximum(np.linalg.norm(j, axis=1, keepdims=True), 1e-12)
    i = np.cross(j, k)
    P = np.array([np.cross(o.backup_secondary_axis_body, o.backup_sun_axis_body), o.backup_secondary_axis_body,
                  o.backup_sun_axis_body], dtype=float)
    out = []
    for c in cfg.pointing:
        if not c.gains.enabled or c.gains.slack_weight > 0:
            continue
        w = P @ np.array(c.boresight_body)  # in the law's frame: rows i, j, k of the target
        axis = w[0] * i + w[1] * j + w[2] * k
        kind, vec = target_kind(c.target)
        r = target_direction(kind, np.array(c.target_vector or vec), theta, cfg.environment.sun_beta_rad)
        th = np.arccos(np.clip(np.sum(axis * r, axis=1), -1.0, 1.0))
        h = c.half_angle_rad - th if c.keep_in else th - c.half_angle_rad
        bad = h < 0.0
        if not bad.any():
            continue
        deg = np.degrees(theta)
        edges = np.flatnonzero(np.diff(np.concatenate([[False], bad, [False]]).astype(int)))
        ranges = [(float(deg[a]), float(deg[b - 1])) for a, b in zip(edges[::2], edges[1::2])]
        if len(ranges) > 1 and ranges[0][0] == 0.0 and ranges[-1][1] >= deg[-1]:  # (wraps through 0)
            ranges = [(ranges[-1][0], ranges[0][1]), *ranges[1:-1]]
        out.append((c.name, float(np.degrees(h.min())), ranges))
    return out
