"""A full inertia tensor (`spacecraft.products_of_inertia_kgm2`) against independent computations.

- the check at load (positive definite, the triangle inequalities);
- a vehicle whose principal axes are turned by R from its body axes moves as the principal vehicle turned by R
  (free motion with the gravity gradient in the rotating Hill frame): the general kernels against the
  principal-axis ones through a rotation, which neither shares with the other;
- the inertial angular momentum A^T (J omega - s D psi) conserved under random wheel commands;
- the admissible set keeps |omega_dot_i| <= omega_dot_max (the bound it is derived for);
- the coupled zero-order-hold rate rows: the rate at the check points within their allowance of their
  prediction, along the plant integrated finely, and the filter's commands keep the rate between samples;
- Basilisk's hub with the same tensor agrees over 2,000 s;
- the default filter (gatekeeper on) keeps Monte Carlo runs of the turned vehicle safe.

The barrier rows against finite differences with a tensor: test_gyrostat.py (its tensor variants).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math

import numpy as np
import pytest
from helpers import SKEWED_AXES, against_basilisk, max_angle, turned_vehicle, with_wheels

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.angular_rate import ZOH_TIMES
from rta_attitude.constraints.base import ZOH_ROWS
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import OMEGA, PSI, Q, make_state
from rta_attitude.errors import ConfigError
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.montecarlo.campaign import montecarlo
from rta_attitude.montecarlo.sampling import sample_initial_states

BASE = config.load()
TURNED, R = turned_vehicle(BASE, 25.0)
"""The paper's 6U with its principal axes 25 deg off the body axes: products of inertia up to 0.0073 kg m^2
(a third of its smallest moment)."""
HAVE_BSK = importlib.util.find_spec("Basilisk") is not None
VEHICLES = {"tensor": TURNED, "tensor-skewed-wheels": with_wheels(TURNED, SKEWED_AXES)}
"""The turned 6U, and the same with its wheels on `helpers.SKEWED_AXES` (G = s D J^-1 A with A not the identity:
the general kernels' wheel terms)."""


def _products(values: tuple[float, float, float], **spacecraft_keys: object) -> dict[str, object]:
    return {"spacecraft.products_of_inertia_kgm2": list(values),
            **{f"spacecraft.{k}": v for k, v in spacecraft_keys.items()}}


def test_the_tensor_is_checked_at_load() -> None:
    """One ConfigError line each: not positive definite; principal moments that break a triangle inequality. A
    valid tensor loads, and the kernels take its general arithmetic."""
    with pytest.raises(ConfigError, match="positive definite"):
        config.load(overrides=_products((0.04, 0.0, 0.0)))
    with pytest.raises(ConfigError, match="triangle inequality"):
        config.load(overrides=_products((0.0, 0.0, 0.0), inertia_kgm2=[0.01, 0.01, 0.05]))
    cfg = config.load(overrides=_products((0.001, -0.002, 0.0005)))
    assert not cfg.spacecraft.principal
    p = spacecraft.plant_record(cfg)[0]
    assert p["diagonal"] == 0
    np.testing.assert_allclose(p["inertia_matrix"] @ p["inertia_inverse"], np.eye(3), atol=1e-12)
    assert spacecraft.plant_record(BASE)[0]["diagonal"] == 1


def test_a_turned_vehicle_moves_as_the_principal_one_turned() -> None:
    """Free motion (no wheel momentum or command: the wheels are on the body axes, not on the turned principal
    ones), gravity gradient on, rotating Hill frame: body axes B = R P, so the turned vehicle's attitude is
    R A_P(t) and its rate R omega_P(t). RK4 is covariant under a fixed linear change of variables, so the two
    agree to round-off (5e-12 asserted) over 500 s at rates up to 1 deg/s."""
    env = dataclasses.replace(BASE.environment, gravity_gradient=True, rotating_hill=True)
    principal = dataclasses.replace(BASE, environment=env)
    turned, R = turned_vehicle(principal, 25.0)
    rng = np.random.default_rng(4)
    for _ in range(3):
        q = quat.normalize(rng.normal(size=4))
        w = rng.normal(size=3)
        w *= math.radians(1.0) / np.linalg.norm(w)
        xp = make_state(q, w, (0.0, 0.0, 0.0))
        qb = np.zeros(4)
        quat.from_matrix(R @ quat.attitude_matrices(q), qb)
        xb = make_state(qb, R @ w, (0.0, 0.0, 0.0))
        pp, pb = spacecraft.plant_record(principal), spacecraft.plant_record(turned)
        for _ in range(500):
            xp = spacecraft.integrate(xp, np.zeros(3), 1.0, pp, 10)[0]
            xb = spacecraft.integrate(xb, np.zeros(3), 1.0, pb, 10)[0]
        assert np.abs(xb[OMEGA] - R @ xp[OMEGA]).max() < 5e-12
        assert np.abs(quat.attitude_matrices(xb[Q]) - R @ quat.attitude_matrices(xp[Q])).max() < 5e-12
        assert np.abs(xp[OMEGA] - w).max() > 1e-3 * np.abs(w).max()  # the motion is not trivial


def _momentum_drift(cfg: config.Config, substeps: int) -> float:
    """Largest relative change of A^T (J omega - s D psi) over 2,000 random held commands (1 s each)."""
    p = spacecraft.plant_record(cfg)
    J, sD = cfg.spacecraft.inertia_matrix, cfg.spacecraft.torque_sign * cfg.spacecraft.wheel_inertia_kgm2
    Aw = np.array(cfg.spacecraft.wheel_axes_body).T  # wheel i's axis: column i
    rng = np.random.default_rng(2000)
    x = make_state(quat.normalize(rng.normal(size=4)), [0.01, -0.012, 0.008], [300.0, -200.0, 100.0])

    def inertial(z: np.ndarray) -> np.ndarray:
        return quat.attitude_matrices(z[Q]).T @ (J @ z[OMEGA] - sD * Aw @ z[PSI])

    H0 = inertial(x)
    for u in rng.uniform(-20.0, 20.0, (2000, 3)):
        x = spacecraft.integrate(x, u - 0.05 * x[PSI], 1.0, p, substeps)[0]
    assert np.max(np.abs(x[PSI] - [300.0, -200.0, 100.0])) > 100.0  # the wheels exchanged momentum
    return float(np.linalg.norm(inertial(x) - H0) / np.linalg.norm(H0))


@pytest.mark.parametrize("vehicle", list(VEHICLES))
@pytest.mark.parametrize("torque_sign", [1.0, -1.0])
def test_inertial_momentum_is_conserved_with_products_of_inertia(torque_sign: float, vehicle: str) -> None:
    """No external torque: the inertial momentum A^T (J omega - s D A_w psi) (A_w: the wheels' spin axes) stays
    constant to RK4's accuracy (the change falls by more than 1,000x with 16 times the substeps); a wrong tensor or
    wheel axis anywhere in Euler's equations or the wheel term breaks it."""
    cfg = VEHICLES[vehicle]
    cfg = dataclasses.replace(cfg, spacecraft=dataclasses.replace(cfg.spacecraft, torque_sign=torque_sign))
    coarse, fine = _momentum_drift(cfg, 10), _momentum_drift(cfg, 160)
    assert coarse < 1e-6
    assert fine < coarse / 1000  # RK4: 16^4 = 65,536x for 16x the substeps (measured 1e4-1e5x; the change's
    # sign varies, so neighbouring substep counts can fall by less than 2^4)


@pytest.mark.parametrize("vehicle", list(VEHICLES))
def test_the_admissible_set_keeps_the_angular_acceleration_limit(vehicle: str) -> None:
    """U is derived so that Euler's torque at any rate within omega_max plus any u in U keeps |omega_dot_i| <=
    omega_dot_max (without the wheels' momentum, as the paper derives it). With every wheel turning every axis U is
    the polytope |(G u)_i| <= b_i: its vertices u = G^-1 a (a at the corners of the box +-b) keep the limit at
    20,000 random rates (corners included) and reach it within 2x; the box U bounds the polytope exactly (each
    wheel's bound reached at a vertex); and the filter's answers to desired commands far outside it stay in it."""
    cfg = VEHICLES[vehicle].with_models("paper", "paper")
    p = spacecraft.plant_record(cfg)
    G, b = cfg.spacecraft.control_matrix, cfg.accel_limit_rad_s2
    rng = np.random.default_rng(9)
    W = cfg.limits.omega_max_rad_s
    w = rng.uniform(-W, W, (20000, 3))
    w[:8] = W * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    vertices = np.linalg.solve(G, (signs * b).T).T
    np.testing.assert_allclose(np.abs(vertices).max(axis=0), cfg.u_max_rad_s2, rtol=1e-12)
    x = np.repeat(make_state([0, 0, 0, 1])[None, :], len(w), axis=0)
    x[:, OMEGA] = w
    worst = 0.0
    for u in vertices:
        worst = max(worst, float(np.abs(spacecraft.omega_dot(x, u, p)).max()))
    assert worst <= cfg.limits.omega_dot_max_rad_s2 * (1 + 1e-12)
    assert worst > 0.5 * cfg.limits.omega_dot_max_rad_s2
    f = AsifFilter(cfg.with_backup("none"))
    states, _ = sample_initial_states(50, 3, cfg)
    tol = 1e-9 * float(np.abs(b).max())
    solved = 0
    for k, u_des in enumerate(rng.uniform(-3.0, 3.0, (50, 3)) * cfg.u_max_rad_s2):
        r = f.filter(states[k], u_des)
        if str(r.status) == "solved":
            solved += 1
            assert np.all(np.abs(G @ np.asarray(r.u)) <= b + tol), (k, G @ np.asarray(r.u), b)
    assert solved >= 25


FINE = 200


@pytest.mark.parametrize("vehicle", list(VEHICLES))
@pytest.mark.parametrize("model", ["gyrostat", "paper"])
def test_zoh_rate_rows_hold_along_the_finely_integrated_plant(model: str, vehicle: str) -> None:
    """With products of inertia every wheel turns every axis, so the robust preset replaces the per-axis interval
    by the coupled rows for either model. At each check point the rate integrated finely (200 RK4 steps over the
    hold) lies within the rows' allowance of their prediction, for random u in U (the polytope |(G u)_i| <= b_i,
    which the rows' bounds assume) at 200 Monte Carlo states; and the filter's solved commands (desired commands up
    to 1.5 U's bounding box) keep |omega_i| <= omega_max at every fine step."""
    cfg = VEHICLES[vehicle].with_models(model, model).with_backup("none")
    limit = (1 - cfg.filter.zoh_margin) * cfg.limits.omega_max_rad_s
    dt = cfg.filter.sample_time_s
    p = spacecraft.plant_record(cfg)
    x, _ = sample_initial_states(200, 11, cfg)
    tab = ConstraintSet(cfg).evaluate(x)
    assert np.all(tab.zoh_rows == ZOH_ROWS)
    rng = np.random.default_rng(18)
    ratios = []
    G, b = cfg.spacecraft.control_matrix, cfg.accel_limit_rad_s2
    for k in range(len(x)):
        u = np.linalg.solve(G, rng.uniform(-1, 1, 3) * b)  # a point of the polytope
        traj = spacecraft.integrate(x[k], u, dt, p, FINE)[1]
        for q in range(ZOH_ROWS):
            m, i = q // 3, tab.zoh_axis[k, q]
            free = -(tab.zoh_lo[k, q] + tab.zoh_hi[k, q]) / 2
            allowance = limit - (tab.zoh_hi[k, q] - tab.zoh_lo[k, q]) / 2
            err = abs(traj[round(ZOH_TIMES[m] * FINE) - 1, OMEGA][i] - (tab.zoh_gain[k, q] @ u + free))
            assert err <= allowance, (k, m, i, err, allowance)
            ratios.append(err / allowance)
    assert np.median(ratios) < 0.3  # the linear part is right: the error is far inside the allowance
    f = AsifFilter(cfg)
    worst, solved = 0.0, 0
    for k in range(len(x)):
        r = f.filter(x[k], rng.uniform(-1.5, 1.5, 3) * cfg.u_max_rad_s2)
        if str(r.status) in ("solved", "pass"):
            solved += 1
            w = spacecraft.integrate(x[k], np.asarray(r.u, dtype=float), dt, p, FINE)[1][:, OMEGA]
            worst = max(worst, float(np.abs(w).max()))
    assert solved > 100
    assert worst <= cfg.limits.omega_max_rad_s


@pytest.mark.skipif(not HAVE_BSK, reason="Basilisk is not installed (pip install rta_attitude[basilisk])")
@pytest.mark.parametrize("vehicle", [*VEHICLES, "tensor-skewed-wheels-wheel_y-failed"])
def test_basilisk_hub_with_the_tensor_agrees_over_2000_s(vehicle: str) -> None:
    """Basilisk's hub inertia is the tensor (plus D A A^T, its wheels' spin-axis part; its wheels on the
    configured axes through rwFactory; a failed wheel's motor torque 0): random commands in U held 1 s for
    2,000 s, rotating Hill frame. Both integrate the same ODE with RK4 at 0.1 s, so rates and wheel speeds agree
    to accumulated round-off (< 1e-10 rad/s asserted) and the attitude differs only by the parametrisation inside
    RK4 (MRP there, quaternion here): well inside the compiled plant's own h vs h/2 difference."""
    failed = vehicle.endswith("-wheel_y-failed")
    cfg = VEHICLES[vehicle.removesuffix("-wheel_y-failed")]
    box = cfg.u_max_rad_s2  # every wheel commanded, the failed one too
    if failed:
        cfg = dataclasses.replace(cfg, spacecraft=dataclasses.replace(cfg.spacecraft, failed_wheels=("wheel_y",)))
    cfg = dataclasses.replace(cfg, environment=dataclasses.replace(cfg.environment, rotating_hill=True))
    rng = np.random.default_rng(11)
    x0 = cfg.scenario("paper-example").x0.copy()
    x0[OMEGA] = math.radians(0.5) * np.array([0.6, -0.48, 0.64])
    x0[PSI] = np.array([120.0, -80.0, 60.0])
    us = rng.uniform(-1.0, 1.0, (2000, 3)) * 0.2 * box
    us -= 0.002 * np.cumsum(us, axis=0)  # a pull-back that keeps the wheels within a few hundred rad/s

    ours, fine, bsk = against_basilisk(cfg, x0, us)

    assert np.abs(ours[:, PSI] - x0[PSI]).max() > 50.0  # the wheels exchanged momentum
    att, truncation = max_angle(bsk[:, Q], ours[:, Q]), max_angle(fine[:, Q], ours[:, Q])
    assert att < 0.1 * truncation, (att, truncation)  # measured 3.7e-8 rad against 8.2e-7
    assert np.abs(bsk[:, OMEGA] - ours[:, OMEGA]).max() < 1e-10
    assert np.abs(bsk[:, PSI] - ours[:, PSI]).max() < 1e-10
    if failed:  # the failed wheel coasts in both (Basilisk's psi is rebuilt from its relative speed: round-off)
        assert np.all(ours[:, PSI.start + 1] == x0[PSI.start + 1])
        np.testing.assert_allclose(bsk[:, PSI.start + 1], x0[PSI.start + 1], rtol=0, atol=1e-10)


def test_the_default_filter_keeps_the_turned_vehicle_safe() -> None:
    """The default configuration (robust preset, gatekeeper) on the turned 6U: the first 40 runs of seed 7's
    1,000-run draw are all safe at every substep (measured: 99 of the first 100; run 53 fails, a large-momentum
    state whose battery the backup law cannot save)."""
    result = montecarlo(TURNED, 1000, 2000.0, 7, max_runs=40)
    failed = np.flatnonzero(result.failed(substeps=True))
    assert failed.size == 0, failed
