"""Direct multiple shooting on the zero-order-hold grid, with exact derivatives from per-step blocks.

Decision variables z = [z_x,0 .. z_x,N (13 each), z_u,0 .. z_u,N-1 (3 each)], scaled
(z_x = x / x_scale, z_u = u / U_max, so the box U is z_u in [-1, 1]); z_x,0 is pinned by bounds. Per
step k: the defect F(x_k, u_k) / x_scale - z_x,k+1 = 0 (F: the plant's RK4 substeps, q renormalised
after each, smooth bounds of max(0, .)), the constraint rows at substeps 1 .. S-1 and at node k; then
the rows at node N. Wheel rows only at the nodes: psi is affine within a held step (RK4 integrates it
exactly), so |psi_i| peaks at an end of the step. Every row is tightened by margin * scale.

Rows (`row_names`, in the registry's order): one per enforced pointing constraint, c = e . r_B, the cosine of
the angle between its boresight e and its target r (body axes, `model.ca_cone_cos`), for any boresight and
target: keep_out c <= cos(alpha) - d, keep_in c >= cos(alpha) + d (arccos is decreasing). A cone
with time windows has its row bounded only at the nodes and substeps whose time (t0 + dt i / substeps, t0 the
start state's time) lies inside a window; elsewhere the row is free (`g_bounds`). Then T / 100 <= (T_max - d) /
100, E / 1000 >= (E_min + d) / 1000, |w_i / w_max| and |psi_i / psi_max| (nodes only) within (limit - d) /
limit, each bounded where its group is enforced; d = margin * the group's scale (1 for a cone, T_max, 1000 J,
w_max, psi_max).

Objective (this is a feasibility problem; a regulariser): 1e-2 mean |z_u|^2 + mean_k |w_k / w_max|^2,
plus, for a receding segment, the parking cost at x_N (`_terminal_cost`): (1 - p . r_S) + sum over the
enforced keep_out cones about the sun of (e_perp . r_S)^2 + |w / w_max|^2, p the panel's normal and e_perp the
part of a cone's boresight perpendicular to it (the paper's: (1 - k_B . r_S) + (i_B . r_S)^2 + |w / w_max|^2).

Speed: the step map G, its Jacobian JG and the Hessian HG of lam^T G are generated once per model as
casadi SX, compiled to C with the system's C compiler and cached (`cache_dir`), then mapped over the
steps on 2 threads; the NLP's jac_g and hess_lag are assembled from them by fixed index maps, so casadi
never differentiates the RK4 chain at run time. Without a compiler (or with compile=False) the same
functions run in casadi's virtual machine (same numbers, about 10x slower).
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from rta_attitude.dynamics.environment import SUN
from rta_attitude.viability.model import ca_along, ca_attitude, ca_cone_cos, ca_dynamics, ca_sun_hill, rk4_chain
from rta_attitude.viability.params import (
    BATTERY,
    KEEP_IN,
    KEEP_OUT,
    N_X,
    POINTING_KINDS,
    RATE,
    TEMPERATURE,
    WHEEL_SPEED,
    OracleModel,
)

Array = NDArray[np.float64]
log = logging.getLogger(__name__)

CACHE_ENV = "RTA_ATTITUDE_CACHE_DIR"
"""Overrides where the compiled blocks are kept."""
COMPILE_FLAGS: tuple[str, ...] = ("-O1", "-shared", "-fPIC")
"""C compiler flags: -O1 compiles in minutes once per model; -O2 takes much longer for little gain."""
THREADS = 2
"""Threads over which the per-step blocks are mapped."""


def cache_dir() -> Path:
    """$RTA_ATTITUDE_CACHE_DIR, else $XDG_CACHE_HOME/rta_attitude/viability, else ~/.cache/rta_attitude/viability."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "rta_attitude" / "viability"


def enforced_cones(m: OracleModel, enforce: tuple[str, ...]) -> tuple[int, ...]:
    """Indices (into m.cones) of the enforced pointing constraints: the cones that get rows."""
    return tuple(j for j, c in enumerate(m.cones) if c.name in enforce)


def row_names(m: OracleModel, cones: tuple[int, ...], node: bool) -> tuple[str, ...]:
    """Rows at a node (`node`) or at an interior substep: the cones `cones` (indices into m.cones), then every
    constraint that is not a cone, in the registry's order (no wheel rows at an interior substep)."""
    names = [m.cones[j].name for j in cones]
    names += [name for name, _, kind in m.constraints
              if kind not in POINTING_KINDS and (node or kind != WHEEL_SPEED)]
    return tuple(names)


def _rows_of(m: OracleModel) -> dict[str, tuple[str, str, int]]:
    """{row name: (group, kind, axis)}: axis, a per-axis row's index within its group (0 for the others)."""
    out: dict[str, tuple[str, str, int]] = {}
    seen: dict[str, int] = {}
    for name, group, kind in m.constraints:
        out[name] = (group, kind, seen.get(group, 0))
        seen[group] = seen.get(group, 0) + 1
    return out


def ca_rows(x: ca.SX, names: tuple[str, ...], m: OracleModel) -> ca.SX:
    """Scaled row values (module docstring): a cone's cos(boresight, target), T / 100, E / 1000, w_i / w_max,
    psi_i / psi_max."""
    xs = m.x_scale
    info = _rows_of(m)
    a = ca_attitude(x[0:4])  # unused (no node) without a cone row
    out = []
    for name in names:
        group, kind, axis = info[name]
        if kind in POINTING_KINDS:
            out.append(ca_cone_cos(x, a, m.cone(group), m))
        elif kind == TEMPERATURE:
            out.append(x[10] / xs[10])
        elif kind == BATTERY:
            out.append(x[11] / xs[11])
        elif kind == RATE:
            out.append(x[4 + axis] / xs[4 + axis])
        elif kind == WHEEL_SPEED:
            out.append(x[7 + axis] / xs[7 + axis])
        else:
            raise ValueError(f"row {name!r} has kind {kind!r}, which the oracle does not model")
    return ca.vertcat(*out)


def row_bounds(names: tuple[str, ...], enforce: tuple[str, ...], margin: float, m: OracleModel) -> tuple[Array, Array]:
    """(lo, hi) of the rows `names`, tightened by margin * scale; +-inf where not enforced (windows aside:
    `g_bounds`)."""
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    xs = m.x_scale
    info = _rows_of(m)
    for j, name in enumerate(names):
        group, kind, _ = info[name]
        if group not in enforce:
            continue
        d = margin * m.scale(group)
        if kind == KEEP_OUT:
            hi[j] = np.cos(m.cone(group).half_angle_rad) - d
        elif kind == KEEP_IN:
            lo[j] = np.cos(m.cone(group).half_angle_rad) + d
        elif kind == TEMPERATURE:
            hi[j] = (m.temperature_max_K - d) / xs[10]
        elif kind == BATTERY:
            lo[j] = (m.energy_min_J + d) / xs[11]
        elif kind == RATE:
            lo[j], hi[j] = -(m.omega_max_rad_s - d) / xs[4], (m.omega_max_rad_s - d) / xs[4]
        elif kind == WHEEL_SPEED:
            lo[j], hi[j] = -(m.psi_keep_rad_s - d) / xs[7], (m.psi_keep_rad_s - d) / xs[7]
    return lo, hi


def n_block_out(m: OracleModel, cones: tuple[int, ...]) -> int:
    return N_X + (m.substeps - 1) * len(row_names(m, cones, False)) + len(row_names(m, cones, True))


def g_layout(n_steps: int, m: OracleModel, cones: tuple[int, ...]) -> tuple[NDArray[np.str_], NDArray[np.int64]]:
    """What each entry of the NLP's g is: (row name, '' for a shooting defect; the index i of the state it is
    evaluated at, time t0 + dt i / substeps, -1 for a defect). Per step k: the defects, the rows at substeps
    k S + 1 .. k S + S - 1, the rows at node k (i = k S); then the rows at node N."""
    S = m.substeps
    inner, node = row_names(m, cones, False), row_names(m, cones, True)
    block_names = np.array([""] * N_X + list(inner) * (S - 1) + list(node))
    block_index = np.concatenate([np.full(N_X, -1), np.repeat(np.arange(1, S), len(inner)), np.zeros(len(node))])
    k = np.repeat(np.arange(n_steps), len(block_names))
    index = np.tile(block_index, n_steps) + np.where(np.tile(block_index, n_steps) >= 0, S * k, 0)
    names = np.concatenate([np.tile(block_names, n_steps), np.array(node)])
    return names, np.concatenate([index, np.full(len(node), S * n_steps)]).astype(np.int64)


def g_bounds(n_steps: int, m: OracleModel, cones: tuple[int, ...], enforce: tuple[str, ...], margin: float,
             t0_s: float = 0.0) -> tuple[Array, Array]:
    """(lbg, ubg) of the NLP's g (`g_layout`): the defects = 0; the rows by `row_bounds`, free at node 0 (the
    start state is fixed) and, for a cone with windows, at every state whose time is outside its windows."""
    S = m.substeps
    lo_s, hi_s = row_bounds(row_names(m, cones, False), enforce, margin, m)
    lo_n, hi_n = row_bounds(row_names(m, cones, True), enforce, margin, m)
    zero = np.zeros(N_X)
    blk_lo = np.concatenate([zero, np.tile(lo_s, S - 1), lo_n])
    blk_hi = np.concatenate([zero, np.tile(hi_s, S - 1), hi_n])
    first_lo, first_hi = blk_lo.copy(), blk_hi.copy()
    first_lo[len(blk_lo) - len(lo_n):], first_hi[len(blk_hi) - len(hi_n):] = -np.inf, np.inf  # x_0: constants
    lbg = np.concatenate([first_lo, np.tile(blk_lo, n_steps - 1), lo_n])
    ubg = np.concatenate([first_hi, np.tile(blk_hi, n_steps - 1), hi_n])
    windowed = [m.cones[j] for j in cones if m.cones[j].windows_s]
    if windowed:
        names, index = g_layout(n_steps, m, cones)
        for cone in windowed:
            rows = np.flatnonzero(names == cone.name)
            off = rows[~cone.applies(t0_s + m.dt_s * (index[rows] / S))]
            lbg[off], ubg[off] = -np.inf, np.inf
    return lbg, ubg


@lru_cache(maxsize=8)
def block_functions(m: OracleModel, cones: tuple[int, ...]) -> tuple[ca.Function, ca.Function, ca.Function]:
    """G(z_x, z_u) = [F / x_scale; rows at substeps 1 .. S-1; rows at x], JG (Jacobian, 16 columns),
    HG(z_x, z_u, lam) = triu(Hessian of lam^T G), all in scaled variables (casadi VM functions); `cones`: the
    pointing constraints with rows (indices into m.cones)."""
    zx = ca.SX.sym("zx", N_X)
    zu = ca.SX.sym("zu", 3)
    x = zx * ca.DM(m.x_scale)
    u = zu * ca.DM(m.u_max)
    subs = rk4_chain(ca_dynamics(m, exact=False), x, u, m)
    inner = row_names(m, cones, False)
    rows = [ca_rows(s, inner, m) for s in subs[:-1]]
    out = ca.vertcat(subs[-1] / ca.DM(m.x_scale), *rows, ca_rows(x, row_names(m, cones, True), m))
    zz = ca.vertcat(zx, zu)
    lam = ca.SX.sym("lam", out.shape[0])
    hess, _ = ca.hessian(ca.dot(lam, out), zz)
    tag = m.name + "".join(f"_c{j}" for j in cones)
    return (ca.Function(f"G_{tag}", [zx, zu], [out]),
            ca.Function(f"JG_{tag}", [zx, zu], [ca.jacobian(out, zz)]),
            ca.Function(f"HG_{tag}", [zx, zu, lam], [ca.triu(hess)]))


@lru_cache(maxsize=8)
def compiled_blocks(m: OracleModel, cones: tuple[int, ...], compiled: bool = True) -> tuple[ca.Function, ...]:
    """`block_functions`, compiled to C and loaded from `cache_dir()` (built on first use, keyed by a
    hash of the generated source and the flags, written atomically). The VM functions without a C
    compiler or with compiled=False."""
    funcs = block_functions(m, cones)
    cc = shutil.which("gcc") or shutil.which("cc")
    if not compiled or cc is None:
        return funcs
    where = cache_dir()
    where.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=where) as tmp:
        tag = funcs[0].name()[2:]
        gen = ca.CodeGenerator(f"blocks_{tag}.c", {"with_header": False})
        for fn in funcs:
            gen.add(fn)
        gen.generate(tmp + os.sep)
        src = Path(tmp) / f"blocks_{tag}.c"
        digest = hashlib.sha256(src.read_bytes() + " ".join(COMPILE_FLAGS).encode()).hexdigest()[:16]
        lib = where / f"blocks_{tag}_{digest}.so"
        if not lib.exists():
            log.warning("compiling the viability oracle's %s blocks to %s (once; a few minutes)", tag, lib)
            part = Path(tmp) / lib.name
            subprocess.run([cc, *COMPILE_FLAGS, "-o", str(part), str(src)], check=True)
            os.replace(part, lib)
    return tuple(ca.external(fn.name(), str(lib)) for fn in funcs)


@dataclass
class Nlp:
    """A transcribed problem: casadi's nlpsol dict, the derivative options, sizes."""

    problem: dict[str, Any]
    opts: dict[str, Any]
    n_steps: int
    n_z: int


def _terminal_cost(zx: ca.SX, m: OracleModel, cones: tuple[int, ...]) -> ca.SX:
    """Parking cost at the last node: (1 - p . r_S) + sum over the enforced keep_out cones about the sun of
    (e_perp . r_S)^2 + |w / w_max|^2 (p the panel's normal, e_perp the part of a cone's boresight perpendicular
    to p: zero with the panel on the sun; module docstring)."""
    x = zx * ca.DM(m.x_scale)
    s_b = ca_attitude(x[0:4]) @ ca_sun_hill(x[12], m)
    p = np.array(m.panel_normal_body)
    cost = 1.0 - ca_along(m.panel_normal_body, s_b)
    for j in cones:
        cone = m.cones[j]
        if cone.kind == KEEP_OUT and cone.target_kind == SUN:
            e = np.array(cone.boresight_body)
            e_perp = e - (e @ p) * p
            if np.linalg.norm(e_perp) > 1e-9:
                cost = cost + ca_along(tuple(float(v) for v in e_perp), s_b) ** 2
    return cost + ca.sumsqr(zx[4:7])


@lru_cache(maxsize=16)
def build_nlp(n_steps: int, m: OracleModel, terminal: bool, cones: tuple[int, ...], compiled: bool = True) -> Nlp:
    """The multiple-shooting NLP over n_steps holds (module docstring), with rows for the pointing constraints
    `cones` (indices into m.cones, `enforced_cones`); bounds are given per solve (`g_bounds`)."""
    g_f, jg_f, hg_f = compiled_blocks(m, cones, compiled)
    n_out = n_block_out(m, cones)
    node_names = row_names(m, cones, True)
    n = n_steps
    nxv = N_X * (n + 1)
    n_z = nxv + 3 * n
    z = ca.MX.sym("z", n_z)
    par = ca.MX.sym("p", 0)
    zx = ca.reshape(z[:nxv], N_X, n + 1)
    zu = ca.reshape(z[nxv:], 3, n)

    zt = ca.SX.sym("zt", N_X)
    lam_t = ca.SX.sym("lam_t", len(node_names))
    sig = ca.SX.sym("sig")
    rows_t = ca_rows(zt * ca.DM(m.x_scale), node_names, m)
    cost_t = _terminal_cost(zt, m, cones) if terminal else ca.SX(0.0)
    fn_rows_t = ca.Function("rows_t", [zt], [rows_t])
    fn_jac_t = ca.Function("jac_t", [zt], [ca.jacobian(rows_t, zt)])
    h_t, _ = ca.hessian(ca.dot(lam_t, rows_t) + sig * cost_t, zt)
    fn_hess_t = ca.Function("hess_t", [zt, lam_t, sig], [ca.triu(h_t)])
    fn_cost_t = ca.Function("cost_t", [zt], [cost_t])

    def constraints(g_fun: ca.Function) -> ca.MX:
        out = g_fun.map(n, "thread", THREADS)(zx[:, :n], zu)
        return ca.vertcat(ca.vec(ca.vertcat(out[0:N_X, :] - zx[:, 1:], out[N_X:, :])), fn_rows_t(zx[:, n]))

    # the problem's g uses the differentiable VM block (casadi's IPOPT interface wants one); IPOPT's
    # own calls go through jac_g / hess_lag below
    g = constraints(block_functions(m, cones)[0])
    obj = 1e-2 * ca.sumsqr(zu) / n + ca.sumsqr(zx[4:7, 1:]) / n + fn_cost_t(zx[:, n])

    def col_of(k: NDArray[np.int64], c: NDArray[np.int64]) -> NDArray[np.int64]:
        return np.where(c < N_X, N_X * k + c, nxv + 3 * k + (c - N_X))

    # constraint Jacobian: the blocks, the -I of the defects, the rows at node N
    rb, cb = (np.asarray(a, dtype=np.int64) for a in jg_f.sparsity_out(0).get_triplet())
    ks = np.repeat(np.arange(n), len(rb))
    kd = np.repeat(np.arange(n), N_X)
    rt, ct = (np.asarray(a, dtype=np.int64) for a in fn_jac_t.sparsity_out(0).get_triplet())
    rows = np.concatenate([n_out * ks + np.tile(rb, n), n_out * kd + np.tile(np.arange(N_X), n), n_out * n + rt])
    cols = np.concatenate([col_of(ks, np.tile(cb, n)), N_X * (kd + 1) + np.tile(np.arange(N_X), n), N_X * n + ct])
    order = np.lexsort((rows, cols))
    n_g = n_out * n + len(node_names)
    sp_j = ca.Sparsity.triplet(n_g, n_z, rows[order].tolist(), cols[order].tolist())
    jb = jg_f.map(n, "thread", THREADS)(zx[:, :n], zu)
    vals = ca.vertcat(jb.nz[:], ca.DM(-np.ones(N_X * n)), fn_jac_t(zx[:, n]).nz[:])
    jac = ca.MX(sp_j, vals[order.tolist()])
    fn_jac_g = ca.Function("jac_g", [z, par], [constraints(g_f), jac], ["x", "p"], ["g", "jac_g_x"])

    # Lagrangian Hessian (upper triangle): the blocks, the terminal node, the objective's diagonal
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", n_g)
    lam_b = ca.reshape(lam_g[:n_out * n], n_out, n)
    rh, chh = (np.asarray(a, dtype=np.int64) for a in hg_f.sparsity_out(0).get_triplet())
    ks = np.repeat(np.arange(n), len(rh))
    rht, cht = (np.asarray(a, dtype=np.int64) for a in fn_hess_t.sparsity_out(0).get_triplet())
    hrows = np.concatenate([col_of(ks, np.tile(rh, n)), N_X * n + rht])
    hcols = np.concatenate([col_of(ks, np.tile(chh, n)), N_X * n + cht])
    horder = np.lexsort((hrows, hcols))
    sp_hh = ca.Sparsity.triplet(n_z, n_z, hrows[horder].tolist(), hcols[horder].tolist())
    hb = hg_f.map(n, "thread", THREADS)(zx[:, :n], zu, lam_b)
    hvals = ca.vertcat(hb.nz[:], fn_hess_t(zx[:, n], lam_g[n_out * n:], lam_f).nz[:])
    diag = np.zeros(n_z)
    diag[nxv:] = 2e-2 / n
    diag[(N_X * np.arange(1, n + 1)[:, None] + np.arange(4, 7)[None, :]).ravel()] = 2.0 / n
    hess = ca.MX(sp_hh, hvals[horder.tolist()]) + lam_f * ca.DM(ca.Sparsity.diag(n_z), diag)
    fn_hess = ca.Function("hess_lag", [z, par, lam_f, lam_g], [ca.triu(hess)],
                          ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    opts = {"jac_g": fn_jac_g, "hess_lag": fn_hess, "calc_lam_x": False, "calc_lam_p": False}
    return Nlp({"x": z, "p": par, "f": obj, "g": g}, opts, n, n_z)


IPOPT_OPTIONS: dict[str, Any] = {
    "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
    "ipopt.tol": 1e-6, "ipopt.constr_viol_tol": 1e-8,
    "ipopt.acceptable_tol": 1e-4, "ipopt.acceptable_constr_viol_tol": 1e-8,
    "ipopt.bound_relax_factor": 0.0, "ipopt.mumps_pivtol": 1e-8, "ipopt.mu_strategy": "monotone",
}
"""IPOPT settings: monotone mu and a low MUMPS pivot tolerance (docs/viability.md: 184 s with adaptive mu,
40 s monotone, 25 s with the pivot tolerance, on one 300-step solve of the prototype)."""


def solve_window(x0: Array, n_steps: int, m: OracleModel, enforce: tuple[str, ...], margin: float,
                 u_guess: Array, x_guess: Array, max_iter: int, wall_s: float, terminal: bool,
                 compiled: bool = True, t0_s: float = 0.0) -> tuple[Array, str, int]:
    """One multiple-shooting solve from x0 at time t0_s (s; windowed cones apply by it); returns (u (N, 3)
    clipped to U, IPOPT status, iterations)."""
    cones = enforced_cones(m, enforce)
    nlp = build_nlp(n_steps, m, terminal, cones, compiled)
    opts = {**nlp.opts, **IPOPT_OPTIONS, "ipopt.max_iter": int(max_iter),
            "ipopt.max_wall_time": max(1.0, float(wall_s))}
    solver = ca.nlpsol("viability", "ipopt", nlp.problem, opts)
    n = n_steps
    nxv = N_X * (n + 1)
    xsc, umax = m.x_scale, m.u_max
    lbx = np.full(nlp.n_z, -np.inf)
    ubx = np.full(nlp.n_z, np.inf)
    lbx[:N_X] = ubx[:N_X] = x0 / xsc
    q_idx = (N_X * np.arange(1, n + 1)[:, None] + np.arange(4)[None, :]).ravel()
    lbx[q_idx], ubx[q_idx] = -1.0, 1.0
    lbx[nxv:], ubx[nxv:] = -1.0, 1.0
    lbg, ubg = g_bounds(n, m, cones, enforce, margin, t0_s)
    z_init = np.concatenate([(x_guess / xsc).ravel(), (np.clip(u_guess, -umax, umax) / umax).ravel()])
    sol = solver(x0=z_init, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=np.zeros(0))
    st = solver.stats()
    u = np.clip(np.asarray(sol["x"]).ravel()[nxv:].reshape(n, 3) * umax, -umax, umax)
    return u, str(st.get("return_status", "?")), int(st.get("iter_count", -1))


__all__ = ["CACHE_ENV", "COMPILE_FLAGS", "IPOPT_OPTIONS", "Nlp", "block_functions", "build_nlp", "ca_rows",
           "cache_dir", "compiled_blocks", "enforced_cones", "g_bounds", "g_layout", "n_block_out", "row_bounds",
           "row_names", "solve_window"]
