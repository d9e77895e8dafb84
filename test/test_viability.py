"""The viability oracle (rta_attitude.viability), checked against the project's own plant.

Every witness is re-simulated here by the project's plant (`dynamics.spacecraft.integrate`: the RK4
with zero-order hold the simulator runs) and checked at every substep with the project's safety
values (`constraints.ConstraintSet`), both independent of the oracle's casadi model. The search runs
in casadi's virtual machine (compile=False) on short horizons: no C compiler in CI.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import best_panel_cos, turned_vehicle

from rta_attitude import config
from rta_attitude.config.schema import BarrierGains, Config, PointingConstraint
from rta_attitude.constraints import ConstraintSet, registry
from rta_attitude.constraints.windows import window_phase
from rta_attitude.dynamics.quaternion import attitude_matrices
from rta_attitude.dynamics.spacecraft import integrate, plant_record
from rta_attitude.dynamics.state import STATE_NAMES, STATE_SIZE
from rta_attitude.viability import find_witness
from rta_attitude.viability.laws import LAWS, quat_from_matrix, simulate_law, sun_safe_matrix
from rta_attitude.viability.model import constraint_values
from rta_attitude.viability.params import check_enforce, default_enforce, from_config
from rta_attitude.viability.result import NO_WITNESS, RECOVERABLE, UNRECOVERABLE, Result
from rta_attitude.viability.rules import (
    _distance_to_bands,
    battery_rule,
    check_rules,
    momentum_band,
    momentum_bands,
    rules_apply,
)

MODELS = ("paper", "gyrostat")


def with_model(cfg: Config, model: str) -> Config:
    return replace(cfg, spacecraft=replace(cfg.spacecraft, model=model))


@pytest.fixture(scope="module")
def cfg() -> Config:
    return config.load()


# ----------------------------------------------------------------------------- the project's plant
def project_run(cfg: Config, x0: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples (N + 1, 19) and every substep state (N * substeps, 19) of the project's plant."""
    p = plant_record(cfg)
    x = np.zeros(STATE_SIZE)
    x[:13] = x0[:13]
    samples, subs = [x.copy()], []
    for uk in u:
        x, s = integrate(x, uk, cfg.filter.sample_time_s, p, cfg.substeps)
        samples.append(x)
        subs.append(s)
    return np.array(samples), np.concatenate(subs) if subs else np.zeros((0, STATE_SIZE))


def project_h(cfg: Config, x0: np.ndarray, subs: np.ndarray, start_s: float = 0.0) -> np.ndarray:
    """The project's safety values (n, rows) at x0 (time start_s) and every substep after it."""
    x = np.zeros(STATE_SIZE)
    x[:13] = x0[:13]
    t = start_s + cfg.filter.sample_time_s * np.arange(len(subs) + 1) / cfg.substeps
    return ConstraintSet(cfg).safety_values(np.vstack([x[None, :], subs]), t)


def enforced_rows(cfg: Config, enforce: tuple[str, ...]) -> list[int]:
    """The project's rows of the constraints in the groups `enforce`."""
    return [c.row for c in registry(cfg) if c.group in enforce]


def row(cfg: Config, name: str) -> int:
    return registry(cfg).index(name)


def check_witness(cfg: Config, x0: np.ndarray, res: Result, steps: int, start_s: float = 0.0) -> dict[str, float]:
    """The box, the oracle's x against the project's plant, every enforced constraint at every substep."""
    assert res.verdict == RECOVERABLE and res.rule is None
    assert res.u is not None and res.x is not None
    assert res.u.shape == (steps, 3) and res.x.shape == (steps + 1, 13)
    assert np.all(np.abs(res.u) <= cfg.u_max_rad_s2), "a command leaves the box U"
    samples, subs = project_run(cfg, x0, res.u)
    np.testing.assert_allclose(res.x, samples[:, :13], rtol=0, atol=1e-7)
    h = project_h(cfg, x0, subs, start_s)
    worst: dict[str, float] = {}
    for c in registry(cfg):
        if c.group in res.enforce:
            worst[c.name] = float(h[:, c.row].min())
            assert worst[c.name] >= 0.0, f"{c.name} violated by the witness on the project's plant: {worst[c.name]}"
    return worst


# ----------------------------------------------------------------------------- states
def sun_safe_state(cfg: Config, tilt_deg: float, omega_y_deg_s: float, psi: tuple[float, float, float],
                   T_K: float, E_J: float, theta: float = 1.0) -> np.ndarray:
    """The sun-safe attitude with the sensor (+i_B) tilted tilt_deg towards the sun about j_B."""
    i, j, k = sun_safe_matrix(theta, from_config(cfg))
    b = math.radians(tilt_deg)
    rows = np.vstack([math.cos(b) * i + math.sin(b) * k, j, -math.sin(b) * i + math.cos(b) * k])
    return np.concatenate([quat_from_matrix(rows), [0.0, math.radians(omega_y_deg_s), 0.0], psi, [T_K, E_J, theta]])


def near_cone_state(cfg: Config) -> np.ndarray:
    """Sensor 40.3 deg from the sun (0.3 deg outside the keep-out cone), turning towards it at 0.9 deg/s:
    only braking at once, about as hard as U allows, keeps it out."""
    return sun_safe_state(cfg, 90.0 - 40.3, -0.9, (0.0, 0.0, 0.0), 280.0, 3000.0)


def dark_panel_state(cfg: Config, E_J: float, theta: float = 1.0) -> np.ndarray:
    """Panel (+k_B) pointing straight away from the sun, at rest."""
    i, j, k = sun_safe_matrix(theta, from_config(cfg))
    return np.concatenate([quat_from_matrix(np.vstack([-i, j, -k])), np.zeros(6), [270.0, E_J, theta]])


# ----------------------------------------------------------------------------- the model
@pytest.mark.parametrize("turn_deg", [0.0, 25.0], ids=["principal", "tensor"])
@pytest.mark.parametrize("model", MODELS)
def test_the_casadi_model_agrees_with_the_project_plant(cfg: Config, model: str, turn_deg: float) -> None:
    """The oracle's model against the compiled plant, on principal axes and with products of inertia (the 6U's
    principal axes turned 25 deg)."""
    from rta_attitude.viability.model import simulate

    c = turned_vehicle(with_model(cfg, model), turn_deg)[0] if turn_deg else with_model(cfg, model)
    rng = np.random.default_rng(14)
    x0 = sun_safe_state(c, 30.0, 0.5, (400.0, -300.0, 200.0), 280.0, 3000.0)
    x0[4:7] += rng.uniform(-0.5, 0.5, 3) * c.limits.omega_max_rad_s
    u = rng.uniform(-1.0, 1.0, (20, 3)) * c.u_max_rad_s2
    xs, subs = simulate(x0, u, from_config(c))
    ref_x, ref_subs = project_run(c, x0, u)
    np.testing.assert_allclose(xs, ref_x[:, :13], rtol=0, atol=1e-9)
    np.testing.assert_allclose(subs, ref_subs[:, :13], rtol=0, atol=1e-9)
    # the two models differ on this state (the wheels' gyroscopic term matters)
    other = from_config(with_model(c, MODELS[1 - MODELS.index(model)]))
    assert np.max(np.abs(simulate(x0, u, other)[0] - xs)) > 1e-6


def test_the_assembled_derivatives_equal_casadi_ad(cfg: Config) -> None:
    """jac_g and hess_lag assembled from the per-step blocks equal casadi's AD of the same NLP."""
    import casadi as ca

    from rta_attitude.viability.transcription import build_nlp

    m = from_config(with_model(cfg, "gyrostat"))
    nlp = build_nlp(2, m, True, (0, 1), compiled=False)  # both cones with rows
    z, g, f = nlp.problem["x"], nlp.problem["g"], nlp.problem["f"]
    lf, lg = ca.MX.sym("lf"), ca.MX.sym("lg", g.shape[0])
    jac_ref = ca.Function("J", [z], [ca.jacobian(g, z)])
    hess_ref = ca.Function("H", [z, lf, lg], [ca.triu(ca.hessian(lf * f + ca.dot(lg, g), z)[0])])
    rng = np.random.default_rng(1)
    zz = rng.normal(size=nlp.n_z) * 0.3
    for k in range(3):
        zz[13 * k:13 * k + 4] /= np.linalg.norm(zz[13 * k:13 * k + 4])
        zz[13 * k + 10], zz[13 * k + 11] = 2.8, 3.0
    lam = rng.normal(size=g.shape[0])
    _, jac = nlp.opts["jac_g"](zz, np.zeros(0))
    np.testing.assert_allclose(np.array(jac), np.array(jac_ref(zz)), rtol=0, atol=1e-12)
    hess = nlp.opts["hess_lag"](zz, np.zeros(0), 0.7, lam)
    np.testing.assert_allclose(np.array(hess), np.array(hess_ref(zz, 0.7, lam)), rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- rules
def test_a_state_violated_at_x0_is_unrecoverable(cfg: Config) -> None:
    x0 = near_cone_state(cfg)
    x0[10] = cfg.limits.temperature_max_K + 0.5
    res = find_witness(x0, 100.0, cfg, compile=False)
    assert (res.verdict, res.rule, res.u, res.x) == (UNRECOVERABLE, "violated_at_x0", None, None)
    assert res.min_margins["temperature"] == pytest.approx(-0.5)


@pytest.mark.parametrize("model", MODELS)
def test_the_battery_rule_proves_a_dark_panel_unrecoverable(cfg: Config, model: str) -> None:
    c = with_model(cfg, model)
    x0 = dark_panel_state(c, 1200.0)
    res = find_witness(x0, 300.0, c, compile=False)
    assert (res.verdict, res.rule, res.u) == (UNRECOVERABLE, "battery_drain", None)
    assert "E_min" in res.detail and res.iterations == 0
    # not contradicted: every warm-start law, on the project's plant, drains the battery below E_min
    battery = row(c, "battery")
    for law in LAWS:
        u, _, _ = simulate_law(x0, 300, from_config(c), law)
        _, subs = project_run(c, x0, u)
        assert project_h(c, x0, subs)[:, battery].min() < 0.0, law


def test_the_temperature_rule_proves_a_hot_face_unrecoverable(cfg: Config) -> None:
    theta = 1.0
    s = np.array([math.cos(theta), math.sin(theta), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    rows = np.vstack([np.cross(-s, z), -s, z])  # -j_B on the sun; sensor and panel perpendicular to it
    x0 = np.concatenate([quat_from_matrix(rows), np.zeros(6), [cfg.limits.temperature_max_K - 0.02, 9000.0, theta]])
    h0 = project_h(cfg, x0, np.zeros((0, STATE_SIZE)))[0]
    assert all(h0[i] >= 0 for i in enforced_rows(cfg, default_enforce(cfg)))
    res = find_witness(x0, 300.0, cfg, compile=False)
    assert (res.verdict, res.rule, res.u) == (UNRECOVERABLE, "temperature_heating", None)


def momentum_state(cfg: Config, psi: float, E_J: float, theta: float = 1.0) -> np.ndarray:
    """At rest, wheels at -psi each (H = -D psi along the body diagonal d), H pointed at the sun:
    the panel is 54.7 deg from the sun, the sensor 54.7 deg, the hot face 125 deg."""
    s, z = np.array([math.cos(theta), math.sin(theta), 0.0]), np.array([0.0, 0.0, 1.0])
    d, d2 = np.ones(3) / math.sqrt(3.0), np.array([1.0, -1.0, 0.0]) / math.sqrt(2.0)
    a = np.outer(d, s) + np.outer(d2, z) + np.outer(np.cross(d, d2), np.cross(s, z))  # Hill -> body: s -> d
    return np.concatenate([quat_from_matrix(a), np.zeros(3), [-psi] * 3, [270.0, E_J, theta]])


def test_the_momentum_bands_are_the_optimisers_best_panel_attitude(cfg: Config) -> None:
    """`momentum_bands` against an optimiser (SLSQP from many starts over rotations): the largest
    k_B . r_S over attitudes whose body momentum fits the wheels' box |H_i| <= c_i is cos(dist(alpha, F))
    (sound: never above; tight: reached), alpha the angle between H and r_S."""
    m = from_config(cfg)
    c = m.J * m.omega_max_rad_s + m.wheel_inertia_kgm2 * m.psi_max_rad_s
    rng = np.random.default_rng(3)
    binding = 0
    for case in range(8):  # even cases: large momentum, the sun near it (the band binds); odd: anything
        big = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.8, 1.0, 3)
        psi = (big if case % 2 == 0 else rng.uniform(-1.0, 1.0, 3)) * 576.0
        x0 = np.concatenate([[0.0, 0.0, 0.0, 1.0], np.zeros(3), psi, [270.0, 5000.0, 0.0]])
        hb = -m.wheel_inertia_kgm2 * x0[7:10]
        s = rng.normal(size=3) + (3.0 * hb / np.linalg.norm(hb) if case % 2 == 0 else 0.0)
        s /= np.linalg.norm(s)
        alpha = math.acos(float(np.clip(hb @ s / np.linalg.norm(hb), -1.0, 1.0)))
        bound = math.cos(float(_distance_to_bands(np.array([alpha]), momentum_bands(hb, m))[0]))
        best = best_panel_cos(hb, s, c, rng, starts=20)
        assert best <= bound + 1e-9
        assert best == pytest.approx(bound, abs=1e-7)
        binding += bound < 1.0 - 1e-9
    assert binding >= 3  # the band did bind


def test_the_momentum_rule_proves_a_panel_the_wheels_cannot_turn_unrecoverable(cfg: Config) -> None:
    """The wheels hold |H| = 970 D only with the panel >= 51.6 deg from H; H points at the sun and E is
    just above E_min: the battery drains though the panel could turn to the sun at the rate bound."""
    m = from_config(cfg)
    x0 = momentum_state(cfg, 560.0, 1020.0)
    h0 = project_h(cfg, x0, np.zeros((0, STATE_SIZE)))[0]
    assert all(h0[i] >= 0 for i in enforced_rows(cfg, default_enforce(cfg)))
    assert battery_rule(x0, 300.0, m) == ""  # turning alone would save it
    res = find_witness(x0, 300.0, cfg, compile=False)
    assert (res.verdict, res.rule, res.u) == (UNRECOVERABLE, "momentum_battery", None)
    # not contradicted: every warm-start law, on the project's plant, drains the battery below E_min
    battery = row(cfg, "battery")
    for law in LAWS:
        u, _, _ = simulate_law(x0, 100, m, law)
        _, subs = project_run(cfg, x0, u)
        assert project_h(cfg, x0, subs)[:, battery].min() < 0.0, law
    # silent where the wheels can hold the momentum with the panel on the sun, or with more energy
    assert check_rules(momentum_state(cfg, 300.0, 1020.0), 300.0, m, default_enforce(cfg)) is None
    assert check_rules(momentum_state(cfg, 560.0, 1100.0), 300.0, m, default_enforce(cfg)) is None
    assert battery_rule(x0, 300.0, replace(m, gyrostat=False), momentum=True) == ""  # the paper model: no band
    # |H| past sqrt(c_1^2 + c_2^2): two disjoint bands, and the panel keeps to the one it starts in
    hb = m.J * x0[4:7] - m.wheel_inertia_kgm2 * x0[7:10]
    both, (_, kept) = momentum_bands(hb, m), momentum_band(x0, m, 0.0)
    assert len(both) == 2 and kept == [both[0]] and both[0][0] < math.acos(1 / math.sqrt(3.0)) < both[0][1]


def test_the_battery_rule_is_silent_with_reserve_and_then_a_witness_exists(cfg: Config) -> None:
    x0 = dark_panel_state(cfg, 3000.0)
    m = from_config(cfg)
    assert check_rules(x0, 2000.0, m, default_enforce(cfg)) is None
    res = find_witness(x0, 60.0, cfg, compile=False)
    check_witness(cfg, x0, res, 60)


def test_just_above_the_rules_threshold_the_answer_is_never_unrecoverable(cfg: Config) -> None:
    """Where no rule fires, a failed search says "no witness found", never "unrecoverable"."""
    m = from_config(cfg)
    x0 = dark_panel_state(cfg, 1000.0)
    lo, hi = 1000.0, 5000.0
    for _ in range(40):
        x0[11] = 0.5 * (lo + hi)
        lo, hi = (x0[11], hi) if battery_rule(x0, 30.0, m) else (lo, x0[11])
    x0[11] = hi + 1e-3
    res = find_witness(x0, 30.0, cfg, compile=False, use_warm_start=False, max_iter=25, time_limit_s=10.0)
    assert res.rule is None and res.verdict in (NO_WITNESS, RECOVERABLE)
    if res.verdict == RECOVERABLE:
        check_witness(cfg, x0, res, 30)


# ----------------------------------------------------------------------------- the cone table
NADIR_HILL = np.array([-1.0, 0.0, 0.0])
"""The Earth from the spacecraft in Hill (+x radial out, +y along-track, +z orbit normal)."""


def star_tracker(windows_s: tuple[tuple[float, float], ...] = ()) -> PointingConstraint:
    """A keep-out cone of 30 deg about the Earth for a star tracker on -k_B."""
    return PointingConstraint(name="star_tracker", kind="keep_out", boresight_body=(0.0, 0.0, -1.0), target="earth",
                              half_angle_rad=math.radians(30.0), gains=BarrierGains(k1=0.1, k2=0.3),
                              windows_s=windows_s)


def with_cones(cfg: Config, *cones: PointingConstraint) -> Config:
    """cfg with more pointing constraints (after the configured ones), each a priority level of its own."""
    levels = (*cfg.filter.priorities, *((c.name,) for c in cones))
    return replace(cfg, pointing=(*cfg.pointing, *cones), filter=replace(cfg.filter, priorities=levels))


def random_states(rng: np.random.Generator, n: int) -> np.ndarray:
    """n oracle states (13,): random attitudes and theta_S, rates, wheels, T and E inside their limits."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.column_stack([q, rng.uniform(-0.01, 0.01, (n, 3)), rng.uniform(-400, 400, (n, 3)),
                            rng.uniform(260, 280, n), rng.uniform(2000, 8000, n), rng.uniform(0, 2 * np.pi, n)])


def row_values(m: object, names: tuple[str, ...], xs: np.ndarray) -> np.ndarray:
    """The transcription's rows `names` (scaled) at states xs (n, 13)."""
    import casadi as ca

    from rta_attitude.viability.transcription import ca_rows

    x = ca.SX.sym("x", 13)
    f = ca.Function("rows", [x], [ca_rows(x, names, m)])  # type: ignore[arg-type]
    return np.array([np.array(f(xk)).ravel() for xk in xs])


def full_states(xs: np.ndarray) -> np.ndarray:
    out = np.zeros((len(xs), STATE_SIZE))
    out[:, :13] = xs
    return out


def test_an_extra_cone_gets_a_row_of_its_boresights_cosine_to_its_target(cfg: Config) -> None:
    """A configured keep-out cone of a star tracker on -k_B about the Earth: a row at every node and substep whose
    value is cos(angle(boresight, Earth)) with the Earth in body axes A(q) r_E, bounded by cos(30 deg) - margin."""
    from rta_attitude.viability.transcription import enforced_cones, row_bounds, row_names

    c = with_cones(cfg, star_tracker())
    m = from_config(c)
    enforce = default_enforce(c)
    assert "star_tracker" in enforce and "star_tracker" in c.groups
    cones = enforced_cones(m, enforce)
    node, inner = row_names(m, cones, True), row_names(m, cones, False)
    assert node[:2] == ("exclusion_zone", "star_tracker") and "star_tracker" in inner  # communication: slacked
    xs = random_states(np.random.default_rng(5), 8)
    cos_row = row_values(m, node, xs)[:, node.index("star_tracker")]
    earth_body = np.einsum("nij,j->ni", attitude_matrices(xs[:, :4]), NADIR_HILL)
    expect = earth_body @ np.array([0.0, 0.0, -1.0])
    assert np.ptp(expect) > 0.5  # the states differ
    np.testing.assert_allclose(cos_row, expect, rtol=0, atol=1e-14)
    lo, hi = row_bounds(node, enforce, 1e-4, m)
    j = node.index("star_tracker")
    assert lo[j] == -np.inf and hi[j] == pytest.approx(math.cos(math.radians(30.0)) - 1e-4, abs=1e-15)
    # the oracle's h and the project's safety value: the angle's margin outside the cone
    h = constraint_values(xs, m)["star_tracker"]
    np.testing.assert_allclose(h, np.arccos(np.clip(expect, -1, 1)) - math.radians(30.0), rtol=0, atol=1e-9)
    np.testing.assert_allclose(h, ConstraintSet(c).safety_values(full_states(xs))[:, row(c, "star_tracker")],
                               rtol=0, atol=1e-8)
    # the same numbers for the paper's two cones as with the default configuration
    base = from_config(cfg)
    both = row_values(base, row_names(base, (0,), True), xs)
    np.testing.assert_array_equal(row_values(m, node, xs)[:, [i for i, n in enumerate(node) if n != "star_tracker"]],
                                  both)


@pytest.mark.parametrize(("target", "vector"), [("sun", None), ("orbit_normal", None), ("velocity", None),
                                                ("hill", (0.6, 0.0, 0.8)), ("inertial", (0.0, 0.6, -0.8))])
def test_a_cone_row_is_its_cosine_for_any_target(cfg: Config, target: str, vector: tuple | None) -> None:
    """A keep-in cone of an oblique boresight about every kind of target, the sun 20 deg out of the orbit
    plane: the row is e . A(q) r (r in Hill: the sun [cos b cos th, cos b sin th, sin b], the orbit normal
    +z, the velocity +y, a Hill vector, an inertial vector turned by R_z(theta_S))."""
    from rta_attitude.viability.transcription import enforced_cones, row_bounds, row_names

    beta = math.radians(20.0)
    e = np.array([0.6, 0.8, 0.0])
    cone = PointingConstraint(name="probe", kind="keep_in", boresight_body=tuple(e), target=target,  # type: ignore
                              half_angle_rad=math.radians(70.0), gains=BarrierGains(k1=0.1, k2=0.3),
                              target_vector=vector)
    c = with_cones(replace(cfg, environment=replace(cfg.environment, sun_beta_rad=beta)), cone)
    m = from_config(c)
    xs = random_states(np.random.default_rng(6), 8)
    th = xs[:, 12]
    one = np.ones_like(th)
    if target == "sun":
        r = np.column_stack([math.cos(beta) * np.cos(th), math.cos(beta) * np.sin(th), math.sin(beta) * one])
    elif target == "inertial":
        v = np.array(vector)
        r = np.column_stack([np.cos(th) * v[0] - np.sin(th) * v[1], np.sin(th) * v[0] + np.cos(th) * v[1], v[2] * one])
    else:
        r = np.tile({"orbit_normal": [0.0, 0.0, 1.0], "velocity": [0.0, 1.0, 0.0], "hill": vector}[target], (8, 1))
    expect = np.einsum("nij,nj->ni", attitude_matrices(xs[:, :4]), r) @ e
    enforce = check_enforce(("probe", "omega"), c)
    names = row_names(m, enforced_cones(m, enforce), True)
    assert names[0] == "probe"
    np.testing.assert_allclose(row_values(m, names, xs)[:, 0], expect, rtol=0, atol=1e-14)
    lo, hi = row_bounds(names, enforce, 1e-4, m)
    assert lo[0] == pytest.approx(math.cos(math.radians(70.0)) + 1e-4, abs=1e-15) and hi[0] == np.inf
    h = constraint_values(xs, m)["probe"]
    np.testing.assert_allclose(h, math.radians(70.0) - np.arccos(expect), rtol=0, atol=1e-9)
    np.testing.assert_allclose(h, ConstraintSet(c).safety_values(full_states(xs))[:, row(c, "probe")], rtol=0,
                               atol=1e-8)


def layout(cfg: Config) -> Config:
    """The face's normal on +i_B, the panel's on (0, -0.6, 0.8), the sun 25 deg out of the orbit plane."""
    return replace(cfg, thermal=replace(cfg.thermal, face_normal_body=(1.0, 0.0, 0.0)),
                   power=replace(cfg.power, panel_normal_body=(0.0, -0.6, 0.8)),
                   environment=replace(cfg.environment, sun_beta_rad=math.radians(25.0)))


def test_the_model_puts_the_face_the_panel_and_the_sun_where_the_config_does(cfg: Config) -> None:
    """With another face, panel and beta angle the oracle's model follows the project's plant (which reads them
    from the same keys), and differs from the paper's layout."""
    from rta_attitude.viability.model import simulate

    c = layout(cfg)
    rng = np.random.default_rng(9)
    x0 = random_states(rng, 1)[0]
    u = rng.uniform(-1.0, 1.0, (20, 3)) * c.u_max_rad_s2
    xs, subs = simulate(x0, u, from_config(c))
    ref_x, ref_subs = project_run(c, x0, u)
    np.testing.assert_allclose(xs, ref_x[:, :13], rtol=0, atol=1e-9)
    np.testing.assert_allclose(subs, ref_subs[:, :13], rtol=0, atol=1e-9)
    paper = simulate(x0, u, from_config(cfg))[0]
    assert abs(paper[-1, 10] - xs[-1, 10]) > 1e-4 and abs(paper[-1, 11] - xs[-1, 11]) > 1e-2


def test_the_sun_safe_attitude_and_the_battery_rule_use_the_configured_panel(cfg: Config) -> None:
    """The sun-safe attitude puts the configured panel on the sun and the face's inward normal on the Earth's
    side; with that panel turned away from the sun the battery rule proves the state unrecoverable, and no
    warm-start law, on the project's plant, keeps the battery."""
    c = layout(cfg)
    m = from_config(c)
    theta, beta = 1.0, math.radians(25.0)
    sun = np.array([math.cos(beta) * math.cos(theta), math.cos(beta) * math.sin(theta), math.sin(beta)])
    a = sun_safe_matrix(theta, m)
    np.testing.assert_allclose(a @ a.T, np.eye(3), rtol=0, atol=1e-14)
    assert np.linalg.det(a) == pytest.approx(1.0)
    panel, face = np.array([0.0, -0.6, 0.8]), np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(a @ sun, panel, rtol=0, atol=1e-14)
    earth_side = NADIR_HILL - (NADIR_HILL @ sun) * sun
    assert (a @ earth_side) @ face < -0.5 * np.linalg.norm(earth_side)  # the face looks away from the Earth
    axis = np.cross(panel, [1.0, 0.0, 0.0])
    axis /= np.linalg.norm(axis)
    dark = (2.0 * np.outer(axis, axis) - np.eye(3)) @ a  # turned half a turn about an axis across the panel
    np.testing.assert_allclose(dark @ sun, -panel, rtol=0, atol=1e-14)
    x0 = np.concatenate([quat_from_matrix(dark), np.zeros(6), [270.0, 1200.0, theta]])
    res = find_witness(x0, 300.0, c, compile=False)
    assert (res.verdict, res.rule) == (UNRECOVERABLE, "battery_drain")
    for law in LAWS:
        u, _, _ = simulate_law(x0, 300, m, law)
        _, subs = project_run(c, x0, u)
        assert project_h(c, x0, subs)[:, row(c, "battery")].min() < 0.0, law


def test_a_windowed_cone_has_rows_only_inside_its_windows(cfg: Config) -> None:
    """A cone with windows [3, 5.5] and [7.2, 9] s, a problem from t0 = 1 s over 10 holds: the cone's rows are
    bounded exactly at the substeps and nodes whose time is inside a window (the project's `window_phase`),
    node 0 aside (its state is fixed); each row is evaluated at the state of its time."""
    from rta_attitude.viability.transcription import build_nlp, enforced_cones, g_bounds, g_layout

    cone = star_tracker(((3.0, 5.5), (7.2, 9.0)))
    c = with_cones(cfg, cone)
    m = from_config(c)
    enforce = default_enforce(c)
    cones = enforced_cones(m, enforce)
    n, t0 = 10, 1.0
    names, index = g_layout(n, m, cones)
    lbg, ubg = g_bounds(n, m, cones, enforce, 1e-4, t0)
    nlp = build_nlp(n, m, False, cones, compiled=False)
    assert len(names) == len(lbg) == nlp.problem["g"].shape[0]
    times = t0 + c.filter.sample_time_s * index / c.substeps
    tracker = np.flatnonzero(names == "star_tracker")
    inside = np.array([window_phase(cone, c, t) == "inside" for t in times[tracker]])
    assert 0 < inside.sum() < len(tracker)
    np.testing.assert_array_equal(np.isfinite(ubg[tracker]), inside & (index[tracker] > 0))
    assert np.all(lbg[tracker] == -np.inf)
    sensor = np.flatnonzero(names == "exclusion_zone")  # the windowless cone: everywhere but node 0
    np.testing.assert_array_equal(np.isfinite(ubg[sensor]), index[sensor] > 0)
    # every row at the state of its time: g at a consistent point against the project's plant
    rng = np.random.default_rng(2)
    x0 = random_states(rng, 1)[0]
    u = rng.uniform(-1.0, 1.0, (n, 3)) * c.u_max_rad_s2
    samples, subs = project_run(c, x0, u)
    z = np.concatenate([(samples[:, :13] / m.x_scale).ravel(), (u / m.u_max).ravel()])
    import casadi as ca

    g = np.array(ca.Function("g", [nlp.problem["x"]], [nlp.problem["g"]])(z)).ravel()
    states = np.vstack([samples[:1], subs])  # the state at index i
    expect = np.einsum("nij,j->ni", attitude_matrices(states[index[tracker], :4]), NADIR_HILL)[:, 2] * -1.0
    np.testing.assert_allclose(g[tracker], expect, rtol=0, atol=1e-9)
    # the exact check and the rules read the windows too: violated at t0 = 40 s (inside), not at 0
    wide = star_tracker(((30.0, 60.0),))
    cw = with_cones(cfg, wide)
    mw = from_config(cw)
    turned = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # -k_B on the Earth, +i_B along-track
    x1 = np.concatenate([quat_from_matrix(turned), np.zeros(6), [275.0, 6000.0, 0.0]])
    assert constraint_values(x1, mw, 0.0)["star_tracker"][0] == np.inf
    assert constraint_values(x1, mw, 40.0)["star_tracker"][0] == pytest.approx(-math.radians(30.0))
    assert check_rules(x1, 20.0, mw, default_enforce(cw)) is None
    rule = check_rules(x1, 20.0, mw, default_enforce(cw), 40.0)
    assert rule is not None and rule[0] == "violated_at_x0" and "star_tracker" in rule[1]
    res = find_witness(x1, 10.0, cw, compile=False)
    assert res.min_margins["star_tracker"] == np.inf and res.start_s == 0.0
    check_witness(cw, x1, res, 10)


def test_a_windowed_cone_is_kept_from_its_windows_start(cfg: Config) -> None:
    """The star tracker starts on the Earth, its window opens at 50 s: a witness over 60 s turns it out of the
    cone in time, checked on the project's plant with the project's windowed safety values."""
    c = with_cones(cfg, star_tracker(((50.0, 100.0),)))
    turned = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # -k_B on the Earth, +i_B across the sun
    x0 = np.concatenate([quat_from_matrix(turned), np.zeros(6), [275.0, 6000.0, math.pi / 2]])
    assert project_h(c, x0, np.zeros((0, STATE_SIZE)), 50.0)[0, row(c, "star_tracker")] == pytest.approx(
        -math.radians(30.0))
    res = find_witness(x0, 60.0, c, compile=False)
    worst = check_witness(c, x0, res, 60)
    assert res.min_margins["star_tracker"] == pytest.approx(worst["star_tracker"], abs=1e-7)
    assert 0.0 <= worst["star_tracker"] < np.inf


# ----------------------------------------------------------------------------- witnesses
@pytest.mark.parametrize("model", MODELS)
def test_a_state_only_a_fast_manoeuvre_saves_gets_a_witness(cfg: Config, model: str) -> None:
    c = with_model(cfg, model)
    m = from_config(c)
    x0 = near_cone_state(c)
    for law in LAWS:  # the warm-start laws do not brake hard enough (checked on the project's plant)
        u, _, _ = simulate_law(x0, 20, m, law)
        _, subs = project_run(c, x0, u)
        h = project_h(c, x0, subs)
        enforced = enforced_rows(c, default_enforce(c))
        assert h[:, enforced].min() < 0.0, law
    res = find_witness(x0, 20.0, c, compile=False)
    assert res.method == "direct" and res.iterations > 0
    worst = check_witness(c, x0, res, 20)
    assert 0.0 <= worst["exclusion_zone"] < math.radians(0.1)  # it did approach the cone
    for g in ("exclusion_zone", "temperature", "battery"):  # the oracle's margins are the plant's
        assert res.min_margins[g] == pytest.approx(worst[g], abs=1e-7)


SEED7_RUN326 = np.array([0.4560378281631259, -0.8426256868543505, 0.0703053119312119, 0.2776123452797958,
                         -0.012262079182708533, 0.0075059478726229355, -0.006944702000167159, -11.167478896036187,
                         -258.6820548230665, 85.44390777244692, 276.3274950684983, 5390.6525382266,
                         0.13167024647449801])
"""Initial state of run 326 of `rta-attitude montecarlo --runs 5000 --duration 2000 --seed 7` (robust
preset, paper model): the filter enters the exclusion zone at 129.8 s (h = -7.1e-3 rad) after 13
infeasible QPs (measured on this branch; docs/viability.md)."""


def test_a_failed_monte_carlo_run_gets_a_witness_over_its_whole_run(cfg: Config) -> None:
    c = with_model(cfg, "paper")
    res = find_witness(SEED7_RUN326, 2000.0, c, compile=False)
    worst = check_witness(c, SEED7_RUN326, res, 2000)
    assert worst["exclusion_zone"] > 0.1  # the witness keeps the sensor well out of the cone


@pytest.mark.parametrize("turn_deg", [0.0, 25.0], ids=["principal", "tensor"])
def test_a_law_witness_is_checked_on_the_project_plant(cfg: Config, turn_deg: float) -> None:
    """A warm-start law's witness, re-run on the compiled plant; with products of inertia too (the oracle's rules
    do not apply there: `rules_apply` is False, so only the search answers)."""
    c = with_model(cfg, "gyrostat")
    c = turned_vehicle(c, turn_deg)[0] if turn_deg else c
    if turn_deg:
        assert not rules_apply(from_config(c))
    x0 = sun_safe_state(c, 45.0, -0.9, (500.0, -500.0, 500.0), 280.0, 3000.0)
    res = find_witness(x0, 100.0, c, compile=False)
    assert res.method == "warm_start" and res.ipopt_status == "not needed"
    check_witness(c, x0, res, 100)


def test_segments_give_one_witness_over_the_whole_horizon(cfg: Config) -> None:
    x0 = near_cone_state(cfg)
    res = find_witness(x0, 40.0, cfg, compile=False, direct_max_s=10.0, window_s=20.0, commit_s=10.0)
    assert res.method == "segmented" and res.segments
    check_witness(cfg, x0, res, 40)


def test_the_slacked_constraint_is_not_enforced_by_default_but_can_be(cfg: Config) -> None:
    assert "communication" in cfg.slacked_constraints and "communication" not in default_enforce(cfg)
    x0 = dark_panel_state(cfg, 8000.0)
    x0[:4] = quat_from_matrix(sun_safe_matrix(1.0, from_config(cfg)))  # antenna on the Earth side
    res = find_witness(x0, 50.0, cfg, compile=False, enforce=(*default_enforce(cfg), "communication"))
    assert "communication" in res.enforce
    check_witness(cfg, x0, res, 50)


def test_bad_inputs_raise(cfg: Config) -> None:
    from rta_attitude.errors import ConfigError

    with pytest.raises(ValueError, match="13 or 19"):
        find_witness(np.zeros(7), 10.0, cfg)
    with pytest.raises(ValueError, match="horizon"):
        find_witness(near_cone_state(cfg), 0.2, cfg)
    with pytest.raises(ConfigError, match="unknown constraint"):
        find_witness(near_cone_state(cfg), 10.0, cfg, enforce=("exclusion",))


def test_the_cache_lives_in_the_user_cache_dir(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from rta_attitude.viability.transcription import CACHE_ENV, cache_dir

    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache_dir() == tmp_path / "rta_attitude" / "viability"
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "x"))
    assert cache_dir() == tmp_path / "x"


def test_importing_the_package_does_not_load_casadi() -> None:
    code = ("import sys, rta_attitude.cli.main, rta_attitude.montecarlo.campaign; "
            "print('casadi' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ----------------------------------------------------------------------------- CLI
def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rta_attitude.cli", "viability", *args], capture_output=True,
                          text=True, timeout=300)


@pytest.mark.parametrize(("args", "message"), [
    (["--state", "1,2,3"], "--state must be 13"),
    (["--state", "a,b"], "--state must be comma-separated numbers"),
    (["--runs", "/nonexistent/runs.csv"], "no such file"),
    (["--state", ",".join(["0"] * 13)], "zero quaternion"),
    (["--state", ",".join(["0.5"] * 13), "--limit", "0"], "--limit must be >= 1"),
    (["--state", ",".join(["0.5"] * 13), "--enforce", "omega,sensor"], "unknown constraint group 'sensor'"),
    (["--runs", "/nonexistent/runs.csv", "--start-time", "5"], "--start-time applies to --state only"),
])  # fmt: skip
def test_cli_errors_are_one_line_and_exit_1(args: list[str], message: str) -> None:
    out = run_cli(*args, "--no-progress")
    assert out.returncode == 1
    assert out.stderr.count("\n") == 1 and out.stderr.startswith("ERROR: ") and message in out.stderr


def test_cli_checks_the_failed_runs_of_a_runs_csv(cfg: Config, tmp_path: Path) -> None:
    hot = near_cone_state(cfg)
    hot[10] = cfg.limits.temperature_max_K + 1.0
    dark = dark_panel_state(cfg, 1200.0)
    runs = tmp_path / "runs.csv"
    with runs.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", *STATE_NAMES[:13], "failed"])
        for k, (x, failed) in enumerate([(hot, 1), (near_cone_state(cfg), 0), (dark, 1)]):
            w.writerow([k, *[repr(float(v)) for v in x], failed])
    (tmp_path / "summary.json").write_text(json.dumps({"setup": {"duration_s": 300.0}}))
    out = run_cli("--runs", str(runs), "--out", str(tmp_path / "v"), "--no-progress", "--no-compile")
    assert out.returncode == 0, out.stderr
    doc = json.loads((tmp_path / "v" / "viability.json").read_text())
    assert [r["state"] for r in doc["results"]] == ["run 0", "run 2"]
    assert [r["rule"] for r in doc["results"]] == ["violated_at_x0", "battery_drain"]
    assert doc["setup"]["horizon_s"] == 300.0 and doc["counts"]["unrecoverable"] == 2
    assert "2 unrecoverable" in out.stdout


def test_montecarlo_reports_its_failures_with_and_without_a_witness(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from rta_attitude.cli.main import main as cli_main

    out = tmp_path / "mc"
    status = cli_main(["montecarlo", "--runs", "6", "--duration", "20", "--seed", "2", "--workers", "1", "--out",
                       str(out), "--no-progress", "--no-plot", "--viability", "--viability-no-compile",
                       "--viability-time-limit", "30"])
    assert status == 0
    failed = json.loads((out / "summary.json").read_text())["at_samples"]["failed"]
    doc = json.loads((out / "viability.json").read_text())
    assert doc["counts"]["states"] == failed and doc["setup"]["horizon_s"] == 20.0
    assert sum(doc["counts"][v] for v in (RECOVERABLE, NO_WITNESS, UNRECOVERABLE)) == failed
    assert f"viability of the {failed} failed runs" in capsys.readouterr().out
