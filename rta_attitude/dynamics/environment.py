"""Where things are: the directions a pointing constraint, the thermal node and the panel aim at, written once.

Frames. Hill H: +x radial out, +y along-track (the velocity of a circular orbit), +z orbit normal. The
inertial frame I used for targets fixed in space: the Hill frame at theta_S = 0, i.e. x_I toward the sun's
direction projected on the orbit plane, z_I the orbit normal. A vector fixed in I reads in Hill as
R_z(theta_S) v_I, and theta_S_dot = -n (the Hill frame turns at the mean motion n against the stars).

Targets (`TARGETS`, the names a configuration uses):

    sun           r_S = R_z(theta_S) [cos beta, 0, sin beta]       beta: the sun's angle out of the orbit
                  = [cos beta cos theta_S, cos beta sin theta_S, sin beta]   plane (0 in the paper)
    earth         [-1, 0, 0] (Hill: nadir, the paper's ground station)
    orbit_normal  [0, 0, 1] (Hill)
    velocity      [0, 1, 0] (Hill)
    hill          a unit vector fixed in Hill (configured)
    inertial      a unit vector fixed in I (configured)

Derivatives. The barriers need each target's first two *inertial* time derivatives (A_dot = -[omega x] A
with omega the inertial body rate). For a vector fixed in I, its Hill components move with theta_S:

    r_dot = n [r_y, -r_x, 0],   r_ddot = -n^2 [r_x, r_y, 0]          (Hill-frame derivatives)

and one fixed in Hill has none. The attitude kinematics may treat the Hill frame as turning at n_f about z
(`environment.rotating_hill`; 0 as the paper); then, with W = [0, 0, n_f],

    r' = r_dot + W x r,   r'' = r_ddot + 2 W x r_dot + W x (W x r)

(`inertial_rates`). With n_f = n a vector fixed in I has r' = 0 exactly, and one fixed in Hill turns.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.jit import LEAF

Array = NDArray[np.float64]

TARGETS: tuple[str, ...] = ("sun", "earth", "orbit_normal", "velocity", "hill", "inertial")
"""What a pointing constraint's boresight is measured against (`constraints.pointing.*.target`)."""
SUN, EARTH, HILL_FIXED, INERTIAL_FIXED = 0, 1, 2, 3
"""How a target moves, as the compiled code reads it (`target_kind`): the sun; the Earth (nadir); any other
vector fixed in Hill; a vector fixed in the inertial frame I."""
EARTH_HILL = (-1.0, 0.0, 0.0)
"""Unit vector from the spacecraft to the Earth (nadir, the paper's ground station) in Hill: -x."""
ORBIT_NORMAL_HILL = (0.0, 0.0, 1.0)
VELOCITY_HILL = (0.0, 1.0, 0.0)
"""Along-track: the velocity direction of a circular orbit, in Hill."""
FIXED_HILL = {"earth": EARTH_HILL, "orbit_normal": ORBIT_NORMAL_HILL, "velocity": VELOCITY_HILL}
"""The named targets fixed in Hill."""


def target_kind(target: str) -> tuple[int, tuple[float, float, float]]:
    """(kind code, vector) of a named target; 'hill' and 'inertial' take the configured vector (returned as 0)."""
    if target == "sun":
        return SUN, (0.0, 0.0, 0.0)
    if target == "earth":
        return EARTH, EARTH_HILL
    if target in FIXED_HILL:
        return HILL_FIXED, FIXED_HILL[target]
    if target == "hill":
        return HILL_FIXED, (0.0, 0.0, 0.0)
    if target == "inertial":
        return INERTIAL_FIXED, (0.0, 0.0, 0.0)
    raise ValueError(f"unknown target {target!r}; known: {', '.join(TARGETS)}")


@numba.njit(**LEAF, inline="always")
def sun_hill(theta_S_rad: float, cos_beta: float, sin_beta: float) -> tuple[float, float, float]:
    """The unit vector to the sun in Hill, [cos beta cos theta_S, cos beta sin theta_S, sin beta] (SPEC sec. 2,
    [resolved]: the paper prints [cos, cos, 0], not a unit vector; its beta is 0)."""
    return cos_beta * math.cos(theta_S_rad), cos_beta * math.sin(theta_S_rad), sin_beta


def sun_direction(theta_S_rad: float | Array, beta_rad: float = 0.0) -> Array:
    """The sun's unit vector in Hill (..., 3) of theta_S (...), rad: the numpy face of `sun_hill`."""
    th = np.asarray(theta_S_rad, dtype=float)
    cb, sb = math.cos(beta_rad), math.sin(beta_rad)
    return np.stack([cb * np.cos(th), cb * np.sin(th), np.full_like(th, sb)], axis=-1)


def inertial_to_hill(v: Array, theta_S_rad: float | Array) -> Array:
    """A vector fixed in the inertial frame I (3,) in Hill (..., 3) at theta_S (...): R_z(theta_S) v."""
    th = np.asarray(theta_S_rad, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1], np.full_like(th, v[2])], axis=-1)


def target_direction(kind: int, vector: Array, theta_S_rad: float | Array, beta_rad: float = 0.0) -> Array:
    """A target's unit vector in Hill (..., 3) at theta_S (...) (the numpy face of `target_hill`)."""
    if kind == SUN:
        return sun_direction(theta_S_rad, beta_rad)
    if kind == INERTIAL_FIXED:
        return inertial_to_hill(np.asarray(vector, dtype=float), theta_S_rad)
    th = np.asarray(theta_S_rad, dtype=float)
    return np.broadcast_to(np.asarray(vector, dtype=float), (*th.shape, 3)).copy()


@numba.njit(**LEAF, inline="always")
def sunlit(sx: float, shadow: float) -> float:
    """1.0 in sunlight, 0.0 in the Earth's cylindrical shadow: sx = r_S . x_Hill (the sun's radial component in
    Hill), shadow = `config.schema.Environment.shadow_sx` (-cos rho; -inf without the eclipse)."""
    return 0.0 if sx < shadow else 1.0


def sunlit_fraction(theta_S_rad: float | Array, beta_rad: float, shadow: float) -> Array:
    """`sunlit` of theta_S (...) (the numpy face)."""
    sx = math.cos(beta_rad) * np.cos(np.asarray(theta_S_rad, dtype=float))
    return np.where(sx < shadow, 0.0, 1.0)


@numba.njit(**LEAF, inline="always")
def target_hill(kind: int, v: Array, theta_S_rad: float, cos_beta: float, sin_beta: float, n: float,
                ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """A target's unit vector r in Hill and its Hill-frame derivatives r_dot, r_ddot (module docstring), as nine
    floats: kind SUN (v unused), EARTH or HILL_FIXED (v: the vector in Hill), INERTIAL_FIXED (v in I).
    Scalars, not arrays, so that the compiler keeps them in registers (the barriers call this for every
    target of every state)."""
    if kind == SUN:
        r0, r1, r2 = sun_hill(theta_S_rad, cos_beta, sin_beta)
    elif kind == INERTIAL_FIXED:
        c, s = math.cos(theta_S_rad), math.sin(theta_S_rad)
        r0, r1, r2 = c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]
    else:
        return v[0], v[1], v[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return r0, r1, r2, n * r1, -n * r0, 0.0, -(n * n) * r0, -(n * n) * r1, 0.0


@numba.njit(**LEAF, inline="always")
def inertial_rates(r0: float, r1: float, rd0: float, rd1: float, rdd0: float, rdd1: float, nf: float,
                   ) -> tuple[float, float, float, float]:
    """The x, y components of the Hill-frame derivatives (rd, rdd) of a vector r made inertial, for a Hill frame
    turning at nf about z: r' = r_dot + W x r, r'' = r_ddot + 2 W x r_dot + W x (W x r), W = [0, 0, nf]
    (z components unchanged). Returns (rd0, rd1, rdd0, rdd1)."""
    if nf == 0.0:
        return rd0, rd1, rdd0, rdd1
    a0 = rdd0 - 2.0 * nf * rd1 - nf * nf * r0
    a1 = rdd1 + 2.0 * nf * rd0 - nf * nf * r1
    return rd0 - nf * r1, rd1 + nf * r0, a0, a1


__all__ = [
    "EARTH", "EARTH_HILL", "FIXED_HILL", "HILL_FIXED", "INERTIAL_FIXED", "ORBIT_NORMAL_HILL", "SUN", "TARGETS",
    "VELOCITY_HILL", "inertial_rates", "inertial_to_hill", "sun_direction", "sun_hill", "sunlit", "sunlit_fraction",
    "target_direction", "target_hill", "target_kind",
]  # fmt: skip
