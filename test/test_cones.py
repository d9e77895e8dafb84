"""Pointing constraints as data: random cones (body axes, targets, half-angles, keep-in and keep-out, inside and
outside time windows, a sun out of the orbit plane) against independent computations.

- every row's HOCBF levels and Lie derivatives against central finite differences along x_dot = f + g u and
  time (the windows' barriers move with t);
- h against the angle computed here from the definitions of the targets (numpy), not from the package;
- the compiled rows against the numpy oracle (test/oracles/constraints/cone.py);
- the filter's answer against Clarabel (an interior-point solver) on the QP built from the rows;
- a window's barrier against a hand calculation of when it must start tightening;
- any number of cones (here 12) runs the same compiled kernels: no new compilation.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import random_states
from oracles.constraints import ConstraintSet as OracleSet

from rta_attitude import config
from rta_attitude.config.schema import MAX_POINTING, Config, PointingConstraint
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.windows import window_phase
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.errors import ConfigError

BASE = config.load().with_backup("none")
TARGETS = ("sun", "earth", "orbit_normal", "velocity", "hill", "inertial")
EPS = 1e-5


def _unit(rng: np.random.Generator) -> tuple[float, float, float]:
    v = rng.normal(size=3)
    v /= np.linalg.norm(v)
    return float(v[0]), float(v[1]), float(v[2])


def random_cones(rng: np.random.Generator, n: int, windows: bool = True) -> tuple[PointingConstraint, ...]:
    """n cones: every target in turn, random boresights and half-angles, keep-in and keep-out, some with two
    windows (in [200, 1800] s)."""
    gains = BASE.pointing[0].gains
    out = []
    for k in range(n):
        target = TARGETS[k % len(TARGETS)]
        win: tuple[tuple[float, float], ...] = ()
        if windows and k % 3 == 1:
            a = float(rng.uniform(200.0, 700.0))
            win = ((a, a + 200.0), (a + 600.0, a + 900.0))
        out.append(PointingConstraint(
            name=f"cone_{k}", kind="keep_in" if k % 2 else "keep_out", boresight_body=_unit(rng), target=target,
            half_angle_rad=math.radians(float(rng.uniform(15.0, 165.0))),
            gains=dataclasses.replace(gains, k1=float(rng.uniform(0.05, 0.3)), k2=float(rng.uniform(0.1, 0.5)),
                                      slack_weight=0.0),
            target_vector=_unit(rng) if target in ("hill", "inertial") else None, windows_s=win))
    return tuple(out)


def with_cones(cfg: Config, cones: tuple[PointingConstraint, ...], beta_deg: float = 0.0) -> Config:
    """cfg with these pointing constraints (every one in the first priority level) and a sun beta angle."""
    levels = (("omega", "psi", *(c.name for c in cones)), ("battery",), ("temperature",))
    scenarios = {k: v for k, v in cfg.scenarios.items() if v.slack_weights is None}  # (they name the paper's cones)
    return dataclasses.replace(cfg, pointing=cones, filter=dataclasses.replace(cfg.filter, priorities=levels),
                               scenarios=scenarios,
                               environment=dataclasses.replace(cfg.environment, sun_beta_rad=math.radians(beta_deg)))


CONES = random_cones(np.random.default_rng(41), 9)
CFG = with_cones(BASE, CONES, beta_deg=23.0)


def target_hill(c: PointingConstraint, theta_S: np.ndarray, beta_rad: float) -> np.ndarray:
    """The target's unit vector in Hill (n, 3), from its definition (docs/constraints.md)."""
    n = len(theta_S)
    if c.target == "sun":
        return np.stack([np.cos(beta_rad) * np.cos(theta_S), np.cos(beta_rad) * np.sin(theta_S),
                         np.full(n, np.sin(beta_rad))], axis=1)
    if c.target == "inertial":  # fixed in the frame whose x is the sun's direction in the orbit plane at theta_S = 0
        v = np.array(c.target_vector)
        rot = np.array([[[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0], [0.0, 0.0, 1.0]] for t in theta_S])
        return rot @ v
    fixed = {"earth": (-1.0, 0.0, 0.0), "orbit_normal": (0.0, 0.0, 1.0), "velocity": (0.0, 1.0, 0.0)}
    return np.tile(np.array(fixed.get(c.target, c.target_vector)), (n, 1))


def _times(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(0.0, 2000.0, n)


def _smooth(cs: ConstraintSet, cfg: Config, x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """States away from every kink: the angles' poles and clamps, the windows' switches (2 s either side)."""
    ok = np.ones(len(x), dtype=bool)
    for th in cs.angles(x).values():
        ok &= np.minimum.reduce([th, np.pi - th, np.abs(th - np.pi / 2)]) > 0.02
    for c in cfg.pointing:
        for start, end in c.windows_s:
            for edge in (start, end, *_ramp_starts(cfg, c)):
                ok &= np.abs(t - edge) > 2.0
    return ok


def _ramp_starts(cfg: Config, c: PointingConstraint) -> list[float]:
    from rta_attitude.constraints.windows import ramp_start

    return [ramp_start(cfg, c, s) for s, _ in c.windows_s]


@pytest.fixture(scope="module")
def sample() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    cs = ConstraintSet(CFG)
    x = random_states(rng, 2500, CFG)
    t = _times(rng, len(x))
    keep = _smooth(cs, CFG, x, t)
    x, t = x[keep][:1200], t[keep][:1200]
    u = rng.uniform(-1, 1, (len(x), 3)) * CFG.u_max_rad_s2
    return x, t, u


def test_the_sample_reaches_every_window_phase(sample) -> None:
    x, t, _ = sample
    assert len(x) >= 1000
    phases = {window_phase(c, CFG, float(tk)) for c in CFG.pointing if c.windows_s for tk in t}
    assert phases == {"off", "ramp", "inside"}


def _fd(fun, x, t, xdot, eps=EPS):
    with np.errstate(invalid="ignore"):  # rows outside their windows: inf - inf
        return (fun(x + eps * xdot, t + eps) - fun(x - eps * xdot, t - eps)) / (2 * eps)


def test_levels_and_barrier_conditions_are_derivatives_along_the_motion_and_time(sample) -> None:
    """Psi_1 = d/dt Psi_0 + k1 Psi_0 and BC(u) = d/dt Psi_1 + k2 Psi_1 + bias, with d/dt along f + g u and t."""
    x, t, u = sample
    cs = ConstraintSet(CFG)
    p = spacecraft.plant_record(CFG)
    tab = cs.evaluate(x, t)
    xdot = spacecraft.state_derivative(x, u, p)
    level0 = _fd(lambda z, s: cs.evaluate(z, s).psi0, x, t, xdot)
    level1 = _fd(lambda z, s: cs.evaluate(z, s).psi1, x, t, xdot)
    bc = tab.drift + np.einsum("nmk,nk->nm", tab.gain, u)
    checked = 0
    for i, c in enumerate(CFG.pointing):
        on = np.isfinite(tab.psi0[:, i])
        g = c.gains
        want1 = level0[on, i] + g.k1 * tab.psi0[on, i]
        err1 = np.abs(tab.psi1[on, i] - want1) / (np.abs(want1) + 1e-6)
        want2 = level1[on, i] + g.k2 * tab.psi1[on, i] + g.bias
        err2 = np.abs(bc[on, i] - want2) / (np.abs(want2) + np.abs(tab.drift[on, i]) + 1e-9)
        assert np.quantile(err1, 0.99) < 1e-5 and np.quantile(err2, 0.99) < 1e-5, c.name
        assert np.max(err2) < 1e-3, c.name
        checked += int(on.sum())
        if c.windows_s:
            assert 0 < on.sum() < len(on)  # rows both on and off in the sample
            np.testing.assert_array_equal(tab.gain[~on, i], 0.0)  # off: no condition on u
            assert np.all(tab.drift[~on, i] == 0.0)
    assert checked > 5000


def test_gains_are_the_derivative_of_the_condition_in_u(sample) -> None:
    x, t, _ = sample
    cs = ConstraintSet(CFG)
    p = spacecraft.plant_record(CFG)
    tab = cs.evaluate(x, t)
    base = _fd(lambda z, s: cs.evaluate(z, s).psi1, x, t, spacecraft.state_derivative(x, np.zeros((len(x), 3)), p))
    k = len(CFG.pointing)
    on = np.isfinite(tab.psi1[:, :k])
    for j in range(3):
        du = np.zeros((len(x), 3))
        du[:, j] = 1.0
        diff = _fd(lambda z, s: cs.evaluate(z, s).psi1, x, t, spacecraft.state_derivative(x, du, p)) - base
        g = tab.gain[:, :k, j]
        err = np.abs(diff[:, :k] - g)[on] / (np.abs(g[on]) + 1e-7 * np.abs(tab.drift[:, :k][on]) + 1e-12)
        assert np.quantile(err, 0.99) < 1e-4


def test_h_is_the_angle_to_the_target_by_definition(sample) -> None:
    x, t, _ = sample
    h = ConstraintSet(CFG).safety_values(x, t)
    A = quat.attitude_matrices(x[:, 0:4])
    beta = CFG.environment.sun_beta_rad
    for i, c in enumerate(CFG.pointing):
        b_hill = np.einsum("nij,i->nj", A, np.array(c.boresight_body))  # A^T b: the boresight in Hill
        theta = np.arccos(np.clip(np.sum(b_hill * target_hill(c, x[:, 12], beta), axis=1), -1.0, 1.0))
        want = (c.half_angle_rad - theta) if c.kind == "keep_in" else (theta - c.half_angle_rad)
        inside = np.array([window_phase(c, CFG, float(tk)) == "inside" for tk in t])
        np.testing.assert_allclose(h[inside, i], want[inside], atol=1e-9, err_msg=c.name)
        assert np.all(np.isinf(h[~inside, i]) & (h[~inside, i] > 0))


def test_rollouts_keep_the_ramped_barrier_ahead_of_a_window(sample) -> None:
    """What the gatekeeper's rollouts keep: inside a window (or without windows) the physical h; on the ramp
    ahead of a window h + rho with rho = r (t0 - t) by hand (r = f ((1 - m) w_max - (n + |n_f|)), t0 the
    window's start), so a plan that leaves the ramp fails its rollout as the filter's barrier would stop it;
    +inf before the ramp and after the window; +inf for a slacked cone whatever the time."""
    x, t, _ = sample
    cs = ConstraintSet(CFG)
    h, kept = cs.safety_values(x, t), cs.rollout_values(x, t)
    A = quat.attitude_matrices(x[:, 0:4])
    n = CFG.environment.mean_motion_rad_s
    r = CFG.filter.window_slew_fraction * ((1.0 - CFG.filter.zoh_margin) * CFG.limits.omega_max_rad_s
                                           - (n + (n if CFG.environment.rotating_hill else 0.0)))
    seen = set()
    for i, c in enumerate(CFG.pointing):
        b_hill = np.einsum("nij,i->nj", A, np.array(c.boresight_body))
        theta = np.arccos(np.clip(np.sum(b_hill * target_hill(c, x[:, 12], CFG.environment.sun_beta_rad), axis=1),
                                  -1.0, 1.0))
        physical = (c.half_angle_rad - theta) if c.kind == "keep_in" else (theta - c.half_angle_rad)
        for k, tk in enumerate(t):
            phase = window_phase(c, CFG, float(tk))
            seen.add(phase)
            if phase == "inside":
                assert kept[k, i] == h[k, i]
            elif phase == "ramp":
                t0 = min(s for s, _ in c.windows_s if s > tk)
                assert kept[k, i] == pytest.approx(physical[k] + r * (t0 - tk), abs=1e-9), c.name
            else:
                assert np.isposinf(kept[k, i])
    assert seen == {"off", "ramp", "inside"}
    np.testing.assert_array_equal(kept[:, len(CFG.pointing):], h[:, len(CFG.pointing):])  # the other rows as they are
    slacked = dataclasses.replace(CFG, pointing=(dataclasses.replace(
        CFG.pointing[0], gains=dataclasses.replace(CFG.pointing[0].gains, slack_weight=1.0)), *CFG.pointing[1:]))
    assert np.all(np.isposinf(ConstraintSet(slacked).rollout_values(x[:50], t[:50])[:, 0]))


def test_compiled_rows_equal_the_numpy_oracle(sample) -> None:
    x, t, _ = sample
    for preset in ("robust", "paper"):
        cfg = dataclasses.replace(CFG, environment=dataclasses.replace(CFG.environment, sun_beta_rad=0.3)) \
            .with_preset(preset).with_models("paper", "paper")
        got, want = ConstraintSet(cfg).evaluate(x, t), OracleSet.from_config(cfg).evaluate(x, t_s=t)
        k = len(cfg.pointing) + 2  # the cones, the temperature and the battery (their sun has beta too)
        for f in ("h", "psi0", "psi1", "drift", "gain"):
            np.testing.assert_allclose(getattr(got, f)[:, :k], getattr(want, f)[:, :k], rtol=1e-10, atol=1e-13,
                                       err_msg=f"{preset} {f}")


def _clarabel(A: np.ndarray, b: np.ndarray, z0: np.ndarray) -> np.ndarray | None:
    """min 1/2 |z - z0|^2 s.t. A z <= b by Clarabel; None if it does not solve."""
    import clarabel

    s = clarabel.DefaultSettings()
    s.verbose = False
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-12
    sol = clarabel.DefaultSolver(sp.csc_matrix(np.eye(len(z0))), -z0, sp.csc_matrix(A), b,
                                 [clarabel.NonnegativeConeT(len(b))], s).solve()
    return np.array(sol.x) if str(sol.status) == "Solved" else None


def test_the_filters_answer_is_the_qp_optimum_by_clarabel() -> None:
    """At random states (and times) inside the safe set, where the filter answered without a fallback (its fast
    path or its QP), u = argmin |u - u_des|^2 s.t. every hard row drift + gain . u >= 0 and the box, as an
    independent solver finds it (on the fast path, each row to the filter's check_tolerance in its units)."""
    from rta_attitude.filter.asif import AsifFilter

    cfg = with_cones(BASE, CONES[:4], beta_deg=23.0).with_preset("paper").with_models("paper", "paper")
    cfg = cfg.with_fallback("hold")
    f = AsifFilter(cfg)
    cs = ConstraintSet(cfg)
    rng = np.random.default_rng(3)
    x = random_states(rng, 20000, cfg)
    x[:, 4:7] *= 0.5
    x[:, 7:10] *= 0.8
    x[:, 10] = rng.uniform(255.0, 278.0, len(x))  # below T_max
    x[:, 11] = rng.uniform(5000.0, 10000.0, len(x))  # above E_min with the panel anywhere
    t = _times(rng, len(x))
    tab = cs.evaluate(x, t)
    inside = np.all(np.nan_to_num(tab.psi1, posinf=1.0) > 0, axis=1) & np.all(tab.h[:, :4] > 0, axis=1)
    x, t = x[inside][:300], t[inside][:300]
    compared = solved = 0
    for k in range(len(x)):
        u_des = rng.uniform(-1, 1, 3) * cfg.u_max_rad_s2
        r = f.filter(x[k], u_des, float(t[k]))
        if str(r.status) == "fallback":
            continue
        solved += str(r.status) == "solved"
        tab = cs.evaluate(x[k], t[k])
        rows = [i for i in range(len(cs.names)) if cs.enabled[i] and np.linalg.norm(tab.gain[i]) > 1e-12
                and not cs.slack_weights[i] > 0]
        # the rows as the filter holds them: its QP exactly; its fast path (u_des inside the box meets every row)
        # to check_tolerance in the row's own units (a rate row's gain is ~1e-5: 0.04 rad/s^2 in u)
        tol = cfg.filter.check_tolerance * np.maximum(1.0, np.linalg.norm(tab.gain[rows], axis=1))
        tol = tol if str(r.status) == "pass" else 0.0 * tol
        A = np.vstack([-tab.gain[rows], np.eye(3), -np.eye(3)])
        b = np.concatenate([tab.drift[rows] + tol, tab.hi, -tab.lo])
        scale = np.linalg.norm(A, axis=1)
        u = _clarabel(A / scale[:, None], b / scale, u_des)
        if u is None:
            continue
        np.testing.assert_allclose(r.u, u, atol=1e-5 * (1 + np.abs(u).max()))
        compared += 1
    assert compared >= 60 and solved >= 20


def test_a_windows_barrier_starts_when_the_hand_calculation_says() -> None:
    """The antenna's pass at [500, 900] s (keep-in, 90 deg): the barrier tightens at r = f ((1 - m) w_max - n)
    (f = filter.window_slew_fraction, m = zoh_margin) from rho_on = pi + margin + (r + sqrt(3) w_max + n) / k1;
    it starts at t0 - rho_on / r, and there Psi_0 > 0 and Psi_1 >= 0 for every state (its own safe set)."""
    base = config.load()
    comm = dataclasses.replace(base.pointing[1], windows_s=((500.0, 900.0),))
    cfg = dataclasses.replace(base, pointing=(base.pointing[0], comm))
    w_max, n = math.radians(1.0), 0.001027
    r = 0.5 * ((1.0 - 0.02) * w_max - n)
    margin = 2e-3  # communication's, as configured
    rho_on = math.pi + margin + (r + math.sqrt(3.0) * w_max + n) / 0.10
    t_on = 500.0 - rho_on / r
    assert t_on == pytest.approx(500.0 - 439.95, abs=0.01)  # 440 s ahead of the pass, by hand
    c = ConstraintSet(cfg).record[0]["cones"][1]
    assert c["ramp_rad_s"] == pytest.approx(r, rel=1e-12)
    assert c["window_on_s"][0] == pytest.approx(t_on, rel=1e-12)
    assert [window_phase(comm, cfg, s) for s in (t_on - 0.01, t_on + 0.01, 499.99, 500.0, 900.0, 900.01)] == \
        ["off", "ramp", "ramp", "inside", "inside", "off"]
    x = random_states(np.random.default_rng(5), 2000, cfg)
    x[:, 4:7] = np.clip(x[:, 4:7], -w_max, w_max)  # any state with the rates inside their limits
    tab = ConstraintSet(cfg).evaluate(x, t_on + 1e-9)
    assert np.all(tab.psi0[:, 1] > 0) and np.all(tab.psi1[:, 1] >= 0)
    h_at_start = ConstraintSet(cfg).evaluate(x, 500.0)
    np.testing.assert_allclose(h_at_start.psi0[:, 1], h_at_start.h[:, 1] - margin, atol=1e-12)  # rho = 0 at t0


def test_twelve_cones_run_the_same_compiled_kernels() -> None:
    """Any number of cones (up to MAX_POINTING) is a configuration, not a new kernel: after a run with the
    paper's two cones, a run with twelve adds no compiled signature to the filter and the loop."""
    from rta_attitude.filter.pipeline import filter_many
    from rta_attitude.simulation.closed_loop import run_scenario, simulate

    simulate(BASE, "paper-example", duration_s=3.0)
    before = (len(filter_many.signatures), len(run_scenario.signatures))
    cfg = with_cones(BASE, random_cones(np.random.default_rng(12), 12, windows=False))
    scen = dataclasses.replace(cfg.scenario("paper-example"), model=None, backup_law=None)
    tr = simulate(cfg, scen, duration_s=3.0)
    assert tr.h.shape[1] == 12 + 8 and tr.names[:12] == tuple(f"cone_{k}" for k in range(12))
    assert (len(filter_many.signatures), len(run_scenario.signatures)) == before
    assert MAX_POINTING >= 12


@pytest.mark.parametrize(("change", "message"), [
    ({"boresight_body": [0.0, 0.0, 0.0]}, "boresight_body must be a unit vector"),
    ({"boresight_body": [1.0, 0.2, 0.0]}, "boresight_body must be a unit vector"),
    ({"target": "moon"}, "target must be one of"),
    ({"half_angle_deg": 180.0}, r"half_angle_deg must be in \(0, 180\)"),
    ({"half_angle_deg": 0.0}, r"half_angle_deg must be in \(0, 180\)"),
    ({"kind": "avoid"}, "kind must be one of"),
    ({"windows_s": [100.0, 300.0, 250.0, 400.0]}, "overlaps"),
    ({"windows_s": [-5.0, 300.0]}, "starts before t = 0"),
    ({"windows_s": [100.0, 300.0, 400.0]}, "pairs"),
    ({"target": "hill"}, "target_vector is missing"),
    ({"target_vector": [0.0, 0.0, 1.0]}, "target_vector is only for"),
])
def test_bad_cones_are_one_line_errors(change, message) -> None:
    params, _ = config.read_parameters()
    entry = params["constraints"]["pointing"]["exclusion_zone"]
    entry.update(change)
    with pytest.raises(ConfigError, match=message) as err:
        config.from_parameters(params)
    assert "\n" not in str(err.value) and "exclusion_zone" in str(err.value)
