"""One filter call, compiled: the one pipeline every path runs (simulate, the filter node, the Monte
Carlo), with the QP solver as a pluggable step.

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
               or `prioritize` (`filter.priorities`: the least important level gives way first, each
               level by as little as possible, one small QP per level and a last one for u)
    gate       with a backup law (`filter.backup_law`): the gatekeeper (`filter.backup`) applies u only
               if u held for a sample, then the backup law, is safe over the horizon on the filter's
               model; else the backup law of its committed plan (the workspace keeps the plan)
    finish     BC_i at the final u, which box bounds clipped u

Parameters travel as one FILTER_DTYPE record (the filter's plant model, the constraints, the
policy and solver settings); scratch as one WORKSPACE_DTYPE record; the result is one RESULT_DTYPE
record (`filter.asif` reads it). `filter_many` runs the same call over a batch.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import MAX_NOMINAL_STEPS, Config
from rta_attitude.constraints.base import (
    CONSTRAINT_DTYPE,
    MAX_ROWS,
    TABLE_DTYPE,
    ZOH_ROWS,
    constraint_record,
    drive_lag,
)
from rta_attitude.constraints.geometry import CONTEXT_DTYPE
from rta_attitude.constraints.registry import levels
from rta_attitude.constraints.rows import rows
from rta_attitude.dynamics.spacecraft import PLANT_DTYPE, plant_record
from rta_attitude.dynamics.state import STATE_SIZE
from rta_attitude.filter import active_set, outcome, proxsuite_qp
from rta_attitude.filter.backup import (
    BACKUP_DTYPE,
    FAILED,
    GATE_DTYPE,
    HORIZON,
    NO_LAW,
    SETTLED,
    SUN_SAFE_VARIANT,
    VARIANTS,
    apply_measurement_margins,
    backup_record,
    backup_tail,
    commit,
    energy_reserve,
    gate,
    hold_sample,
    large_momentum,
    predict,
    predicted,
    same_answer,
    settled,
    sun_safe_command,
    variant_at,
    verify,
)
from rta_attitude.filter.outcome import (
    ACTIVE_SET,
    FALLBACK,
    GATE_BACKUP,
    GATE_FILTERED_BACKUP,
    GATE_OFF,
    GATE_TOWARD_BACKUP,
    GATE_UNVERIFIED,
    GATE_VERIFIED,
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
"""Rows of every per-constraint array (the capacity); a call uses the configuration's n_rows of them."""

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

FILTER_DTYPE = np.dtype([
    ("plant", PLANT_DTYPE),                  # the filter's model of the spacecraft
    ("constraints", CONSTRAINT_DTYPE),
    ("policy", np.int8),                     # outcome.FALLBACKS code
    ("solver", np.int8),                     # outcome.SOLVERS code
    ("backup_solver", np.int8),              # outcome.BACKUP_SOLVERS code (proxsuite only)
    ("check_tolerance", np.float64),         # a solution must meet every row to this
    ("soften_weight", np.float64),           # slack weight of every row in the soften fallback
    ("max_active_set_iter", np.int64),
    ("eps_abs", np.float64),                 # proxsuite settings
    ("eps_primal_inf", np.float64),
    ("eps_dual_inf", np.float64),
    ("max_iterations", np.int64),
    ("max_inner_iterations", np.int64),
    ("backup", BACKUP_DTYPE),                # the gatekeeper (backup law NO_LAW: off)
    ("level", np.int64, (M,)),               # priority level of each constraint (0: most important)
    ("n_levels", np.int64),
    ("lag_gain", np.float64),                # the drive's lag compensated: c and e of `constraints.base.drive_lag`
    ("lag_decay", np.float64),               # (0: not compensated)
])  # fmt: skip
"""Everything one filter call reads, by name."""

RESULT_DTYPE = np.dtype([
    ("u", np.float64, (3,)),                 # u_act, rad/s^2, the command sent: finite, inside U
    ("u_held", np.float64, (3,)),            # the filter's answer: what the wheels hold over the sample (u
    # but where the drive's lag is compensated: `drive_command`)
    ("u_des", np.float64, (3,)),             # as received
    ("h", np.float64, (M,)),                 # physical h at x
    ("psi0", np.float64, (M,)),              # HOCBF levels at x
    ("psi1", np.float64, (M,)),
    ("bc", np.float64, (M,)),                # barrier conditions at u (slack not included)
    ("slack", np.float64, (M,)),             # delta_i of slacked rows
    ("intervening", np.uint8, (M,)),         # rows active at the solution
    ("uncontrollable", np.uint8, (M,)),      # rows violated whatever u is (no gradient in u)
    ("box_active", np.uint8, (3,)),          # axes the box clipped
    ("lo", np.float64, (3,)),                # the box
    ("hi", np.float64, (3,)),
    ("status", np.int8),                     # outcome.STATUS_NAMES code
    ("fallback", np.int8),                   # outcome.FALLBACK_REASONS code
    ("solver", np.int8),                     # the solver of the first QP (outcome.SOLVERS code)
    ("solve_result", np.int8),               # outcome.SOLVE_RESULTS code of the first QP, NOT_SOLVED if none
    ("backup_result", np.int8),              # quadprog's re-solve of it (proxsuite), NOT_SOLVED if none
    ("soft_result", np.int8),                # the soften fallback's QP, NOT_SOLVED if none
    ("qp_failed", np.uint8),                 # the first QP failed (the policy acted)
    ("raise_error", np.uint8),               # policy `raise` and the QP failed: Python raises
    ("gate", np.int8),                       # outcome.GATE_NAMES code: what the gatekeeper did
    ("gave_way", np.int8),                   # prioritize: the most important level that gave way (NO_LEVEL)
    ("iterations", np.int64),                # solver iterations of every solve of the call
    ("solves", np.int64),                    # QP solves of the call (a proxsuite solve and its re-solve: one)
    ("solve_time_s", np.float64),            # wall time of the whole call (set by the Python face)
])  # fmt: skip
"""What one filter call did, for one state (a batch: a leading axis)."""

WORKSPACE_DTYPE = np.dtype([
    ("ctx", CONTEXT_DTYPE),
    ("table", TABLE_DTYPE),
    ("x", np.float64, (STATE_SIZE,)),        # the state, quaternion normalised
    ("lo0", np.float64, (3,)),               # what the drive can hold this call (`drive_box`; the rows' box)
    ("hi0", np.float64, (3,)),
    ("u_target", np.float64, (3,)),          # u_des with non-finite entries set to 0
    ("gnorm", np.float64, (M,)),             # |dBC/du| of each row
    ("gate", GATE_DTYPE),                    # the gatekeeper's committed plan and scratch (memory!)
    ("result", RESULT_DTYPE),                # scratch: the answers the gatekeeper's nominal plan predicts
])  # fmt: skip
"""Scratch and memory of one filter: a WORKSPACES-long array (`new_workspace`); the call uses the first,
the gatekeeper's nominal plan runs the filter's own answers in the second."""
WORKSPACES = 2


def filter_record(cfg: Config) -> NDArray[np.void]:
    """The FILTER_DTYPE record (1,) of a configuration."""
    rec = np.zeros(1, FILTER_DTYPE)
    f = rec[0]
    f["plant"] = plant_record(cfg, cfg.filter.model)[0]
    f["constraints"] = constraint_record(cfg)[0]
    o = cfg.filter
    f["policy"] = outcome.FALLBACKS.index(o.fallback)
    f["solver"] = outcome.SOLVERS.index(o.solver)
    f["backup_solver"] = outcome.BACKUP_SOLVERS.index(o.backup_solver)
    f["check_tolerance"], f["soften_weight"] = o.check_tolerance, o.soften_weight
    f["max_active_set_iter"] = active_set.MAX_ACTIVE_SET_ITER
    f["eps_abs"], f["eps_primal_inf"], f["eps_dual_inf"] = o.eps_abs, o.eps_primal_inf, o.eps_dual_inf
    f["max_iterations"], f["max_inner_iterations"] = o.max_iterations, o.max_inner_iterations
    f["backup"] = backup_record(cfg)[0]
    f["level"][: len(cfg.constraint_names)] = levels(cfg)
    f["n_levels"] = len(cfg.priority_levels)
    f["lag_gain"], f["lag_decay"] = drive_lag(cfg)
    apply_measurement_margins(rec, cfg)  # the backup law inside its rollouts' margins (sensor errors on)
    return rec


def new_workspace() -> NDArray[np.void]:
    """A workspace record array (WORKSPACES,): scratch, and the gatekeeper's plan (none yet)."""
    return np.zeros(WORKSPACES, WORKSPACE_DTYPE)


# ----------------------------------------------------------------------------- steps


@numba.njit(**LEAF)
def prepare(x_in: Array, u_des: Array, t_s: float, f: np.void, ws: np.void, r: np.void) -> tuple[bool, bool, bool]:
    """Validity, rows, box and the fast-path test of one state at time t_s. Returns (valid, u_des finite, QP
    needed). For an invalid state the rows are zero and the box is U."""
    x, t = ws.x, ws.table
    c = f.constraints
    n = c.n_rows
    valid = True
    for i in range(STATE_SIZE):
        x[i] = x_in[i]
        if not math.isfinite(x[i]):
            valid = False
    q_norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]) if valid else 0.0
    if not (0.5 < q_norm < 1.5):
        valid = False
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
    reported as and taking the mode of their axis's rate constraint); the last three rows are the box.

    Returns (C (r+3, n), lower, upper (r+3,), z0 (n,), row_of (r,) constraint of each row,
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
    C = np.zeros((r + 3, n))
    lower = np.full(r + 3, -BIG)
    upper = np.full(r + 3, BIG)
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


# ----------------------------------------------------------------------------- the call


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


@numba.njit(**JIT)
def plan_nominal(x: Array, u: Array, u_des: Array, N: int, f: np.void, wsa: NDArray[np.void]) -> bool:
    """The gatekeeper's nominal plan from the state x (19,): u (3,) held for a sample, then for N - 1
    samples the filter's own answer (`answer`, u_des held) at each predicted state, then the backup law
    (the committed plan's variant, the momentum mode only with a large momentum) until it settles (small
    momentum) or to the horizon (large), every sample checked at every substep (`backup.hold_sample`).
    On success the plan is committed: its states and answers at the samples go to the gate's plan_x,
    plan_u (later calls at those states with those answers are applied without a rollout: `gate_call`),
    its state after them to next_x. Returns False (nothing committed) at the first violation or invalid
    state."""
    b = f.backup
    g, inner = wsa[0].gate, wsa[1]
    large = large_momentum(x, f.plant, b)
    g.law = g.plan_law if (g.plan_law == SUN_SAFE_VARIANT or large) else SUN_SAFE_VARIANT
    for i in range(STATE_SIZE):
        g.x[i] = x[i]
    g.checked = 0
    g.t = g.t_call
    g.candidate = 1  # the filter's own answers: a candidate's margins
    for j in range(N):
        if j == 0:
            for i in range(STATE_SIZE):
                g.plan_x[0, i] = g.x[i]
            for a in range(3):
                g.plan_u[0, a] = u[a]
        else:  # the filter's answer to the predicted state as it will receive it
            predict(g.x, b, g, g.plan_x[j])
            if not answer(g.plan_x[j], u_des, g.t, f, inner, inner.result):
                return False
            for a in range(3):
                g.plan_u[j, a] = inner.result.u[a]
        if not hold_sample(g.plan_u[j], f, g, g.subs, False):
            return False
    for i in range(STATE_SIZE):
        g.first_x[i] = g.x[i]
    found = backup_tail(f, g, g.subs, False)
    if not (found == SETTLED or (found == HORIZON and large and energy_reserve(g.x, f.plant, f.constraints, b, g))):
        return False
    commit(g.first_x, g.law, found == SETTLED, False, b, g)
    g.plan_steps = b.horizon_steps + N - 1  # the nominal samples, then the backup law's horizon
    g.plan_n = N
    g.plan_at = 1
    return True


@numba.njit(**JIT)
def _filtered_rollout(x: Array, law: int, n: int, f: np.void, wsa: NDArray[np.void], xr: Array, ul: Array
                      ) -> tuple[int, int]:
    """One rollout of `plan_filtered` for the variant law from x: (FAILED, HORIZON or SETTLED; how many
    samples went to plan_x, plan_u: its first n samples' states as received and commands); g.x its last
    state."""
    b = f.backup
    p = f.plant
    g, inner = wsa[0].gate, wsa[1]
    g.law = law
    g.candidate = 0
    g.checked = 0
    g.t = g.t_call
    for i in range(STATE_SIZE):
        g.x[i] = x[i]
    for j in range(b.horizon_steps + 1):
        if j > 0 and settled(g.x, p, b, g):
            return SETTLED, min(j, n)
        if j == 0:
            for i in range(STATE_SIZE):
                xr[i] = x[i]
        else:
            predict(g.x, b, g, xr)
        sun_safe_command(xr, p, f.constraints, b, g, ul)
        if not answer(xr, ul, g.t, f, inner, inner.result):
            return FAILED, min(j, n)
        if j < n:
            for i in range(STATE_SIZE):
                g.plan_x[j, i] = xr[i]
            for a in range(3):
                g.plan_u[j, a] = inner.result.u[a]
        if not hold_sample(inner.result.u, f, g, g.subs, False):
            return FAILED, min(j + 1, n)
    return HORIZON, min(b.horizon_steps + 1, n)


@numba.njit(**JIT)
def plan_filtered(x: Array, f: np.void, wsa: NDArray[np.void], u: Array) -> bool:
    """The backup law filtered by the ASIF: for each variant in `verify`'s order, a rollout from the state x
    (19,) as received whose every sample holds the filter's answer (`answer`) to the law's command, both at
    the state as the filter will receive it (`predict`), checked at every substep (`hold_sample`), to the
    terminal set or (large momentum) to the horizon with the energy reserve; failing that, the first variant
    safe to the horizon without the reserve (as `backup.commit_weak` for the law's own plans). The law knows
    nothing of the keep-out cone and the other rows; the ASIF's rows steer its slew round them. On success
    the first nominal_steps samples are committed as a plan (plan_x, plan_u: later calls at those states
    apply its commands, `gate_call`) and u := its first command."""
    b = f.backup
    p = f.plant
    g = wsa[0].gate
    large = large_momentum(x, p, b)
    n = min(max(b.nominal_steps, 1), MAX_NOMINAL_STEPS)
    xr = np.empty(STATE_SIZE)
    ul = np.empty(3)
    weak = -1
    chosen = -1
    recorded = 0
    for t in range(len(VARIANTS)):
        law = variant_at(t, g.plan_law, large)
        if law < 0:
            continue
        found, recorded = _filtered_rollout(x, law, n, f, wsa, xr, ul)
        if found == SETTLED:
            chosen = law
            break
        if found == HORIZON and large:
            if energy_reserve(g.x, p, f.constraints, b, g):
                chosen = law
                break
            if weak < 0:
                weak = law
    if chosen < 0 and weak >= 0:
        chosen = weak
        _, recorded = _filtered_rollout(x, weak, n, f, wsa, xr, ul)  # its plan again (a later one overwrote it)
    if chosen < 0:
        return False
    for a in range(3):
        u[a] = g.plan_u[0, a]
    g.plan_n = recorded  # (a plan that settles within n samples holds fewer)
    g.plan_at = 1
    g.plan_steps = 0
    g.has_next = 0
    g.plan_law = chosen
    return True


FILTERED_BACKOFF_MAX = 16
"""Where nothing verifies call after call, the backup law through the filter (`plan_filtered`: up to 5 x 300
QPs a call) is tried at the first such call, then after waits of 1, 2, 4, 8, then 16 calls between tries
(reset when `backup.gate` finds a way out, the candidate, the law's own command or the committed plan's, or a
filtered plan is found; calls answered from a nominal plan, or by a new one, return before and leave it)."""
UNIT_TOLERANCE = 1e-12
"""The gatekeeper's rollouts start from the state as received where its quaternion's norm is within this of
1 (the plant's always is: it renormalises at every substep), so that they predict the plant bit for bit;
from the normalised state otherwise."""


@numba.njit(**JIT)
def gate_call(x: Array, u_des: Array, t_s: float, f: np.void, wsa: NDArray[np.void], r: np.void) -> int:
    """The gatekeeper at the state x (19,) as received at time t_s with the filter's answer r.u (replaced in
    place by the command to apply); returns its GATE_NAMES code. Its rollouts start at t_s (g.t_call): a cone's
    windows apply at the times they reach. In order:

    - on a committed nominal plan (x and r.u are the state and answer it predicted for this sample:
      `backup.predicted`, `backup.same_answer`, bit for bit but for the interface's roundings) -> apply the
      plan's answer, verified by that plan's rollout;
    - a new nominal plan (`plan_nominal`, nominal_steps samples; after one fails, or after a call that was
      not the one its plan predicted (sensor noise, another u_des), not tried again for nominal_steps
      calls: halving the plan after a failure saved 10 % of the CPU and lost one more of 1,000 runs);
    - on the plan's state but with another answer (u_des changed) -> that answer alone (`backup.verify`),
      else the plan's own answer for this sample, and the plan goes on;
    - otherwise `backup.gate` (the answer held a sample then the backup law); where that finds nothing
      verified (`unverified`, `toward_backup`), the backup law through the filter (`plan_filtered`) ->
      its first command (`filtered_backup`); tried at the first such call, then after growing waits while
      nothing verifies (FILTERED_BACKOFF_MAX)."""
    b = f.backup
    if b.law == NO_LAW:
        return GATE_OFF
    ws = wsa[0]
    g = ws.gate
    g.t_call = t_s
    n2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]
    raw = abs(n2 - 1.0) <= UNIT_TOLERANCE  # where the rollouts start (UNIT_TOLERANCE)
    xs = g.x0  # (a copy: numba cannot pick between the two arrays, x read-only and ws.x)
    for i in range(STATE_SIZE):
        xs[i] = x[i] if raw else ws.x[i]
    at = g.plan_at
    on_plan = at < g.plan_n and predicted(x, g.plan_x[at])
    if on_plan:
        if same_answer(r.u, g.plan_u[at], f.constraints.u_max_rad_s2):  # the plan's, verified, answer
            for a in range(3):
                r.u[a] = g.plan_u[at, a]
            g.plan_at += 1
            g.plan_steps -= 1
            g.reused += 1
            return GATE_VERIFIED
        # u_des is not the one the plan held: no new nominal plan for a while; the answer alone, else the
        # plan's own answer (its rows are intact: no nominal plan was tried)
        g.nominal_wait = max(g.nominal_wait, b.nominal_steps)
        if verify(xs, r.u, True, f, g):
            g.plan_n = g.plan_at = 0
            return GATE_VERIFIED
        for a in range(3):
            r.u[a] = g.plan_u[at, a]
        g.plan_at += 1
        g.plan_steps -= 1
        return GATE_BACKUP
    if at < g.plan_n:  # off the plan's state (noise, another model): no new nominal plan for a while
        g.nominal_wait = max(g.nominal_wait, b.nominal_steps)
    g.plan_n = g.plan_at = 0
    if b.nominal_steps > 1:
        if g.nominal_wait > 0:
            g.nominal_wait -= 1
        elif plan_nominal(xs, r.u, u_des, b.nominal_steps, f, wsa):
            return GATE_VERIFIED
        else:
            g.nominal_wait = b.nominal_steps
    code = gate(xs, f, g, r.u)
    if not (code == GATE_UNVERIFIED or code == GATE_TOWARD_BACKUP):
        g.filtered_wait = g.filtered_backoff = 0  # gate found a way out: the next search starts afresh
        return code
    if g.filtered_wait > 0:  # the last tries found nothing (FILTERED_BACKOFF_MAX)
        g.filtered_wait -= 1
        return code
    g.filtered_tries += 1
    if plan_filtered(xs, f, wsa, r.u):
        g.filtered_backoff = 0
        return GATE_FILTERED_BACKUP
    g.filtered_wait = g.filtered_backoff
    g.filtered_backoff = min(max(2 * g.filtered_backoff, 1), FILTERED_BACKOFF_MAX)
    return code


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


@numba.njit(**JIT)
def filter_state(x: Array, u_des: Array, t_s: float, f: np.void, wsa: NDArray[np.void], r: np.void) -> None:
    """One whole filter call: state x (19,) at time t_s (s from the run's start), desired wheel accelerations
    u_des (3,) -> result record r (its answer u_held, the command u that makes the drive hold it:
    `drive_command`); wsa: the filter's workspaces (`new_workspace`)."""
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


__all__ = [
    "ACTIVE_MULTIPLIER", "BIG", "DISTANCE", "FILTER_DTYPE", "HARD", "MIN_ROW_NORM", "NO_LEVEL", "OFF", "RESULT_DTYPE",
    "SLACKED", "WORKSPACES", "WORKSPACE_DTYPE", "answer", "assemble", "drive_box", "drive_command",
    "extract", "filter_many", "filter_record", "filter_state", "finish", "gate_call", "new_workspace", "plan_nominal",
    "prepare", "prioritize", "row_modes", "solve",
]  # fmt: skip
