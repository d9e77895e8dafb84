"""The `prioritize` fallback (issue 14 item 3): when the filter's QP is infeasible, the levels of
`filter.priorities` give way least important first, each by as little as possible.

Checked against an independent lexicographic solve with Clarabel (an interior-point solver: nothing
shared with the filter's active-set QPs but the barrier table): level by level, the least sum of squared
violations of the level's rows -- each measured as a distance in u, violation / |dBC/du| (rows of very
different scales weigh alike) -- with every more important level held as relaxed so far, then the
least change of u_des with every row relaxed by that much."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from rta_attitude import config
from rta_attitude.constraints.registry import levels as constraint_levels
from rta_attitude.errors import ConfigError
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.topics import QP_KEYS

CFG = config.load().with_fallback("prioritize").with_backup("none")  # the ASIF's own answer
SPLIT = (("exclusion_zone",), ("omega",), ("psi",), ("temperature", "battery", "communication"))
"""Levels that separate the default top level's groups, so that one of them gives way and the others hold."""


def _solve(P, q, A, b):
    import clarabel

    A, b = np.array(A), np.array(b)
    norm = np.linalg.norm(A, axis=1)  # rows scaled to unit norm (same feasible set, better conditioned)
    A, b = A / norm[:, None], b / norm
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-9
    solver = clarabel.DefaultSolver(sp.csc_matrix(P), q, sp.csc_matrix(A), b,
                                    [clarabel.NonnegativeConeT(len(b))], settings)
    sol = solver.solve()
    assert str(sol.status) in ("Solved", "AlmostSolved"), sol.status
    return np.array(sol.x)


def _oracle(t, levels, slack_w, u_des):
    """The lexicographic answer from the table t of one state: (u, how far each row (M,) and each
    coupled rate row (k,) gives way, in its own units). Rows: the constraint rows drift + gain u >= 0
    (those that depend on u; rows with a configured slack weight only in the last QP, with their
    slack), the coupled rate rows lo <= g u <= hi (their axis's rate constraint's level), the box
    lo <= u <= hi always hard. Each level's QP minimises the sum of squared distances w (in u) by
    which its rows give way: drift + gain u + |gain| w >= 0."""
    m = len(CFG.constraint_names)
    on = [i for i in range(m) if np.linalg.norm(t.gain[i]) > 1e-12]
    hard = [i for i in on if slack_w[i] == 0]
    nz = int(t.zoh_rows)
    zlevel = [levels[CFG.constraint_names.index("omega_x") + int(t.zoh_axis[q])] for q in range(nz)]
    relax, zrelax = np.zeros(m), np.zeros(nz)

    def rows(n, level_of_var):
        """Constraint rows as A z <= b over z = [u, v...]; level_of_var maps rows to their v index."""
        A, b = [], []
        for i in hard:
            a = np.zeros(n)
            a[:3] = -t.gain[i]
            if ("c", i) in level_of_var:
                a[level_of_var[("c", i)]] = -np.linalg.norm(t.gain[i])  # w: a distance in u
                A.append(a)
                b.append(t.drift[i])
            elif levels[i] <= current[0]:
                A.append(a)
                b.append(t.drift[i] + relax[i])
        for q in range(nz):
            if ("z", q) in level_of_var or zlevel[q] <= current[0]:
                for sign, bound in ((1.0, t.zoh_hi[q]), (-1.0, -t.zoh_lo[q])):
                    a = np.zeros(n)
                    a[:3] = sign * t.zoh_gain[q]
                    extra = zrelax[q]
                    if ("z", q) in level_of_var:
                        a[level_of_var[("z", q)]] = -np.linalg.norm(t.zoh_gain[q])
                        extra = 0.0
                    A.append(a)
                    b.append(bound + extra)
        for j in range(3):
            a = np.zeros(n)
            a[j] = 1.0
            A.extend([a.copy(), -a])
            b.extend([t.hi[j], -t.lo[j]])
        return A, b

    current = [-1]
    for lev in range(max(levels) + 1):
        here = [("c", i) for i in hard if levels[i] == lev] + [("z", q) for q in range(nz) if zlevel[q] == lev]
        if not here:
            continue
        current[0] = lev - 1
        n = 3 + len(here)
        var = {key: 3 + k for k, key in enumerate(here)}
        P = np.zeros((n, n))
        P[3:, 3:] = 2 * np.eye(len(here))
        A, b = rows(n, var)
        for k in range(len(here)):  # v >= 0
            a = np.zeros(n)
            a[3 + k] = -1.0
            A.append(a)
            b.append(0.0)
        z = _solve(P, np.zeros(n), A, b)
        for (kind, i), k in var.items():  # relaxations in the rows' own units
            g = t.gain[i] if kind == "c" else t.zoh_gain[i]
            (relax if kind == "c" else zrelax)[i] = max(0.0, z[k]) * np.linalg.norm(g)
    current[0] = max(levels)
    soft = [i for i in on if slack_w[i] > 0]
    n = 3 + len(soft)
    P = np.zeros((n, n))
    P[:3, :3] = 2 * np.eye(3)
    q = np.zeros(n)
    q[:3] = -2 * u_des
    A, b = rows(n, {})
    for k, i in enumerate(soft):
        a = np.zeros(n)
        a[:3] = -t.gain[i]
        a[3 + k] = -1.0
        P[3 + k, 3 + k] = 2 * slack_w[i]
        A.append(a)
        b.append(t.drift[i])
    z = _solve(P, q, A, b)
    return z[:3], relax, zrelax


def _violations(t, u):
    """max(0, -BC_i) of each constraint row at u, and of each coupled rate row (either side)."""
    rows = np.maximum(0.0, -(t.drift + t.gain @ u))
    nz = int(t.zoh_rows)
    g = t.zoh_gain[:nz] @ u
    return rows, np.maximum(0.0, np.maximum(t.zoh_lo[:nz] - g, g - t.zoh_hi[:nz]))


def _level_cost(t, u, levels, slack_w, lev):
    """Sum of squared violations of one level's rows at u as distances in u (violation / |dBC/du|;
    configured slacked rows not counted)."""
    rows, zoh = _violations(t, u)
    gn = np.linalg.norm(t.gain, axis=1)
    on = gn > 1e-12
    rows = np.where(on, rows / np.where(on, gn, 1.0), 0.0)
    nz = int(t.zoh_rows)
    zoh = zoh / np.linalg.norm(t.zoh_gain[:nz], axis=1)
    mask = on & (levels == lev) & (slack_w == 0)
    ox = CFG.constraint_names.index("omega_x")
    zmask = np.array([levels[ox + int(t.zoh_axis[q])] == lev for q in range(int(t.zoh_rows))], dtype=bool)
    return float(np.sum(rows[mask] ** 2) + np.sum(zoh[zmask] ** 2))


def _infeasible_states(cfg, count, seed=5):
    """States (with u_des) at which the filter's own QP is infeasible: sampled initial states of the Monte
    Carlo with random commands inside U (seeded)."""
    X, _ = sample_initial_states(4000, seed, cfg)
    rng = np.random.default_rng(seed)
    f = AsifFilter(cfg)
    out = []
    for x in X:
        u_des = rng.uniform(-1, 1, 3) * cfg.limits.wheel_accel_max_rad_s2
        if bool(f.filter(x, u_des).qp_failed):
            out.append((x, u_des))
            if len(out) == count:
                break
    assert len(out) == count, f"only {len(out)} infeasible states"
    return out


def _slack_weights(cfg):
    return np.array([cfg.gains(n).slack_weight for n in cfg.constraint_names])


@pytest.mark.parametrize("priorities", [CFG.filter.priorities, SPLIT], ids=["default", "split"])
def test_prioritize_is_the_lexicographic_optimum_of_an_independent_solver(priorities):
    cfg = replace(CFG, filter=replace(CFG.filter, priorities=priorities))
    levels = constraint_levels(cfg)
    slack_w = _slack_weights(cfg)
    f = AsifFilter(cfg)
    soften = AsifFilter(cfg.with_fallback("soften"))
    gave = set()
    soften_worse = 0
    for x, u_des in _infeasible_states(cfg, 12):
        res = f.filter(x, u_des)
        assert bool(res.qp_failed) and str(res.status) == "fallback" and str(res.fallback) == "prioritize"
        assert "+prioritize:active_set:solved" in str(res.solver_status)
        t = f.constraints.evaluate(x)
        u_ref, relax, _ = _oracle(t, levels, slack_w, u_des)
        first, maybe = None, []
        for lev in range(len(priorities)):  # lexicographic: each level as little as the oracle allows
            ours, best = _level_cost(t, res.u, levels, slack_w, lev), _level_cost(t, u_ref, levels, slack_w, lev)
            assert ours <= best * (1 + 1e-4) + 1e-10, (lev, ours, best)
            if first is None and best > 1e-10:  # relaxed by more than 1e-5 (a distance in u): clearly gave way
                first = lev
            elif first is None and best > 1e-13:  # within ~10x of the solvers' tolerances: either way
                maybe.append(lev)
        # the level that gave way is the most important one the oracle had to relax
        named = {"+".join(priorities[lev]) for lev in maybe} | {"+".join(priorities[first]) if first is not None
                                                                else ""}
        assert str(res.gave_way) in named, (str(res.gave_way), named)
        gave.add(str(res.gave_way))
        assert np.all(res.u >= t.lo - 1e-9) and np.all(res.u <= t.hi + 1e-9)
        np.testing.assert_allclose(res.u, u_ref, atol=2e-4 * cfg.limits.wheel_accel_max_rad_s2)
        # the reported give-way (res.slack) covers what each hard row misses at u, and is the oracle's
        # where the oracle relaxed a row by more than the near-degenerate splits between nearly parallel
        # rows allow to differ (the level costs above agree to 1e-4)
        hard = (slack_w == 0) & (np.linalg.norm(t.gain, axis=1) > 1e-12)
        gn = np.linalg.norm(t.gain[hard], axis=1)  # as distances in u, rad/s^2
        missed = _violations(t, res.u)[0][hard]
        assert np.all(missed / gn <= res.slack[hard] / gn + 1e-9)
        big = relax[hard] / gn > 1e-2
        np.testing.assert_allclose(res.slack[hard][big] / gn[big], relax[hard][big] / gn[big], rtol=1e-3)
        # `soften` weighs every row alike: lexicographically it is never better, and at some states worse
        u_soft = soften.filter(x, u_des).u
        for lev in range(len(priorities)):
            a, b = _level_cost(t, res.u, levels, slack_w, lev), _level_cost(t, u_soft, levels, slack_w, lev)
            if abs(a - b) > 1e-3 * max(a, b) + 1e-10:
                assert b > a, f"soften lets level {lev} give way less than prioritize ({b:g} < {a:g})"
                soften_worse += 1
                break
    assert gave - {""}, "no level gave way at any of the states"
    assert soften_worse > 0, "soften and prioritize agree at every state: the check could not tell them apart"


def test_gave_way_is_reported_in_the_result_and_filter_status():
    (x, u_des), = _infeasible_states(CFG, 1)
    res = AsifFilter(CFG).filter(x, u_des)
    assert str(res.gave_way) in {"+".join(level) for level in CFG.filter.priorities}
    assert "gave_way" in QP_KEYS
    assert np.any(res.slack > 0)  # how far the relaxed rows gave way
    X, _ = sample_initial_states(50, 5, CFG)
    feasible = [r for r in (AsifFilter(CFG).filter(x, np.zeros(3)) for x in X) if not bool(r.qp_failed)]
    assert feasible and all(str(r.gave_way) == "" for r in feasible)


def test_other_policies_are_unchanged_by_the_priorities():
    """The soften filter gives the same answers whatever the priorities say."""
    base = config.load().with_fallback("soften").with_backup("none")
    other = replace(base, filter=replace(base.filter, priorities=SPLIT))
    for x, u_des in _infeasible_states(base, 4):
        a, b = AsifFilter(base).filter(x, u_des), AsifFilter(other).filter(x, u_des)
        assert np.array_equal(a.u, b.u) and str(a.gave_way) == str(b.gave_way) == ""


@pytest.mark.parametrize(("levels", "message"), [
    (["omega, psi, exclusion_zone", "temperature", "communication"], "missing battery"),
    (["omega psi exclusion_zone", "omega", "temperature", "battery", "communication"], "omega twice"),
    (["omega, psi, exclusion_zone, wheels", "temperature", "battery", "communication"], "must be one of"),
    ("omega", "must be a list of strings"),
])
def test_priorities_are_validated_in_the_config(levels, message):
    params, _ = config.read_parameters()
    params["filter"]["priorities"] = levels
    with pytest.raises(ConfigError, match=message) as err:
        config.from_parameters(params)
    assert "\n" not in str(err.value)


def test_priorities_parse_from_ros_style_strings():
    params, _ = config.read_parameters()
    params["filter"]["priorities"] = ["exclusion_zone", "omega,psi", "battery temperature", "communication"]
    cfg = config.from_parameters(params)
    assert cfg.filter.priorities == (("exclusion_zone",), ("omega", "psi"), ("battery", "temperature"),
                                     ("communication",))
    assert constraint_levels(cfg).tolist() == [0, 3, 2, 2, 1, 1, 1, 1, 1, 1]
    assert set(cfg.groups) == {g for level in cfg.filter.priorities for g in level}


def test_conflicting_constraints_scenario_shows_which_level_gives_way() -> None:
    """`battery_vs_temperature` (Monte Carlo seed 1, run 2094; gyrostat, no primary controller): battery and
    temperature cannot both keep their rows. With the default order (battery above temperature)
    temperature gives way for a few steps and nothing is violated: its augmented barrier keeps a reserve
    (delta0, delta1) that a short give-way spends without reaching T_max, and the node cools by radiation;
    with temperature above the battery, the battery gives way ~1,700 steps and is lost (the model does
    not cap E, so it drains at P_out). Which level gave way is read from the filter's own report
    (`gave_way`) at the trajectory's states. The priorities alone (`--backup-law none`): with the gatekeeper
    (the default) both orders keep every hard constraint."""
    from collections import Counter

    from rta_attitude.simulation.closed_loop import ClosedLoop

    gated = config.load()
    cfg = gated.with_backup("none")
    scenario = cfg.scenario("battery-vs-temperature")
    p = cfg.filter.priorities
    assert p[1] == ("battery",) and p[2] == ("temperature",)  # the default order this test describes
    seen = {}
    for label, order in (("default", p), ("temperature first", (p[0], p[2], p[1], p[3]))):
        c = replace(cfg, filter=replace(cfg.filter, priorities=order))
        traj = ClosedLoop(c, scenario, rta=True).run()
        f = AsifFilter(c)
        gave = Counter(str(f.filter(traj.x[k], np.zeros(3)).gave_way) for k in range(len(traj.x) - 1))
        h = dict(zip(traj.names, np.minimum(traj.h.min(axis=0), traj.h_substep_min.min(axis=0))))
        seen[label] = gave, h
    gave, h = seen["temperature first"]
    assert gave["battery"] > 1000 and gave["temperature"] == 0
    assert h["battery"] < 0 and h["temperature"] > 0 and h["exclusion_zone"] > 0
    gave, h = seen["default"]
    assert 0 < gave["temperature"] < 100 and gave["battery"] == 0
    hard = [n for n in traj.names if n != "communication"]
    assert all(h[n] >= 0 for n in hard), h
    assert gated.filter.backup_law == "sun_safe"
    c = replace(gated, filter=replace(gated.filter, priorities=(p[0], p[2], p[1], p[3])))
    traj = ClosedLoop(c, scenario, rta=True).run()
    h = dict(zip(traj.names, np.minimum(traj.h.min(axis=0), traj.h_substep_min.min(axis=0))))
    assert all(h[n] >= 0 for n in hard), h
