"""The ASIF over an array of N reaction wheels: the QP in the N wheel accelerations.

Any array moves the body as three wheels on the body axes would, holding the momentum A psi and driven by A u
(A (3, N): the spin axes as columns; `spacecraft.wheel_spin_axes_body`). So every constraint of the body (the
pointing cones, temperature, battery, the rates, the angular-acceleration limit) is the three-wheel filter's row
evaluated at the *virtual* state (psi_virtual = A psi) of the *virtual* vehicle (`Config.virtual_vehicle`: the same
body with three wheels on its axes), and its gain in u is that row's gain times A. The wheels' own constraints are
per wheel: |psi_i| <= psi_keep (psi_dot_i = u_i, the rows of `constraints.wheel_speed`), the box |u_i| <= U_i (0
for a failed wheel), and in the `robust` preset each wheel's one-step zero-order-hold interval. Then

    min_{u, s}  |u - u_target|^2 + |s|^2      u (N,): the wheel accelerations, rad/s^2
    s.t.        rows of the body (gain A) and of each wheel, as `filter.qp` builds them, the box per wheel

solved by the same solvers (`filter.qp.solve`: the exact active-set method or proxsuite) with the same
fallback policies (`prioritize`: the least important level gives way first). The virtual vehicle's box is
|(A u)_a| <= sum_i |A_ai| U_i (with its angular-acceleration bound where the body is on principal axes): rows of
the QP here, with the rate's ZOH intervals it carries in the robust preset; its derived margins (sampled-data,
inertia) take that box, which holds every body acceleration the array can give (a bound, not the set).

The null space of A (the wheel accelerations that do not turn the body) is used, not wasted: u_target is the
primary's u_des plus a null-space law (`null_target`) that moves the wheels along the null space to where the
slowest is fastest with none beyond a cap (`null_space_bias` of psi_keep), so no wheel sits at or crosses zero
speed (stiction, the tachometer's dead band) while the body's momentum allows, and where it needs more than the
cap, to where the fastest is slowest (away from the limit); at the rate `null_space_gain_1_s`. The QP keeps
every limit whatever the law asks. (A law on u_des rather than a secondary objective in the QP: the QP's answer
stays the minimal change of what it is asked, as the paper's filter, and the law is one line to replace.)

This path takes an array without the gatekeeper, sensor errors or a transport delay (`ArrayFilter` refuses them
in one line); three wheels take `filter.asif` (every path, the paper's bit for bit). With the paper's three
wheels this QP is the three-wheel filter's: the tests check they answer alike (docs/wheels.md).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints.base import GAIN_DTYPE, MAX_ROWS, hold_interval
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.rows import safety_values
from rta_attitude.constraints.wheel_speed import hold_bounds
from rta_attitude.dynamics.state import STATE_SIZE, state_size, wheel_column
from rta_attitude.errors import ConfigError, SolverError
from rta_attitude.filter.active_set import BIG
from rta_attitude.filter.asif import FilterCounters, FilterResult
from rta_attitude.filter.outcome import (
    FALLBACK,
    GATE_OFF,
    HOLD,
    INVALID_STATE,
    NO_FALLBACK,
    NON_FINITE_U_DES,
    NOT_SOLVED,
    PASS,
    POLICY_ACTED,
    PRIORITIZE,
    RAISE,
    SOFTEN,
    SOLVE_OK,
    SOLVED,
)
from rta_attitude.filter.qp import (
    ACTIVE_MULTIPLIER,
    DISTANCE,
    HARD,
    MIN_ROW_NORM,
    NO_LEVEL,
    OFF,
    SLACKED,
    prepare,
    solve,
)
from rta_attitude.filter.records import filter_record, new_workspace
from rta_attitude.jit import JIT, LEAF

Array = NDArray[np.float64]

MAX_WHEELS = 8
"""The most wheels `ArrayFilter` takes (the capacity of its records)."""
MAX_ARRAY_ROWS = MAX_ROWS - 3 + MAX_WHEELS
"""Constraints of an array: the body's (the three-wheel set less its three wheel rows), then one per wheel."""


ARRAY_DTYPE = np.dtype([
    ("n", np.int64),                           # N, the wheels
    ("axes", np.float64, (3, MAX_WHEELS)),     # A: wheel i's spin axis in body axes is column i
    ("u_max", np.float64, (MAX_WHEELS,)),      # U_i, the box (0: a failed wheel)
    ("row_psi", np.int64),                     # the first wheel's constraint (after the body's)
    ("n_rows", np.int64),                      # row_psi + N
    ("enabled", np.uint8, (MAX_ARRAY_ROWS,)),  # per constraint of the array
    ("slack_weight", np.float64, (MAX_ARRAY_ROWS,)),
    ("level", np.int64, (MAX_ARRAY_ROWS,)),    # priority level (0: most important)
    ("psi_gains", GAIN_DTYPE),                 # the wheels' constraint (`psi`)
    ("psi_keep", np.float64),                  # the speed the rows keep |psi_i| within (`Config.psi_keep_rad_s`)
    ("psi_limit", np.float64),                 # the limit h judges (psi_max)
    ("relative", np.uint8),                    # h judges |psi_i + a_i . omega| (the speed relative to the body)
    ("robust", np.uint8),
    ("zoh_margin", np.float64),
    ("dt_s", np.float64),
    ("n_null", np.int64),                      # dimension of the working wheels' null space
    ("null_basis", np.float64, (MAX_WHEELS, MAX_WHEELS)),  # its orthonormal basis, column b (0 on failed wheels)
    ("null_gain", np.float64),                 # 1/s
    ("null_bias", np.float64),                 # rad/s, the speed up to which the law spins the wheels
    ("null_accel", np.float64),                # rad/s^2, the most the law asks of any wheel
])  # fmt: skip
"""The array's part of the filter (the body's is the virtual vehicle's FILTER_DTYPE)."""


ARRAY_RESULT_DTYPE = np.dtype([
    ("u", np.float64, (MAX_WHEELS,)),          # the wheel accelerations sent, rad/s^2
    ("u_held", np.float64, (MAX_WHEELS,)),     # (u: no drive lag on this path)
    ("u_des", np.float64, (MAX_WHEELS,)),      # as received
    ("u_target", np.float64, (MAX_WHEELS,)),   # u_des with the null-space law's term
    ("h", np.float64, (MAX_ARRAY_ROWS,)),
    ("psi0", np.float64, (MAX_ARRAY_ROWS,)),
    ("psi1", np.float64, (MAX_ARRAY_ROWS,)),
    ("bc", np.float64, (MAX_ARRAY_ROWS,)),
    ("slack", np.float64, (MAX_ARRAY_ROWS,)),
    ("intervening", np.uint8, (MAX_ARRAY_ROWS,)),
    ("uncontrollable", np.uint8, (MAX_ARRAY_ROWS,)),
    ("box_active", np.uint8, (MAX_WHEELS,)),
    ("lo", np.float64, (MAX_WHEELS,)),
    ("hi", np.float64, (MAX_WHEELS,)),
    ("status", np.int8),
    ("fallback", np.int8),
    ("solver", np.int8),
    ("solve_result", np.int8),
    ("backup_result", np.int8),
    ("soft_result", np.int8),
    ("qp_failed", np.uint8),
    ("raise_error", np.uint8),
    ("gate", np.int8),
    ("gave_way", np.int8),
    ("iterations", np.int64),
    ("solves", np.int64),
    ("solve_time_s", np.float64),
])  # fmt: skip
"""What one call over an array did: RESULT_DTYPE's fields by name, per wheel and per constraint of the array."""


def null_basis(axes: Array, failed: NDArray[np.bool_]) -> Array:
    """An orthonormal basis (N, k) of the working wheels' null space: accelerations that do not turn the body
    (0 on a failed wheel), each column's sign such that its largest entry is positive (deterministic)."""
    work = np.flatnonzero(~failed)
    _, s, vt = np.linalg.svd(axes[:, work])
    rank = int(np.count_nonzero(s > 1e-9 * max(s[0], 1.0)))
    basis = np.zeros((axes.shape[1], len(work) - rank))
    basis[work] = vt[rank:].T
    for b in range(basis.shape[1]):
        if basis[np.argmax(np.abs(basis[:, b])), b] < 0:
            basis[:, b] = -basis[:, b]
    return basis


def array_records(cfg: Config) -> tuple[NDArray[np.void], NDArray[np.void]]:
    """The records (1,) of the filter over cfg's array: the virtual vehicle's FILTER_DTYPE record (its three wheel
    rows off: the array's wheels have their own) and the array's ARRAY_DTYPE record."""
    body = filter_record(cfg.virtual_vehicle)
    sc = cfg.spacecraft
    n = sc.n_wheels
    rec = np.zeros(1, ARRAY_DTYPE)
    a = rec[0]
    c = body[0]["constraints"]
    row_psi = int(c["row_psi"])
    a["n"] = n
    a["axes"][:, :n] = sc.wheel_axes
    a["u_max"][:n] = cfg.u_max_rad_s2
    a["row_psi"], a["n_rows"] = row_psi, row_psi + n
    for i in range(row_psi):
        g = c["gains"][i]
        a["enabled"][i], a["slack_weight"][i], a["level"][i] = g["enabled"], g["slack_weight"], body[0]["level"][i]
    psi = c["gains"][row_psi]
    a["psi_gains"] = psi
    for j in range(n):
        a["enabled"][row_psi + j], a["slack_weight"][row_psi + j] = psi["enabled"], psi["slack_weight"]
        a["level"][row_psi + j] = body[0]["level"][row_psi]
    a["psi_keep"], a["psi_limit"] = cfg.psi_keep_rad_s, cfg.limits.psi_max_rad_s
    a["relative"] = cfg.limits.wheel_speed_relative_to_body
    a["robust"], a["zoh_margin"], a["dt_s"] = c["robust"], c["zoh_margin"], c["dt_s"]
    basis = null_basis(sc.wheel_axes, sc.wheel_failed)
    a["n_null"] = basis.shape[1]
    a["null_basis"][:n, : basis.shape[1]] = basis
    o = cfg.filter
    a["null_gain"], a["null_bias"] = o.null_space_gain_1_s, o.null_space_bias * cfg.psi_keep_rad_s
    a["null_accel"] = o.null_space_accel_fraction * cfg.limits.wheel_accel_max_rad_s2
    c["gains"]["enabled"][row_psi: row_psi + 3] = 0
    return body, rec


# --------------------------------------------------------------------------------------- compiled


@numba.njit(**LEAF)
def wheel_speed_h(x: Array, a: np.void, j: int) -> float:
    """psi_max^2 - v^2 of wheel j (rad^2/s^2), v its speed (relative to the body where `relative`); negative =
    too fast (what the plant is judged by)."""
    v = x[wheel_column(j)]
    if a.relative:
        v += a.axes[0, j] * x[4] + a.axes[1, j] * x[5] + a.axes[2, j] * x[6]
    return a.psi_limit**2 - v * v


@numba.njit(**LEAF)
def virtual_state(x: Array, a: np.void, out: Array) -> None:
    """The virtual vehicle's state (19,) of the array's x (16 + N,): x's body entries, the wheels' A psi."""
    for i in range(STATE_SIZE):
        out[i] = x[i]
    for b in range(3):
        s = 0.0
        for j in range(a.n):
            s += a.axes[b, j] * x[wheel_column(j)]
        out[7 + b] = s


@numba.njit(**LEAF, inline="always")
def _spread(x: Array, a: np.void, b: int, s0: float, s: float) -> tuple[float, float]:
    """(min, max) of |psi_i| over the working wheels with null-space coordinate b moved from s0 to s."""
    lo, hi = np.inf, 0.0
    for j in range(a.n):
        if a.u_max[j] > 0.0:
            v = abs(x[wheel_column(j)] + a.null_basis[j, b] * (s - s0))
            lo, hi = min(lo, v), max(hi, v)
    return lo, hi


@numba.njit(**LEAF)
def null_target(x: Array, a: np.void, b: int, s0: float) -> float:
    """The null-space coordinate b the law steers to (the others held), s0 its value now: among the coordinates that
    keep every working wheel within null_bias, the one whose slowest wheel is fastest (the wheels as far from zero
    speed as that cap allows); where none does (the body's momentum alone needs more), the one whose fastest
    wheel is slowest (as far from the limit as can be). psi_i(s) = psi_i + n_bi (s - s0) is linear in s, so both
    optima lie at an end of the allowed interval or where two wheels' |psi| cross: those candidates are tried
    (nearest s0 first on a tie)."""
    cap = a.null_bias
    lo_s, hi_s = -np.inf, np.inf
    for j in range(a.n):
        nj = a.null_basis[j, b]
        if a.u_max[j] > 0.0 and nj != 0.0:
            e1, e2 = (-cap - x[wheel_column(j)]) / nj + s0, (cap - x[wheel_column(j)]) / nj + s0
            lo_s, hi_s = max(lo_s, min(e1, e2)), min(hi_s, max(e1, e2))
    inside = lo_s <= hi_s
    best, best_val = s0, -np.inf
    for c in range(-2, a.n * a.n * 2):
        if c == -2:
            s = lo_s if inside else s0
        elif c == -1:
            s = hi_s if inside else s0
        else:  # where |psi_i(s)| = |psi_j(s)|, psi_i(s) = +-psi_j(s)
            i, rest = c // (2 * a.n), c % (2 * a.n)
            j, sign = rest // 2, 1.0 if rest % 2 == 0 else -1.0
            if i >= j or a.u_max[i] == 0.0 or a.u_max[j] == 0.0:
                continue
            den = a.null_basis[i, b] - sign * a.null_basis[j, b]
            if den == 0.0:
                continue
            s = s0 + (sign * x[wheel_column(j)] - x[wheel_column(i)]) / den
            if inside and not (lo_s <= s <= hi_s):
                continue
        slow, fast = _spread(x, a, b, s0, s)
        val = slow if inside else -fast
        if val > best_val or (val == best_val and abs(s - s0) < abs(best - s0)):
            best, best_val = s, val
    return best


@numba.njit(**LEAF)
def null_space_term(x: Array, a: np.void, out: Array) -> None:
    """The null-space law's accelerations (N,) into out: each null-space coordinate s_b = n_b . psi driven toward
    `null_target` at null_gain, the ask capped at null_accel per wheel (0 without a null space or a bias)."""
    n = a.n
    for j in range(n):
        out[j] = 0.0
    if a.null_bias <= 0.0:
        return
    for b in range(a.n_null):
        s = 0.0
        for j in range(n):
            s += a.null_basis[j, b] * x[wheel_column(j)]
        rate = -a.null_gain * (s - null_target(x, a, b, s))
        for j in range(n):
            out[j] += rate * a.null_basis[j, b]
    worst = 0.0
    for j in range(n):
        worst = max(worst, abs(out[j]))
    if worst > a.null_accel:
        for j in range(n):
            out[j] *= a.null_accel / worst


@numba.njit(**LEAF)
def _lift(g: Array, a: np.void, out: Array) -> float:
    """out (N,) = g (3,) A: a body row's gain on the wheels; returns its norm."""
    ss = 0.0
    for j in range(a.n):
        v = g[0] * a.axes[0, j] + g[1] * a.axes[1, j] + g[2] * a.axes[2, j]
        out[j] = v
        ss += v * v
    return math.sqrt(ss)


@numba.njit(**JIT)
def array_table(x: Array, f: np.void, a: np.void, ws: np.void, r: np.void
                ) -> tuple[Array, Array, Array, NDArray[np.int64], int, Array, Array]:
    """The rows of the array's QP at the prepared state (ws.table: the virtual vehicle's rows): (G (K, N), lo, hi
    (K,), con (K,) each row's constraint, or -1 for a hard row (the virtual box, the acceleration rows, the rates'
    ZOH intervals on the virtual box), or -2 - i for a hard row of rate constraint i (a ZOH interval: hard as the
    three-wheel filter's box, which it is where the wheels are the paper's; `prioritize` lets it give way with
    its rate where the array cannot meet every hard row), K, box lo and hi (N,)); h, psi0, psi1 and
    uncontrollable of every constraint into r."""
    t, c = ws.table, f.constraints
    n = a.n
    cap = c.n_rows + t.zoh_rows + 9 + n
    G = np.zeros((cap, n))
    lo = np.full(cap, -BIG)
    hi = np.full(cap, BIG)
    con = np.full(cap, -1, dtype=np.int64)
    k = 0
    for i in range(a.row_psi):
        r.h[i], r.psi0[i], r.psi1[i] = t.h[i], t.psi0[i], t.psi1[i]
        norm = _lift(t.gain[i], a, G[k])
        on = a.enabled[i] != 0
        r.uncontrollable[i] = 1 if (on and norm <= MIN_ROW_NORM and t.drift[i] < 0) else 0
        if on and norm > MIN_ROW_NORM:
            lo[k] = -t.drift[i]
            con[k] = i
            k += 1
    for q in range(t.zoh_rows):
        if _lift(t.zoh_gain[q], a, G[k]) > MIN_ROW_NORM:
            lo[k], hi[k] = t.zoh_lo[q], t.zoh_hi[q]
            con[k] = c.row_omega + t.zoh_axis[q]
            k += 1
    e = np.zeros(3)
    for b in range(3):  # the virtual vehicle's box, then its rate's ZOH interval where that is narrower
        e[b] = 1.0
        _lift(e, a, G[k])
        lo[k], hi[k] = ws.lo0[b], ws.hi0[b]
        k += 1
        if t.lo[b] > ws.lo0[b] or t.hi[b] < ws.hi0[b]:
            _lift(e, a, G[k])
            lo[k], hi[k] = t.lo[b], t.hi[b]
            con[k] = -2 - (c.row_omega + b)
            k += 1
        e[b] = 0.0
    if c.accel_rows:  # |(G_virtual A u)_b| <= b_b
        Gv, lim = f.plant.control_matrix, c.accel_limit_rad_s2
        for b in range(3):
            e[0], e[1], e[2] = Gv[b, 0], Gv[b, 1], Gv[b, 2]
            _lift(e, a, G[k])
            lo[k], hi[k] = -lim[b], lim[b]
            k += 1
    g = a.psi_gains
    blo, bhi = np.empty(n), np.empty(n)
    for j in range(n):
        i = a.row_psi + j
        psi = x[wheel_column(j)]
        hv = a.psi_keep**2 - psi * psi
        r.h[i], r.psi0[i], r.psi1[i] = hv, hv, hv
        r.uncontrollable[i] = 0
        if a.enabled[i] and psi != 0.0:
            G[k, j] = -2.0 * psi
            lo[k] = -(g.k1 * hv + g.bias)
            con[k] = i
            k += 1
        elif a.enabled[i] and g.k1 * hv + g.bias < 0.0:
            r.uncontrollable[i] = 1
        lo_j, hi_j = -a.u_max[j], a.u_max[j]
        if a.robust and a.enabled[i]:  # (no sensor errors on this path: ArrayFilter refuses them)
            zlo, zhi = hold_bounds(psi, a.psi_keep, a.zoh_margin, 0.0, 0.0, a.dt_s)
            lo_j, hi_j = hold_interval(lo_j, hi_j, zlo, zhi)
        blo[j], bhi[j] = lo_j, hi_j
    return G, lo, hi, con, k, blo, bhi


@numba.njit(**LEAF, inline="always")
def _owner(con: NDArray[np.int64], k: int, soft_zoh: bool) -> int:
    """The constraint whose mode row k takes: its own, or with soft_zoh a rate's ZOH interval's rate (-1: hard)."""
    i = con[k]
    if i <= -2:
        return -2 - i if soft_zoh else -1
    return i


@numba.njit(**LEAF)
def _row_value(G: Array, k: int, u: Array) -> float:
    v = 0.0
    for j in range(G.shape[1]):
        v += G[k, j] * u[j]
    return v


@numba.njit(**LEAF)
def _violation(G: Array, lo: Array, hi: Array, k: int, u: Array) -> float:
    """How far row k misses at u (either side)."""
    v = _row_value(G, k, u)
    return max(0.0, lo[k] - v, v - hi[k])


@numba.njit(**LEAF)
def _row_norm(G: Array, k: int) -> float:
    ss = 0.0
    for j in range(G.shape[1]):
        ss += G[k, j] * G[k, j]
    return math.sqrt(ss)


@numba.njit(**JIT)
def assemble(G: Array, lo: Array, hi: Array, con: NDArray[np.int64], K: int, blo: Array, bhi: Array,
             target: Array, mode: NDArray[np.int8], relax: Array, a: np.void, soften_weight: float, soft_zoh: bool
             ) -> tuple[Array, Array, Array, Array, NDArray[np.int64], NDArray[np.int64], Array]:
    """The QP over z = [u (N); s]: each table row k whose constraint's mode is not OFF (hard rows always; with
    soft_zoh the rates' ZOH rows take their rate's mode, `_owner`), normalised, slacked where its mode says
    (SLACKED: weight p, its configured or soften_weight; DISTANCE: soften_weight on the relaxation as a distance
    in u), relaxed by relax[k] (both sides); then the box. Returns (C, lower, upper, z0, row_of (r,) the table row
    of each QP row, var (r,) its slack variable or -1, scale (n,) delta = scale * s)."""
    n = a.n
    r = 0
    ns = 0
    for k in range(K):
        i = _owner(con, k, soft_zoh)
        if i < 0 or mode[i] != OFF:
            r += 1
            if i >= 0 and mode[i] >= SLACKED:
                ns += 1
    nz = n + ns
    C = np.zeros((r + n, nz))
    lower = np.full(r + n, -BIG)
    upper = np.full(r + n, BIG)
    row_of = np.empty(r, dtype=np.int64)
    var = np.full(r, -1, dtype=np.int64)
    scale = np.zeros(nz)
    q = 0
    v = n
    for k in range(K):
        i = _owner(con, k, soft_zoh)
        if not (i < 0 or mode[i] != OFF):
            continue
        row_of[q] = k
        for j in range(n):
            C[q, j] = G[k, j]
        if i >= 0 and mode[i] >= SLACKED:
            if mode[i] == DISTANCE:
                scale[v] = _row_norm(G, k) / math.sqrt(soften_weight)
            else:
                p = a.slack_weight[i] if a.slack_weight[i] > 0 else soften_weight
                scale[v] = 1.0 / math.sqrt(p)
            C[q, v] = scale[v]
            var[q] = v
            v += 1
        ss = 0.0
        for j in range(nz):
            ss += C[q, j] * C[q, j]
        norm = math.sqrt(ss)
        for j in range(nz):
            C[q, j] = C[q, j] / norm
        if lo[k] > -BIG / 2:
            lower[q] = (lo[k] - relax[k]) / norm
        if hi[k] < BIG / 2:
            upper[q] = (hi[k] + relax[k]) / norm
        q += 1
    for j in range(n):
        C[r + j, j] = 1.0
        lower[r + j], upper[r + j] = blo[j], bhi[j]
    z0 = np.zeros(nz)
    for j in range(n):
        z0[j] = target[j]
    return C, lower, upper, z0, row_of, var, scale


@numba.njit(**LEAF)
def _modes(a: np.void, soften: bool, mode: NDArray[np.int8]) -> None:
    for i in range(a.n_rows):
        if not a.enabled[i]:
            mode[i] = OFF
        elif soften or a.slack_weight[i] > 0:
            mode[i] = SLACKED
        else:
            mode[i] = HARD


@numba.njit(**LEAF)
def _clip_u(z: Array, blo: Array, bhi: Array, u: Array) -> None:
    for j in range(u.shape[0]):
        u[j] = min(max(z[j], blo[j]), bhi[j])


@numba.njit(**JIT)
def prioritize(G: Array, lo: Array, hi: Array, con: NDArray[np.int64], K: int, blo: Array, bhi: Array,
               target: Array, f: np.void, a: np.void, rb: np.void, r: np.void, soft_zoh: bool
               ) -> tuple[bool, Array, Array, NDArray[np.int64], NDArray[np.int64], Array, Array]:
    """`filter.qp.prioritize` over the array's rows: for each level, most important first, the least violation
    of its rows as distances in u (the more important hard as relaxed so far, the less important left out, the
    box and the hard rows kept), which fixes how far each gives way; then the filter's QP with every row
    relaxed by that much. r.gave_way: the most important level relaxed; r.soft_result: the last QP. soft_zoh: the
    rates' ZOH rows give way with their rate (`array_table`) instead of staying hard. Returns (ok, z, mult,
    row_of, var, scale, relax) of the last QP solved."""
    n = a.n
    mode = np.zeros(MAX_ARRAY_ROWS, dtype=np.int8)
    relax = np.zeros(K)
    u = np.empty(n)
    have = False
    z = np.zeros(n)
    mult = np.zeros(n)
    row_of = np.zeros(0, dtype=np.int64)
    var = np.zeros(0, dtype=np.int64)
    scale = np.zeros(n)
    for lev in range(f.n_levels):
        rows_here = False
        for i in range(a.n_rows):
            if not a.enabled[i] or a.slack_weight[i] > 0 or a.level[i] > lev:
                mode[i] = OFF
            elif a.level[i] == lev:
                mode[i] = DISTANCE
            else:
                mode[i] = HARD
        for k in range(K):
            i = _owner(con, k, soft_zoh)
            if i >= 0 and mode[i] == DISTANCE:
                rows_here = True
        if not rows_here:
            continue
        C, lower, upper, z0, ro, vr, sc = assemble(G, lo, hi, con, K, blo, bhi, target, mode, relax, a,
                                                   f.soften_weight, soft_zoh)
        zl, ml, code, backup = solve(C, lower, upper, z0, f, rb)
        if not (code == SOLVE_OK or backup == SOLVE_OK):
            break
        _clip_u(zl, blo, bhi, u)
        z, mult, row_of, var, scale, have = zl, ml, ro, vr, sc, True
        for k in range(K):
            i = _owner(con, k, soft_zoh)
            if i >= 0 and mode[i] == DISTANCE:
                v = _violation(G, lo, hi, k, u)
                if v > 0.0:
                    relax[k] = v + f.check_tolerance * _row_norm(G, k)
    tol2 = 2.0 * f.check_tolerance
    top = f.n_levels
    for k in range(K):
        i = _owner(con, k, soft_zoh)
        if i >= 0 and relax[k] > tol2 * _row_norm(G, k):
            top = min(top, a.level[i])
    r.gave_way = top if top < f.n_levels else NO_LEVEL
    _modes(a, False, mode)
    C, lower, upper, z0, ro, vr, sc = assemble(G, lo, hi, con, K, blo, bhi, target, mode, relax, a, f.soften_weight,
                                               soft_zoh)
    zl, ml, code, backup = solve(C, lower, upper, z0, f, rb)
    r.soft_result = code if backup == NOT_SOLVED or code == SOLVE_OK else backup
    if code == SOLVE_OK or backup == SOLVE_OK:
        return True, zl, ml, ro, vr, sc, relax
    return have, z, mult, row_of, var, scale, relax


@numba.njit(**JIT)
def array_call(x: Array, u_des: Array, t_s: float, f: np.void, a: np.void, ws: np.void, r: np.void) -> None:
    """The array's answer r.u (N) at state x (16 + N,) and time t_s for the desired wheel accelerations u_des (N,):
    the virtual vehicle's rows at the virtual state, lifted to the wheels, the wheels' rows, the QP, the policy
    where it fails, and every constraint's barrier condition at u. ws: a filter workspace (scratch)."""
    n = a.n
    rb = ws.result
    rb.iterations = rb.solves = 0
    for i in range(a.n_rows):
        r.slack[i] = 0.0
        r.intervening[i] = 0
    r.solver = f.solver
    r.solve_result = r.backup_result = r.soft_result = NOT_SOLVED
    r.qp_failed = r.raise_error = 0
    r.gate = GATE_OFF
    r.gave_way = NO_LEVEL
    xv = np.empty(STATE_SIZE)
    virtual_state(x, a, xv)
    finite = True
    for j in range(n):
        finite = finite and math.isfinite(x[wheel_column(j)])
    finite_des = True
    vdes = np.zeros(3)
    for j in range(n):
        r.u_des[j] = u_des[j]
        if not math.isfinite(u_des[j]):
            finite_des = False
    c = f.constraints
    for b in range(3):
        ws.lo0[b], ws.hi0[b] = -c.u_max_rad_s2[b], c.u_max_rad_s2[b]
    valid, _, _ = prepare(xv, vdes, t_s, f, ws, rb)
    valid = valid and finite
    if not valid:
        for j in range(n):
            r.u[j] = r.u_held[j] = r.u_target[j] = 0.0
            r.lo[j], r.hi[j] = -a.u_max[j], a.u_max[j]
            r.box_active[j] = 0
        for i in range(a.n_rows):
            r.h[i] = r.psi0[i] = r.psi1[i] = r.bc[i] = np.nan
            r.uncontrollable[i] = 0
        r.status, r.fallback = FALLBACK, INVALID_STATE
        r.iterations, r.solves = 0, 0
        return
    G, lo, hi, con, K, blo, bhi = array_table(x, f, a, ws, r)
    target = np.empty(n)
    null_space_term(x, a, target)
    for j in range(n):
        target[j] += u_des[j] if math.isfinite(u_des[j]) else 0.0
        r.u_target[j] = target[j]
        r.u[j] = min(max(target[j], blo[j]), bhi[j])
        r.lo[j], r.hi[j] = blo[j], bhi[j]
    need = not finite_des
    tol = f.check_tolerance
    for k in range(K):
        if _violation(G, lo, hi, k, r.u[:n]) > tol * max(1.0, _row_norm(G, k)):
            need = True
    reason = NO_FALLBACK if finite_des else NON_FINITE_U_DES
    soft_zoh = False
    if need:
        mode = np.empty(MAX_ARRAY_ROWS, dtype=np.int8)
        _modes(a, False, mode)
        relax = np.zeros(K)
        C, lower, upper, z0, row_of, var, scale = assemble(G, lo, hi, con, K, blo, bhi, target, mode, relax, a,
                                                           f.soften_weight, False)
        z, mult, code, backup = solve(C, lower, upper, z0, f, rb)
        r.solve_result, r.backup_result = code, backup
        ok = code == SOLVE_OK or backup == SOLVE_OK
        if not ok:
            r.qp_failed = 1
            reason = POLICY_ACTED
            if f.policy == RAISE:
                r.raise_error = 1
            elif f.policy == SOFTEN:
                soft_zoh = True
                _modes(a, True, mode)
                C, lower, upper, z0, row_of, var, scale = assemble(G, lo, hi, con, K, blo, bhi, target, mode, relax,
                                                                   a, f.soften_weight, True)
                z, mult, soft, soft_backup = solve(C, lower, upper, z0, f, rb)
                ok = soft == SOLVE_OK or soft_backup == SOLVE_OK
                r.soft_result = SOLVE_OK if ok else soft
            elif f.policy == PRIORITIZE:
                ok, z, mult, row_of, var, scale, relax = prioritize(G, lo, hi, con, K, blo, bhi, target, f, a, rb, r,
                                                                    False)
                if r.soft_result != SOLVE_OK:  # a hard row the array cannot meet with the rest: the rates' ZOH
                    soft_zoh = True            # rows give way with their rate (the paper's wheels never come here)
                    ok2, z2, m2, ro2, v2, s2, rx2 = prioritize(G, lo, hi, con, K, blo, bhi, target, f, a, rb, r, True)
                    if ok2:
                        ok, z, mult, row_of, var, scale, relax = ok2, z2, m2, ro2, v2, s2, rx2
            if not ok and f.policy == HOLD:
                for j in range(n):
                    r.u[j] = min(max(0.0, blo[j]), bhi[j])
        if ok:
            _clip_u(z, blo, bhi, r.u[:n])
            for q in range(row_of.shape[0]):
                k = row_of[q]
                i = _owner(con, k, soft_zoh)
                if i < 0:
                    continue
                if abs(mult[q]) > ACTIVE_MULTIPLIER:
                    r.intervening[i] = 1
                if var[q] >= 0:
                    r.slack[i] = max(r.slack[i], scale[var[q]] * z[var[q]])
            if f.policy == PRIORITIZE and r.qp_failed:
                for k in range(K):
                    i = _owner(con, k, soft_zoh)
                    if i >= 0 and relax[k] > 0.0:
                        r.slack[i] = max(r.slack[i], relax[k])
        r.status = FALLBACK if reason != NO_FALLBACK else SOLVED
    else:
        r.status = PASS
    r.fallback = reason
    r.iterations, r.solves = rb.iterations, rb.solves
    _finish(x, a, ws, blo, bhi, r)


@numba.njit(**LEAF)
def _finish(x: Array, a: np.void, ws: np.void, blo: Array, bhi: Array, r: np.void) -> None:
    """BC_i at the final u of every constraint (a body row at the virtual v = A u), the box flags, u_held."""
    n = a.n
    t = ws.table
    v0 = v1 = v2 = 0.0
    for j in range(n):
        v0 += a.axes[0, j] * r.u[j]
        v1 += a.axes[1, j] * r.u[j]
        v2 += a.axes[2, j] * r.u[j]
    for i in range(a.row_psi):
        r.bc[i] = t.drift[i] + (t.gain[i, 0] * v0 + t.gain[i, 1] * v1 + t.gain[i, 2] * v2)
    g = a.psi_gains
    for j in range(n):
        psi = x[wheel_column(j)]
        i = a.row_psi + j
        r.bc[i] = -2.0 * psi * r.u[j] + g.k1 * r.psi0[i] + g.bias
        ut = r.u_target[j]
        r.box_active[j] = 1 if ((r.u[j] <= blo[j] and ut < blo[j]) or (r.u[j] >= bhi[j] and ut > bhi[j])) else 0
        r.u_held[j] = r.u[j]


@numba.njit(**JIT)
def array_problem(x: Array, u_des: Array, t_s: float, f: NDArray[np.void], a: NDArray[np.void], ws: NDArray[np.void],
                  r: NDArray[np.void]) -> tuple[Array, Array, Array, NDArray[np.int64], Array, Array, Array]:
    """The rows `array_call` puts to its QP at a valid state x (`array_table`: G, lo, hi, con, the box) and its
    u_target (u_des + the null-space law), for checks against another solver."""
    xv = np.empty(STATE_SIZE)
    virtual_state(x, a[0], xv)
    c = f[0].constraints
    for b in range(3):
        ws[0].lo0[b], ws[0].hi0[b] = -c.u_max_rad_s2[b], c.u_max_rad_s2[b]
    prepare(xv, np.zeros(3), t_s, f[0], ws[0], ws[0].result)
    G, lo, hi, con, K, blo, bhi = array_table(x, f[0], a[0], ws[0], r[0])
    target = np.empty(a[0].n)
    null_space_term(x, a[0], target)
    for j in range(a[0].n):
        target[j] += u_des[j]
    return G[:K].copy(), lo[:K].copy(), hi[:K].copy(), con[:K].copy(), blo, bhi, target


@numba.njit(**JIT)
def array_many(X: Array, U_des: Array, T: Array, f: NDArray[np.void], a: NDArray[np.void], ws: NDArray[np.void],
               R: NDArray[np.void]) -> None:
    """`array_call` of states X (K, 16 + N) at times T (K,) with U_des (K, N) into results R (K,)."""
    for k in range(X.shape[0]):
        array_call(X[k], U_des[k], T[k], f[0], a[0], ws[0], R[k])


@numba.njit(**LEAF)
def array_safety(x: Array, a: np.void, body_h: Array, out: Array) -> None:
    """Every constraint of the array (row_psi + N) from the virtual vehicle's safety values body_h: the body's,
    then each wheel's."""
    for i in range(a.row_psi):
        out[i] = body_h[i]
    for j in range(a.n):
        out[a.row_psi + j] = wheel_speed_h(x, a, j)


@numba.njit(**JIT)
def array_safety_many(X: Array, T: Array, f: NDArray[np.void], a: NDArray[np.void], out: Array) -> None:
    """Physical h of every constraint of the array (row_psi + N) of states X (K, 16 + N) at times T (K,) into out
    (K, >= row_psi + N): the body's at the virtual state (`constraints.rows.safety_values`), each wheel's speed."""
    ctx = np.zeros(1, CONTEXT_DTYPE)
    xv = np.empty(STATE_SIZE)
    hb = np.empty(MAX_ROWS)
    ar = a[0]
    for k in range(X.shape[0]):
        virtual_state(X[k], ar, xv)
        safety_values(xv, T[k], f[0].plant, f[0].constraints, ctx[0], hb)
        array_safety(X[k], ar, hb, out[k])


# --------------------------------------------------------------------------------------- Python face


class ArrayResult(FilterResult):
    """FilterResult of a call over an array: u, u_des, lo, hi, box_active per wheel (N), the per-constraint fields
    over `names` (the body's, then psi_<wheel> per wheel)."""

    def __init__(self, record: NDArray[np.void], policy: str, levels: tuple[tuple[str, ...], ...],
                 names: tuple[str, ...], n_wheels: int) -> None:
        super().__init__(record, policy, levels, names)
        self.n_wheels = n_wheels

    def _field(self, name: str) -> NDArray[np.generic]:
        a = self.record[name]
        if name in ("u", "u_held", "u_des", "u_target", "lo", "hi", "box_active"):
            return a[..., : self.n_wheels]
        return super()._field(name)

    u_target = property(lambda self: self._field("u_target"))

    def __getitem__(self, k: int) -> ArrayResult:
        return ArrayResult(self.record[k], self.policy, self.levels, self.names, self.n_wheels)


def check_array(cfg: Config) -> None:
    """Raise ConfigError (one line) for what the array's filter does not take: more than MAX_WHEELS wheels, the
    gatekeeper, sensor errors, a transport delay."""
    sc = cfg.spacecraft
    refused = [(sc.n_wheels > MAX_WHEELS, f"more than {MAX_WHEELS} wheels"),
               (cfg.filter.backup_law != "none", "the gatekeeper (set filter.backup_law: none)"),
               (cfg.sensors.enabled, "sensor errors (sensors.enabled)"),
               (sc.transport_delay_s > 0.0, "a transport delay (spacecraft.transport_delay_s)")]
    for bad, what in refused:
        if bad:
            raise ConfigError(f"the filter over {sc.n_wheels} wheels ({', '.join(sc.wheel_names)}) does not take "
                              f"{what} yet (docs/wheels.md)")


class ArraySafety:
    """The safety values of cfg's array: `values(x, t_s)` of states x (..., 16 + N), (..., m) over `names`."""

    def __init__(self, cfg: Config) -> None:
        self.record, self.array = array_records(cfg)
        self.names = cfg.constraint_names

    def values(self, x: Array, t_s: float | Array = 0.0) -> Array:
        X = np.ascontiguousarray(np.reshape(x, (-1, np.shape(x)[-1])), dtype=float)
        T = np.ascontiguousarray(np.broadcast_to(np.asarray(t_s, dtype=float), np.shape(x)[:-1]).reshape(-1))
        H = np.empty((X.shape[0], MAX_ARRAY_ROWS))
        array_safety_many(X, T, self.record, self.array, H)
        return H[:, : len(self.names)].reshape((*np.shape(x)[:-1], len(self.names)))


class ArrayFilter:
    """The ASIF over an array of N wheels (any N from 3 to MAX_WHEELS); call `filter(x, u_des, t_s)`.

    x is the array's state (16 + N,: `dynamics.state`), u_des the N wheel accelerations (the primary's body torque
    split by `dynamics.spacecraft.torque_to_wheels`, its minimum-norm split). Not thread-safe (one workspace)."""

    def __init__(self, cfg: Config) -> None:
        check_array(cfg)
        self.cfg = cfg
        self.n_wheels = cfg.spacecraft.n_wheels
        self.record, self.array = array_records(cfg)
        self.names = cfg.constraint_names
        self.levels = cfg.priority_levels
        self.counters = FilterCounters()
        self._ws = new_workspace()
        self._n_state = state_size(self.n_wheels)
        self._x1 = np.zeros((1, self._n_state))
        self._u1 = np.zeros((1, self.n_wheels))
        self._t1 = np.zeros(1)
        self._out = np.zeros(1, ARRAY_RESULT_DTYPE)

    def filter(self, x: Array, u_des: Array, t_s: float = 0.0) -> ArrayResult:
        """Filter one desired command: x (16 + N,), u_des (N,) rad/s^2, t_s the time of x (s from the run's start).

        Raises:
            SolverError: the QP failed and the fallback policy is 'raise'.
        """
        t0 = time.perf_counter()
        if np.shape(x) != (self._n_state,) or np.shape(u_des) != (self.n_wheels,):
            raise ValueError(f"filter takes x ({self._n_state},) and u_des ({self.n_wheels},), got {np.shape(x)} "
                             f"and {np.shape(u_des)}")
        self._x1[0], self._u1[0], self._t1[0] = x, u_des, t_s
        array_many(self._x1, self._u1, self._t1, self.record, self.array, self._ws, self._out)
        rec = np.frombuffer(bytearray(self._out.tobytes()), ARRAY_RESULT_DTYPE).reshape(())
        rec["solve_time_s"] = time.perf_counter() - t0
        self.counters.add_one(rec)
        result = ArrayResult(rec, self.cfg.filter.fallback, self.levels, self.names, self.n_wheels)
        if rec["raise_error"]:
            raise SolverError(f"ASIF QP failed ({result.solver_status})")
        return result

    def problem(self, x: Array, u_des: Array, t_s: float = 0.0) -> dict[str, Array]:
        """The QP's rows at a valid state x (16 + N,) and time t_s, before normalisation: each row k reads lo_k <=
        G_k u (+ its slack where its constraint `con_k` is slacked) <= hi_k (con_k -1: always hard), the box
        box_lo <= u <= box_hi, and the point the QP keeps u nearest, u_target (u_des + the null-space law)."""
        x = np.ascontiguousarray(x, dtype=float)
        ws, out = new_workspace(), np.zeros(1, ARRAY_RESULT_DTYPE)
        G, lo, hi, con, blo, bhi, target = array_problem(x, np.ascontiguousarray(u_des, dtype=float), float(t_s),
                                                         self.record, self.array, ws, out)
        return {"G": G, "lo": lo, "hi": hi, "con": con, "box_lo": blo, "box_hi": bhi, "u_target": target}


__all__ = ["ARRAY_DTYPE", "ARRAY_RESULT_DTYPE", "MAX_WHEELS", "ArrayFilter", "ArrayResult", "ArraySafety",
           "array_call",
           "array_records", "check_array", "null_basis"]
