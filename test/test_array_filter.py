"""The filter over an array of N wheels (rta_attitude.filter.wheel_array), checked against independent computations:
the three-wheel filter where the array is the paper's three wheels, finite differences of the true N-wheel dynamics
for every row, Clarabel for the QP, and closed loops of the 12U pyramid example."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from rta_attitude.config.loader import load
from rta_attitude.dynamics.spacecraft import plant_record, state_derivative
from rta_attitude.dynamics.state import wheel_columns
from rta_attitude.errors import ConfigError
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.wheel_array import ArrayFilter, ArraySafety, null_basis
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.array_loop import array_state
from rta_attitude.simulation.closed_loop import simulate

ROOT = Path(__file__).resolve().parents[1]
PYRAMID = ROOT / "config" / "examples" / "pyramid_12u.yaml"


def _no_gate(cfg):
    return replace(cfg, filter=replace(cfg.filter, backup_law="none"))


@pytest.fixture(scope="module")
def paper():
    return _no_gate(load())


@pytest.fixture(scope="module")
def pyramid():
    return load(PYRAMID)


def _array_states(cfg, runs: int, seed: int) -> np.ndarray:
    """States of cfg's array: the default's sampled states (the momentum held by the minimum-norm split) with
    random wheel speeds added along the null space, each wheel within the speed its rows keep."""
    rng = np.random.default_rng(seed)
    X3, _ = sample_initial_states(runs, seed, _no_gate(load()))
    basis = null_basis(cfg.spacecraft.wheel_axes, cfg.spacecraft.wheel_failed)
    cols = list(wheel_columns(cfg.spacecraft.n_wheels))
    out = []
    for x3 in X3:
        x = array_state(cfg, x3)
        x[cols] = np.clip(x[cols] + basis @ rng.uniform(-150.0, 150.0, basis.shape[1]), -0.9 * cfg.psi_keep_rad_s,
                          0.9 * cfg.psi_keep_rad_s)
        out.append(x)
    return np.array(out)


def test_the_paper_s_three_wheels_through_the_array_filter_answer_as_the_three_wheel_filter(paper) -> None:
    # the same vehicle, two assemblies of its QP: the array's lifts the virtual rows by A = I and keeps each wheel's
    # rows and box as rows of its own (the null-space law has nothing to do: three wheels have no null space)
    array, three = ArrayFilter(paper), AsifFilter(paper)
    X, _ = sample_initial_states(300, 3, paper)
    rng = np.random.default_rng(3)
    statuses = set()
    for k, x in enumerate(X):
        u_des = rng.uniform(-1.5, 1.5, 3) * paper.u_max_rad_s2
        ra, r3 = array.filter(x, u_des, 7.0 * k), three.filter(x, u_des, 7.0 * k)
        assert ra.status == r3.status and ra.gave_way == r3.gave_way, k
        np.testing.assert_allclose(ra.u, r3.u, rtol=0, atol=1e-9 * np.max(paper.u_max_rad_s2), err_msg=str(k))
        np.testing.assert_allclose(ra.h, r3.h, rtol=1e-12, atol=0, err_msg=str(k))
        np.testing.assert_allclose(ra.bc, r3.bc, rtol=1e-9, atol=1e-12, err_msg=str(k))
        statuses.add(str(r3.status))
    assert statuses == {"pass", "solved", "fallback"}  # every branch was compared


@pytest.mark.parametrize("failed", [(), ("rw2",)])
def test_every_row_of_the_pyramid_is_the_derivative_of_the_true_dynamics(pyramid, failed) -> None:
    # the paper preset's rows are the exact conditions: BC = d/dt psi1 + k2 psi1 + bias (HOCBF), or d/dt h + k1 h +
    # bias; the derivative by central differences along the N-wheel plant's own derivative at the filter's answer
    cfg = replace(pyramid.with_preset("paper"),
                  spacecraft=replace(pyramid.spacecraft, failed_wheels=failed))
    filt = ArrayFilter(cfg)
    p = plant_record(cfg, cfg.filter.model)
    X = _array_states(cfg, 40, 11)
    rng = np.random.default_rng(11)
    gains = [cfg.gains(n) for n in filt.names]
    eps = 1e-3
    checked = 0
    for k, x in enumerate(X):
        t = 50.0 * k
        r = filt.filter(x, rng.uniform(-1, 1, cfg.spacecraft.n_wheels) * 30.0, t)
        if r.status == "fallback":
            continue
        f = state_derivative(x, r.u, p)
        rp, rm = filt.filter(x + eps * f, r.u, t + eps), filt.filter(x - eps * f, r.u, t - eps)
        for i, name in enumerate(filt.names):
            g = gains[i]
            if not g.enabled:
                continue
            second = name not in filt.names[-cfg.spacecraft.n_wheels - 3:]  # cones, temperature, battery
            level = (rp.psi1[i] - rm.psi1[i]) / (2 * eps) if second else (rp.psi0[i] - rm.psi0[i]) / (2 * eps)
            expect = level + (g.k2 * r.psi1[i] if second else g.k1 * r.psi0[i]) + g.bias
            scale = max(1.0, abs(expect), abs(level))
            assert abs(r.bc[i] - expect) <= 2e-5 * scale, (k, name, r.bc[i], expect)
            if second:  # and the first level: psi1 = d/dt psi0 + k1 psi0
                d0 = (rp.psi0[i] - rm.psi0[i]) / (2 * eps)
                assert abs(r.psi1[i] - (d0 + g.k1 * r.psi0[i])) <= 2e-5 * max(1.0, abs(r.psi1[i])), (k, name)
            checked += 1
    assert checked > 30 * len(filt.names) // 2


def _clarabel(prob: dict[str, np.ndarray], weights: np.ndarray) -> np.ndarray | None:
    """min |u - u_target|^2 + sum p_k d_k^2 s.t. lo_k <= G_k u + d_k <= hi_k (d_k only where its constraint has a
    slack weight p > 0), box_lo <= u <= box_hi; None if Clarabel finds it infeasible."""
    import clarabel

    G, lo, hi, con = prob["G"], prob["lo"], prob["hi"], prob["con"]
    n = G.shape[1]
    soft = [k for k in range(len(con)) if con[k] >= 0 and weights[con[k]] > 0]
    nz = n + len(soft)
    P = np.zeros((nz, nz))
    P[:n, :n] = 2 * np.eye(n)
    q = np.zeros(nz)
    q[:n] = -2 * prob["u_target"]
    A, b = [], []

    def side(row: np.ndarray, bound: float) -> None:
        if abs(bound) < 1e19:
            A.append(row)
            b.append(bound)

    for k in range(len(con)):
        row = np.zeros(nz)
        row[:n] = G[k]
        if k in soft:
            row[n + soft.index(k)] = 1.0
            P[n + soft.index(k), n + soft.index(k)] = 2 * weights[con[k]]
        side(row.copy(), hi[k])
        side(-row, -lo[k])
    for j in range(n):
        e = np.zeros(nz)
        e[j] = 1.0
        side(e.copy(), prob["box_hi"][j])
        side(-e, -prob["box_lo"][j])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-11
    sol = clarabel.DefaultSolver(sp.csc_matrix(P), q, sp.csc_matrix(np.array(A)), np.array(b),
                                 [clarabel.NonnegativeConeT(len(b))], settings).solve()
    if str(sol.status) not in ("Solved", "AlmostSolved"):
        return None
    return np.array(sol.x)[:n]


def test_the_pyramid_s_qp_answer_is_clarabel_s(pyramid) -> None:
    filt = ArrayFilter(pyramid)
    weights = np.array([pyramid.gains(n).slack_weight if pyramid.gains(n).enabled else 0.0
                        for n in filt.names])
    X = _array_states(pyramid, 150, 5)
    rng = np.random.default_rng(5)
    solved = 0
    for k, x in enumerate(X):
        u_des = rng.uniform(-1.2, 1.2, 4) * pyramid.limits.wheel_accel_max_rad_s2
        r = filt.filter(x, u_des, 13.0 * k)
        if r.status != "solved":
            continue
        u = _clarabel(filt.problem(x, u_des, 13.0 * k), weights)
        assert u is not None, k
        np.testing.assert_allclose(r.u, u, rtol=0, atol=2e-4 * pyramid.limits.wheel_accel_max_rad_s2, err_msg=str(k))
        solved += 1
    assert solved >= 50


def test_the_pyramid_keeps_every_hard_constraint_through_the_paper_example_also_with_a_failed_wheel(pyramid) -> None:
    for failed in ((), ("rw3",)):
        cfg = replace(pyramid, spacecraft=replace(pyramid.spacecraft, failed_wheels=failed))
        run = simulate(cfg, "paper-example")
        hard = [i for i, n in enumerate(run.names) if n not in cfg.slacked_constraints]
        assert run.h_substep_min[:, hard].min() >= 0.0, (failed, run.names)
        assert set(run.status) <= {"pass", "solved"}, failed
        if failed:  # the failed wheel never moves: it coasts at its speed
            col = list(wheel_columns(4))[2]
            assert np.all(run.x[:, col] == run.x[0, col]) and np.all(run.u[:, 2] == 0.0)
        # the momentum the wheels hold is the body's A psi: the safety values agree with a second evaluation
        np.testing.assert_array_equal(ArraySafety(cfg).values(run.x, run.t_s), run.h)


def test_the_null_space_target_is_the_best_by_a_search_along_the_null_space(pyramid) -> None:
    # the law's target against a fine search of the null-space coordinate: within the cap, the slowest wheel as
    # fast as it can be; where the cap cannot hold (a large momentum), the fastest as slow as it can be
    from rta_attitude.filter.wheel_array import null_target

    rec = ArrayFilter(pyramid).array[0]
    cap = float(rec["null_bias"])
    basis = rec["null_basis"][:4, 0]
    rng = np.random.default_rng(2)
    grid = np.linspace(-3000.0, 3000.0, 600_001)
    for k in range(60):
        x = array_state(pyramid, sample_initial_states(1, k, _no_gate(load()))[0][0])
        cols = list(wheel_columns(4))
        x[cols] = rng.uniform(-1, 1, 4) * (cap if k % 2 else 4 * cap)
        s0 = float(basis @ x[cols])
        speeds = np.abs(x[cols][:, None] + basis[:, None] * (grid - s0))
        slow, fast = speeds.min(axis=0), speeds.max(axis=0)
        s = null_target(x, rec, 0, s0)
        got = np.abs(x[cols] + basis * (s - s0))
        if np.any(fast <= cap):
            assert got.max() <= cap * (1 + 1e-9) and got.min() >= slow[fast <= cap].max() - 1e-6, k
        else:
            assert got.max() <= fast.min() + 1e-6, k


def test_from_rest_the_null_space_law_keeps_the_wheels_off_zero_speed(pyramid) -> None:
    # the wheels start at rest; without the law (bias 0) the minimum-norm split of the body's small momentum keeps
    # them near zero speed; with it they spread to the cap along the null space
    scen = pyramid.scenario("paper-example")
    x0 = scen.x0.copy()
    x0[7:10] = 0.0
    scen = replace(scen, x0=x0, duration_s=600.0)
    slowest = {}
    for bias in (0.0, pyramid.filter.null_space_bias):
        cfg = replace(pyramid, filter=replace(pyramid.filter, null_space_bias=bias))
        run = simulate(cfg, scen)
        assert run.h_substep_min.min() >= 0.0
        slowest[bias] = float(np.abs(run.x[300:, list(wheel_columns(4))]).min())
    cap = pyramid.filter.null_space_bias * pyramid.psi_keep_rad_s
    law = slowest[pyramid.filter.null_space_bias]
    assert law > 0.4 * cap and law > 5 * slowest[0.0], slowest  # measured: 28.6 rad/s (cap 57.6) against 3.1


@pytest.mark.parametrize("change,what", [
    ({"filter": {"backup_law": "sun_safe"}}, "the gatekeeper"),
    ({"sensors": {"enabled": True}}, "sensor errors"),
])
def test_what_the_array_filter_does_not_take_is_one_line(pyramid, change, what) -> None:
    section, values = next(iter(change.items()))
    cfg = replace(pyramid, **{section: replace(getattr(pyramid, section), **values)})
    with pytest.raises(ConfigError) as info:
        ArrayFilter(cfg)
    assert what in str(info.value) and "\n" not in str(info.value)
