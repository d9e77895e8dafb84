"""The ASIF's answer to one state, compiled: the QP step of the filter call (`answer`).

    prepare    the state is checked (finite, quaternion norm in (0.5, 1.5)) and its quaternion
               normalised; rows and box (`constraints.rows`); u0 = clip(u_des, lo, hi) is the exact
               QP solution if it meets every enabled row (the fast path, no solver)
    assemble   min 1/2 |z - z0|^2 s.t. lower <= C z <= upper, z = [u; s]: rows normalised to unit norm,
               one scaled slack per slacked row (delta = s / sqrt(p)), the box as the last rows
    solve      `filter.solver`: the exact dual active-set method (`active_set`, compiled, in line) or
               proxsuite (`proxsuite_qp`, Python, entered through numba's object mode: imported only
               when chosen); every answer is checked against the rows
    fallback   a failed QP: `pass_through` (u0), `hold` (u = 0 clipped to the box), `soften` (the QP
               again with every row slacked; u0 if that fails too), `raise` (flagged; Python raises)
               or `prioritize` (`Config.priority_levels`: the least important level gives way first, each
               level by as little as possible, one small QP per level and a last one for u)
    finish     BC_i at the final u, which box bounds clipped u
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.constraints.base import (
    MAX_ROWS,
    ZOH_ROWS,
)
from rta_attitude.constraints.rows import rows
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter import active_set, proxsuite_qp
from rta_attitude.filter.outcome import (
    ACTIVE_SET,
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
    SOLVE_CHECK_FAILED,
    SOLVE_OK,
    SOLVED,
)
from rta_attitude.jit import JIT, LEAF

Array = NDArray[np.float64]
M = MAX_ROWS


BIG = active_set.BIG
"""Stand-in for an infinite bound (proxsuite's convention)."""


MIN_ROW_NORM = 1e-12
"""Rows whose gradient in u is smaller than this do not depend on u and are not sent to the QP."""


ACTIVE_MULTIPLIER = 1e-9
"""A row whose multiplier exceeds this at the solution is active (it shapes u)."""


OFF, HARD, SLACKED, DISTANCE = 0, 1, 2, 3
"""How `assemble` takes a constraint's rows: left out; hard; with a slack (its configured weight, or
soften_weight where it has none: cost p delta^2, delta in the row's own units); with a slack whose
cost is soften_weight (delta / |dBC/du|)^2 (the relaxation measured as a distance in u, rad/s^2: rows of
very different scales -- a rate row's gain ~1e-5, a wheel row's ~1e3 -- weigh alike)."""


NO_LEVEL = -1
"""`gave_way` of a call where no priority level gave way."""


@numba.njit(**LEAF)
def usable_quaternion_norm(x: Array) -> float:
    """|q| of the state x (19,) where the filter can use it (every entry finite, |q| within (0.5, 1.5), so
    normalising it is a correction, not a guess); 0 where it cannot (the call is answered as invalid)."""
    for i in range(STATE_SIZE):
        if not math.isfinite(x[i]):
            return 0.0
    q_norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    return q_norm if 0.5 < q_norm < 1.5 else 0.0


@numba.njit(**LEAF)
def prepare(x_in: Array, u_des: Array, t_s: float, f: np.void, ws: np.void, r: np.void) -> tuple[bool, bool, bool]:
    """Validity, rows, box and the fast-path test of one state at time t_s. Returns (valid, u_des finite, QP
    needed). For an invalid state the rows are zero and the box is U."""
    x, t = ws.x, ws.table
    c = f.constraints
    n = c.n_rows
    for i in range(STATE_SIZE):
        x[i] = x_in[i]
    q_norm = usable_quaternion_norm(x)
    valid = q_norm > 0.0
    if valid:
        for i in range(4):
            x[i] = x[i] / q_norm
    else:  # evaluate a harmless placeholder; the call is answered as invalid
        for i in range(STATE_SIZE):
            x[i] = 0.0
        x[3] = 1.0
        x[10] = 273.15
    rows(x, t_s, f.plant, c, ws.ctx, t, ws.lo0, ws.hi0)
    for i in range(n):
        if not math.isfinite(t.drift[i]):
            valid = False
        for a in range(3):
            if not math.isfinite(t.gain[i, a]):
                valid = False
    for a in range(3):
        if not (math.isfinite(t.lo[a]) and math.isfinite(t.hi[a])):
            valid = False
    finite_des = True
    for a in range(3):
        r.u_des[a] = u_des[a]
        if math.isfinite(u_des[a]):
            ws.u_target[a] = u_des[a]
        else:
            ws.u_target[a] = 0.0
            finite_des = False
    if not valid:
        for i in range(n):
            t.drift[i] = 0.0
            ws.gnorm[i] = 0.0
            r.uncontrollable[i] = 0
            for a in range(3):
                t.gain[i, a] = 0.0
        for a in range(3):
            t.lo[a] = -c.u_max_rad_s2[a]
            t.hi[a] = c.u_max_rad_s2[a]
        t.zoh_rows = 0
        return False, finite_des, False
    need = not finite_des
    tol = f.check_tolerance
    for i in range(n):
        g0, g1, g2 = t.gain[i, 0], t.gain[i, 1], t.gain[i, 2]
        ws.gnorm[i] = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        on = c.gains[i].enabled != 0
        depends = ws.gnorm[i] > MIN_ROW_NORM
        r.uncontrollable[i] = 1 if (on and not depends and t.drift[i] < 0) else 0
        if on and depends:
            bc0 = t.drift[i]
            for a in range(3):
                bc0 += t.gain[i, a] * min(max(ws.u_target[a], t.lo[a]), t.hi[a])
            if bc0 < -tol * max(1.0, ws.gnorm[i]):
                need = True
    if c.accel_rows:  # |(G u)_i| <= b_i (rad/s^2)
        G = f.plant.control_matrix
        for i in range(3):
            v = 0.0
            for a in range(3):
                v += G[i, a] * min(max(ws.u_target[a], t.lo[a]), t.hi[a])
            if abs(v) > c.accel_limit_rad_s2[i] + tol:
                need = True
    for q in range(t.zoh_rows):  # the coupled rate rows (rad/s), checked normalised as the QP has them
        v = 0.0
        gn = 0.0
        for a in range(3):
            v += t.zoh_gain[q, a] * min(max(ws.u_target[a], t.lo[a]), t.hi[a])
            gn += t.zoh_gain[q, a] * t.zoh_gain[q, a]
        gn = math.sqrt(gn)
        if v < t.zoh_lo[q] - tol * gn or v > t.zoh_hi[q] + tol * gn:
            need = True
    return True, finite_des, need


@numba.njit(**LEAF)
def row_modes(f: np.void, soften: bool, mode: NDArray[np.int8]) -> None:
    """The modes (M,) of the filter's QP (soften False: slacked where a slack weight is configured, else
    hard) or of the soften fallback's (every enabled constraint slacked)."""
    g = f.constraints.gains
    for i in range(f.constraints.n_rows):
        if not g[i].enabled:
            mode[i] = OFF
        elif soften or g[i].slack_weight > 0:
            mode[i] = SLACKED
        else:
            mode[i] = HARD


@numba.njit(**JIT)
def assemble(f: np.void, ws: np.void, mode: NDArray[np.int8], relax: Array
             ) -> tuple[Array, Array, Array, Array, NDArray[np.int64], NDArray[np.int64], Array]:
    """The QP of the prepared state: min 1/2 |z - z0|^2 s.t. lower <= C z <= upper, z = [u (3); s].

    mode (M,): each constraint's rows OFF (left out, as are disabled constraints and rows that do not
    depend on u), HARD, or SLACKED (a variable s with delta = s / sqrt(p), p its slack weight or
    soften_weight). relax (M + ZOH_ROWS,): how far each constraint row (BC_i + relax_i >= 0) and each
    coupled rate row (both sides, rad/s) is relaxed (the `prioritize` fallback; 0: not). Rows are
    normalised to unit norm; then the coupled rate rows of the table (two-sided, `angular_rate.zoh_rows`,
    reported as and taking the mode of their axis's rate constraint); then the box (three rows); where the wheels
    turn every axis (`accel_rows`), last the angular-acceleration rows |(G u)_i| <= b_i, hard as the box.

    Returns (C (r+3+a, n), lower, upper (r+3+a,), z0 (n,), row_of (r,) constraint of each row,
    slack_var (m,) variable of each constraint's slack or -1, scale (n,) delta = scale * s).
    """
    t = ws.table
    g = f.constraints.gains
    n_rows, omega_x = f.constraints.n_rows, f.constraints.row_omega
    r = 0
    ns = 0
    for i in range(n_rows):
        if g[i].enabled and mode[i] != OFF and ws.gnorm[i] > MIN_ROW_NORM:
            r += 1
            if mode[i] >= SLACKED:
                ns += 1
    nz = 0
    for q in range(t.zoh_rows):
        mq = mode[omega_x + t.zoh_axis[q]]
        if mq != OFF:
            nz += 1
            if mq >= SLACKED:
                ns += 1
    r += nz
    n = 3 + ns
    na = 3 if f.constraints.accel_rows else 0
    C = np.zeros((r + 3 + na, n))
    lower = np.full(r + 3 + na, -BIG)
    upper = np.full(r + 3 + na, BIG)
    row_of = np.empty(r, dtype=np.int64)
    slack_var = np.full(M, -1, dtype=np.int64)
    scale = np.zeros(n)
    k = 0
    v = 3
    for i in range(n_rows):
        if not (g[i].enabled and mode[i] != OFF and ws.gnorm[i] > MIN_ROW_NORM):
            continue
        row_of[k] = i
        for a in range(3):
            C[k, a] = t.gain[i, a]
        if mode[i] >= SLACKED:
            if mode[i] == DISTANCE:
                scale[v] = ws.gnorm[i] / math.sqrt(f.soften_weight)
            else:
                p = g[i].slack_weight if g[i].slack_weight > 0 else f.soften_weight
                scale[v] = 1.0 / math.sqrt(p)
            C[k, v] = scale[v]
            slack_var[i] = v
            v += 1
        ss = 0.0
        for j in range(n):
            ss += C[k, j] * C[k, j]
        norm = math.sqrt(ss)
        for j in range(n):
            C[k, j] = C[k, j] / norm
        lower[k] = -t.drift[i] / norm if relax[i] <= 0.0 else (-t.drift[i] - relax[i]) / norm
        k += 1
    for q in range(t.zoh_rows):
        mq = mode[omega_x + t.zoh_axis[q]]
        if mq == OFF:
            continue
        row_of[k] = omega_x + t.zoh_axis[q]
        for a in range(3):
            C[k, a] = t.zoh_gain[q, a]
        if mq >= SLACKED:
            scale[v] = 1.0 / math.sqrt(f.soften_weight)
            if mq == DISTANCE:
                scale[v] *= _zoh_norm(t, q)
            C[k, v] = scale[v]
            v += 1
        ss = 0.0
        for j in range(n):
            ss += C[k, j] * C[k, j]
        norm = math.sqrt(ss)
        for j in range(n):
            C[k, j] = C[k, j] / norm
        w = relax[M + q]
        lower[k] = t.zoh_lo[q] / norm if w <= 0.0 else (t.zoh_lo[q] - w) / norm
        upper[k] = t.zoh_hi[q] / norm if w <= 0.0 else (t.zoh_hi[q] + w) / norm
        k += 1
    for a in range(3):
        C[r + a, a] = 1.0
        lower[r + a] = t.lo[a]
        upper[r + a] = t.hi[a]
    if na:
        G, b = f.plant.control_matrix, f.constraints.accel_limit_rad_s2
        for i in range(3):
            norm = math.sqrt(G[i, 0] * G[i, 0] + G[i, 1] * G[i, 1] + G[i, 2] * G[i, 2])
            for a in range(3):
                C[r + 3 + i, a] = G[i, a] / norm
            lower[r + 3 + i] = -b[i] / norm
            upper[r + 3 + i] = b[i] / norm
    z0 = np.zeros(n)
    for a in range(3):
        z0[a] = ws.u_target[a]
    return C, lower, upper, z0, row_of, slack_var, scale


@numba.njit(**JIT)
def solve(C: Array, lower: Array, upper: Array, z0: Array, f: np.void, r: np.void
          ) -> tuple[Array, Array, int, int]:
    """The solver step: (z, multipliers in proxsuite's sign convention, SOLVE_RESULTS code, backup code).
    A claimed solution that misses a row by more than check_tolerance counts as SOLVE_CHECK_FAILED."""
    backup = NOT_SOLVED
    if f.solver == ACTIVE_SET:
        z, mult, code, iters = active_set.solve(C, lower, upper, z0, f.max_active_set_iter)
    else:
        z = np.empty(z0.shape[0])
        mult = np.empty(C.shape[0])
        with numba.objmode(code="int64", iters="int64", backup="int64"):
            code, iters, backup = proxsuite_qp.solve(C, lower, upper, z0, f, z, mult)
    r.iterations += iters
    r.solves += 1
    if code == SOLVE_OK and not active_set.rows_hold(C, lower, upper, z, f.check_tolerance):
        code = SOLVE_CHECK_FAILED
    return z, mult, code, backup


@numba.njit(**LEAF)
def extract(z: Array, mult: Array, row_of: NDArray[np.int64], slack_var: NDArray[np.int64], scale: Array,
            ws: np.void, r: np.void) -> None:
    """u (clipped to the box), the slacks and the active rows from a QP solution."""
    t = ws.table
    for a in range(3):
        r.u[a] = min(max(z[a], t.lo[a]), t.hi[a])
    for k in range(row_of.shape[0]):
        i = row_of[k]
        if abs(mult[k]) > ACTIVE_MULTIPLIER:  # (several rows may report one constraint)
            r.intervening[i] = 1
        if slack_var[i] >= 0:
            r.slack[i] = scale[slack_var[i]] * z[slack_var[i]]


@numba.njit(**LEAF)
def finish(n: int, ws: np.void, r: np.void) -> None:
    """BC_i at the final u (slack not included) of the n rows, the box flags, and the table copied into the
    result."""
    t = ws.table
    for i in range(n):
        r.bc[i] = t.drift[i] + (t.gain[i, 0] * r.u[0] + t.gain[i, 1] * r.u[1] + t.gain[i, 2] * r.u[2])
        r.h[i], r.psi0[i], r.psi1[i] = t.h[i], t.psi0[i], t.psi1[i]
    for a in range(3):
        r.lo[a], r.hi[a] = t.lo[a], t.hi[a]
        u, ut = r.u[a], ws.u_target[a]
        r.box_active[a] = 1 if ((u <= t.lo[a] and ut < t.lo[a]) or (u >= t.hi[a] and ut > t.hi[a])) else 0


@numba.njit(**LEAF)
def _zoh_norm(t: np.void, q: int) -> float:
    """|d/du| of coupled rate row q of table t (its gain's norm)."""
    return math.sqrt(t.zoh_gain[q, 0] ** 2 + t.zoh_gain[q, 1] ** 2 + t.zoh_gain[q, 2] ** 2)


@numba.njit(**LEAF)
def _violation(ws: np.void, u: Array, i: int) -> float:
    """How far constraint row i misses at u: max(0, -BC_i(u))."""
    t = ws.table
    bc = t.drift[i] + t.gain[i, 0] * u[0] + t.gain[i, 1] * u[1] + t.gain[i, 2] * u[2]
    return -bc if bc < 0.0 else 0.0


@numba.njit(**LEAF)
def _zoh_violation(ws: np.void, u: Array, q: int) -> float:
    """How far coupled rate row q misses at u (either side), rad/s."""
    t = ws.table
    v = t.zoh_gain[q, 0] * u[0] + t.zoh_gain[q, 1] * u[1] + t.zoh_gain[q, 2] * u[2]
    return max(0.0, t.zoh_lo[q] - v, v - t.zoh_hi[q])


@numba.njit(**JIT)
def prioritize(f: np.void, ws: np.void, r: np.void
               ) -> tuple[bool, Array, Array, NDArray[np.int64], NDArray[np.int64], Array, Array]:
    """The `prioritize` fallback, a lexicographic hierarchy solved exactly by a short sequence of QPs:
    for each level of `filter.priorities` in turn, most important first, the least violation of its
    rows, measured as distances in u (sum of (delta_i / |dBC_i/du|)^2: a QP with the level's rows slacked
    as DISTANCE at soften_weight, against which |u - u_des|^2 weighs ~1e-8), the more important levels hard as
    relaxed so far, the less important left out, the box hard) fixes how far each of its rows is
    relaxed: the violation max(0, -BC_i) at that QP's u (a point where every more important row holds
    as relaxed, so the next QP is feasible by construction); then the filter's own QP (slacks of the
    configured slacked rows as usual) with every row relaxed by that much. Rows with a configured slack
    weight take part in the last QP only (they never make it infeasible). r.gave_way: the most important
    level relaxed (NO_LEVEL if none), r.slack: each relaxed row's relaxation, r.soft_result: the last QP.

    Returns (ok, z, mult, row_of, slack_var, scale, relax) of the last QP (or of the last level's QP if
    the last one failed: its u meets every row as relaxed)."""
    g = f.constraints.gains
    n, omega_x = f.constraints.n_rows, f.constraints.row_omega
    t = ws.table
    mode = np.zeros(M, dtype=np.int8)
    relax = np.zeros(M + ZOH_ROWS)
    u = np.empty(3)
    have = False
    z = np.zeros(3)
    mult = np.zeros(3)
    row_of = np.zeros(0, dtype=np.int64)
    slack_var = np.full(M, -1, dtype=np.int64)
    scale = np.zeros(3)
    for lev in range(f.n_levels):
        rows_here = False
        for i in range(n):
            if not g[i].enabled or g[i].slack_weight > 0 or f.level[i] > lev:
                mode[i] = OFF
            elif f.level[i] == lev:
                mode[i] = DISTANCE
                rows_here = rows_here or ws.gnorm[i] > MIN_ROW_NORM
            else:
                mode[i] = HARD
        for q in range(t.zoh_rows):
            if f.level[omega_x + t.zoh_axis[q]] == lev and g[omega_x + t.zoh_axis[q]].enabled:
                rows_here = True
        if not rows_here:
            continue
        C, lower, upper, z0, ro, sv, sc = assemble(f, ws, mode, relax)
        zl, ml, code, backup = solve(C, lower, upper, z0, f, r)
        if not (code == SOLVE_OK or backup == SOLVE_OK):
            break  # (never expected: the level's rows are slacked, the rest feasible as relaxed)
        for a in range(3):
            u[a] = min(max(zl[a], t.lo[a]), t.hi[a])
        z, mult, row_of, slack_var, scale, have = zl, ml, ro, sv, sc, True
        for i in range(n):
            if mode[i] == DISTANCE and ws.gnorm[i] > MIN_ROW_NORM:
                v = _violation(ws, u, i)
                if v > 0.0:  # (+ the solver's tolerance, a distance in u as the rows are normalised)
                    relax[i] = v + f.check_tolerance * ws.gnorm[i]
        for q in range(t.zoh_rows):
            if mode[omega_x + t.zoh_axis[q]] == DISTANCE:
                v = _zoh_violation(ws, u, q)
                if v > 0.0:
                    relax[M + q] = v + f.check_tolerance * _zoh_norm(t, q)
    # the most important level with a row that misses by more than the solver's tolerance (as a distance)
    tol2 = 2.0 * f.check_tolerance
    top = f.n_levels
    for i in range(n):
        if relax[i] > tol2 * ws.gnorm[i]:
            top = min(top, f.level[i])
    for q in range(t.zoh_rows):
        if relax[M + q] > tol2 * _zoh_norm(t, q):
            top = min(top, f.level[omega_x + t.zoh_axis[q]])
    r.gave_way = top if top < f.n_levels else NO_LEVEL
    row_modes(f, False, mode)
    C, lower, upper, z0, ro, sv, sc = assemble(f, ws, mode, relax)
    zl, ml, code, backup = solve(C, lower, upper, z0, f, r)
    r.soft_result = code if backup == NOT_SOLVED or code == SOLVE_OK else backup
    if code == SOLVE_OK or backup == SOLVE_OK:
        return True, zl, ml, ro, sv, sc, relax
    return have, z, mult, row_of, slack_var, scale, relax


@numba.njit(**JIT)
def answer(x: Array, u_des: Array, t_s: float, f: np.void, ws: np.void, r: np.void) -> bool:
    """The ASIF's answer r.u at state x (19,) and time t_s (s from the run's start: the cones' windows) for the
    desired wheel accelerations u_des (3,): every step of the call but the gate and finish (a pure function of
    x, u_des and t_s: ws is scratch). Returns False for an invalid state, answered (u = 0) and finished here."""
    t = ws.table
    n = f.constraints.n_rows
    for i in range(n):
        r.slack[i] = 0.0
        r.intervening[i] = 0
    r.solver = f.solver
    r.solve_result = r.backup_result = r.soft_result = NOT_SOLVED
    r.qp_failed = r.raise_error = 0
    r.iterations = 0
    r.solves = 0
    r.gate = GATE_OFF
    r.gave_way = NO_LEVEL
    valid, finite_des, need = prepare(x, u_des, t_s, f, ws, r)
    if not valid:
        # no barrier can be trusted: the wheels hold their speed (u = 0), keeping the body rates
        r.u[0] = r.u[1] = r.u[2] = 0.0
        r.status, r.fallback = FALLBACK, INVALID_STATE
        finish(n, ws, r)
        for i in range(n):
            r.h[i] = r.psi0[i] = r.psi1[i] = r.bc[i] = np.nan
        return False
    for a in range(3):
        r.u[a] = min(max(ws.u_target[a], t.lo[a]), t.hi[a])
    if not need:
        r.status, r.fallback = PASS, NO_FALLBACK
        return True
    mode = np.empty(M, dtype=np.int8)
    row_modes(f, False, mode)
    relax = np.zeros(M + ZOH_ROWS)
    C, lower, upper, z0, row_of, slack_var, scale = assemble(f, ws, mode, relax)
    z, mult, code, backup = solve(C, lower, upper, z0, f, r)
    r.solve_result, r.backup_result = code, backup
    ok = code == SOLVE_OK or backup == SOLVE_OK
    reason = NO_FALLBACK if finite_des else NON_FINITE_U_DES
    if not ok:
        r.qp_failed = 1
        reason = POLICY_ACTED
        if f.policy == RAISE:
            r.raise_error = 1
        elif f.policy == SOFTEN:
            row_modes(f, True, mode)
            C, lower, upper, z0, row_of, slack_var, scale = assemble(f, ws, mode, relax)
            z, mult, soft, soft_backup = solve(C, lower, upper, z0, f, r)
            ok = soft == SOLVE_OK or soft_backup == SOLVE_OK
            r.soft_result = SOLVE_OK if ok else soft
        elif f.policy == PRIORITIZE:
            ok, z, mult, row_of, slack_var, scale, relax = prioritize(f, ws, r)
        if not ok and f.policy == HOLD:
            for a in range(3):
                r.u[a] = min(max(0.0, t.lo[a]), t.hi[a])
    if ok:
        extract(z, mult, row_of, slack_var, scale, ws, r)
        if f.policy == PRIORITIZE and r.qp_failed:
            for i in range(n):  # how far each row gave way (a relaxed row has no slack variable)
                if relax[i] > 0.0:
                    r.slack[i] = relax[i]
            for q in range(t.zoh_rows):
                i = f.constraints.row_omega + t.zoh_axis[q]
                r.slack[i] = max(r.slack[i], relax[M + q])
    r.fallback = reason
    r.status = FALLBACK if reason != NO_FALLBACK else SOLVED
    return True
