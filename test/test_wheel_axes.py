"""Wheels on any spin axes (`spacecraft.wheel_spin_axes_body`) against independent computations.

- the check at load (unit axes, one per wheel, spanning the body's three axes);
- a vehicle whose principal axes and wheels are turned together by R moves as the paper's vehicle turned by R,
  with the wheels' momentum and commands (the general kernels, G = s D J^-1 A and the momentum -s D A psi,
  against the per-axis ones through a rotation neither shares);
- the torque interface: what crosses DDS is the body torque D A u, and a wheel command comes back from it;
- the wheel-speed limit relative to the body judges psi_i + a_i . omega;
- the default filter (gatekeeper on) keeps the Monte Carlo runs of a vehicle with skewed wheels safe below a large
  momentum.

Also with skewed wheels: the barrier rows against finite differences (test_gyrostat.py), the inertial momentum
conserved, the coupled ZOH rate rows along the finely integrated plant and Basilisk's rwFactory array over
2,000 s (test_inertia_tensor.py), a lockstep run over Fast DDS equal to `simulate` (test_nodes.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import SKEWED_AXES, turned_with_wheels, with_wheels

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import OMEGA, PSI, Q, make_state
from rta_attitude.errors import ConfigError
from rta_attitude.filter.gatekeeper.records import backup_record
from rta_attitude.montecarlo.campaign import montecarlo
from rta_attitude.montecarlo.sampling import sample_initial_states

ROOT = Path(__file__).resolve().parents[1]
BASE = config.load()
SKEWED = with_wheels(BASE, SKEWED_AXES)


def _axes(**wheels: list[float]) -> dict[str, object]:
    return {f"spacecraft.wheel_spin_axes_body.{k}": v for k, v in wheels.items()}


def test_the_wheel_axes_are_checked_at_load() -> None:
    """One ConfigError line each: an axis that is not a unit vector; three axes in one plane (no 3-axis control).
    Axes given to three decimals load normalised, and the kernels take their general arithmetic; the default is
    the paper's, per axis."""
    x, y = [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]
    with pytest.raises(ConfigError, match="wheel_x must be a unit vector"):
        config.load(overrides=_axes(wheel_x=[1.0, 0.5, 0.0]))
    with pytest.raises(ConfigError, match="span the three body axes"):
        config.load(overrides=_axes(wheel_x=x, wheel_y=y, wheel_z=[0.707, 0.707, 0.0]))
    cfg = config.load(overrides=_axes(wheel_z=[0.577, 0.577, 0.577]))
    assert cfg.spacecraft.wheel_axes_body[2] == pytest.approx((3 ** -0.5,) * 3, rel=1e-12)
    assert not cfg.spacecraft.diagonal and cfg.spacecraft.principal
    p = spacecraft.plant_record(cfg)[0]
    assert p["diagonal"] == 0
    np.testing.assert_allclose(p["wheel_axes"] @ p["wheel_axes_inverse"], np.eye(3), atol=1e-12)
    assert BASE.spacecraft.diagonal and spacecraft.plant_record(BASE)[0]["diagonal"] == 1


@pytest.mark.parametrize("model", ["gyrostat", "paper"])
def test_a_vehicle_turned_with_its_wheels_moves_as_the_paper_one_turned(model: str) -> None:
    """Principal axes and wheels turned together by R (wheel i on R e_i, J = R J_P R^T): the body's rate is R
    omega_P, the attitude R A_P, the wheel speeds the same, under the same wheel commands, with the wheels'
    gyroscopic torque (gyrostat) and the gravity gradient in the rotating Hill frame. RK4 is covariant under a
    fixed linear change of variables, so they agree to round-off over 300 s of random commands."""
    base = BASE.with_models(model, model)
    env = base.environment.__class__(**{**base.environment.__dict__, "gravity_gradient": True,
                                        "rotating_hill": True})
    paper = base.__class__(**{**base.__dict__, "environment": env})
    turned, R = turned_with_wheels(paper, 35.0, (2.0, -1.0, 1.0))
    assert not turned.spacecraft.diagonal
    pp, pb = spacecraft.plant_record(paper), spacecraft.plant_record(turned)
    rng = np.random.default_rng(35)
    q = quat.normalize(rng.normal(size=4))
    w = math.radians(0.5) * rng.uniform(-1, 1, 3)
    psi = rng.uniform(-400.0, 400.0, 3)
    xp = make_state(q, w, psi)
    qb = np.zeros(4)
    quat.from_matrix(R @ quat.attitude_matrices(q), qb)
    xb = make_state(qb, R @ w, psi)
    for u in rng.uniform(-1.0, 1.0, (300, 3)) * 0.3 * BASE.u_max_rad_s2:
        xp = spacecraft.integrate(xp, u, 1.0, pp, 10)[0]
        xb = spacecraft.integrate(xb, u, 1.0, pb, 10)[0]
    assert np.abs(xb[OMEGA] - R @ xp[OMEGA]).max() < 1e-11
    assert np.abs(xb[PSI] - xp[PSI]).max() < 1e-9
    assert np.abs(quat.attitude_matrices(xb[Q]) - R @ quat.attitude_matrices(xp[Q])).max() < 1e-10
    assert np.abs(xp[PSI] - psi).max() > 10.0  # the commands moved the wheels


def test_the_torque_interface_carries_the_body_torque() -> None:
    """torque_cmd is the body torque D A u of the wheel accelerations u, and the plant gets u = A^-1 tau / D back
    (to round-off); the compiled round trip the in-process loops make equals the nodes' two conversions bit for
    bit (a lockstep run over DDS equals `simulate`); a primary controller's demand v reaches the filter as the
    wheel accelerations whose torque is D v. With the paper's wheels every conversion is per axis."""
    rng = np.random.default_rng(3)
    for cfg in (SKEWED, BASE):
        p = spacecraft.plant_record(cfg)
        A, D = np.array(cfg.spacecraft.wheel_axes_body).T, cfg.spacecraft.wheel_inertia_kgm2
        for u in rng.uniform(-50.0, 50.0, (200, 3)):
            tau = spacecraft.wheels_to_torque(u, p)
            np.testing.assert_allclose(tau, D * (A @ u), rtol=1e-13, atol=1e-18)
            back = spacecraft.torque_to_wheels(tau, p)
            np.testing.assert_allclose(back, u, rtol=1e-12, atol=1e-12)
            demand = np.empty(3)
            spacecraft.demand_round_trip(u, p[0], demand)
            np.testing.assert_allclose(D * (A @ demand), D * u, rtol=1e-12, atol=1e-16)
        u = rng.uniform(-50.0, 50.0, 3)
        out = np.empty(3)
        spacecraft.torque_round_trip(u, p[0], out)
        np.testing.assert_array_equal(out, spacecraft.torque_to_wheels(spacecraft.wheels_to_torque(u, p), p))
    p = spacecraft.plant_record(BASE)
    np.testing.assert_array_equal(spacecraft.wheels_to_torque(u, p), BASE.spacecraft.wheel_inertia_kgm2 * u)


def test_the_relative_wheel_speed_is_along_each_wheels_axis() -> None:
    """With `limits.wheel_speed_relative_to_body`, h_i = psi_max^2 - (psi_i + a_i . omega)^2 (the rotor's speed
    relative to the body, computed here from the axes directly); the rows keep |psi_i| <= psi_max - omega_max
    max_i |a_i|_1."""
    limits = BASE.limits.__class__(**{**BASE.limits.__dict__, "wheel_speed_relative_to_body": True})
    cfg = SKEWED.__class__(**{**SKEWED.__dict__, "limits": limits})
    A = np.array(cfg.spacecraft.wheel_axes_body)  # rows a_i
    x, _ = sample_initial_states(50, 2, cfg)
    cs = ConstraintSet(cfg)
    h = cs.safety_values(x)
    rows = [i for i, n in enumerate(cs.names) if n.startswith("psi_")]
    v = x[:, PSI] + x[:, OMEGA] @ A.T
    np.testing.assert_allclose(h[:, rows], limits.psi_max_rad_s**2 - v**2, rtol=1e-12, atol=1e-9)
    reach = np.abs(A).sum(axis=1).max()
    assert reach > 1.2
    assert cfg.psi_keep_rad_s == pytest.approx(limits.psi_max_rad_s - limits.omega_max_rad_s * reach, rel=1e-15)


def test_the_default_filter_keeps_a_vehicle_with_skewed_wheels_safe_below_a_large_momentum() -> None:
    """The default configuration (robust preset, gatekeeper) with the wheels tilted 20 deg
    (config/examples/skewed_wheels.yaml), the first 20 runs of seed 7's 1,000-run draw: every run whose momentum
    every wheel can hold at rest in any attitude (|H| / D below the gatekeeper's large-momentum threshold, derived
    from the wheels' axes) is safe at every substep, and so are some of the others; the runs that fail are
    large-momentum states (measured on the first 30: runs 0 and 5 fail, both above it)."""
    cfg = config.load(ROOT / "config" / "examples" / "skewed_wheels.yaml")
    result = montecarlo(cfg, 1000, 2000.0, 7, max_runs=20)
    failed = result.failed(substeps=True)
    p = spacecraft.plant_record(cfg)[0]
    H = np.array([[spacecraft.angular_momentum(p, x, a) for a in range(3)] for x in result.x0])
    threshold = backup_record(cfg)[0]["momentum_variant_rad_s"]
    large = np.linalg.norm(H, axis=1) / cfg.spacecraft.wheel_inertia_kgm2 > threshold
    assert 0 < large.sum() < len(large)  # both kinds are in the draw
    assert not np.any(failed & ~large), np.flatnonzero(failed)
    assert np.sum(large & ~failed) > np.sum(failed)


TILTED = config.load(ROOT / "config" / "examples" / "skewed_wheels.yaml")
"""The shipped example's array: each wheel 20 deg off its body axis toward [1, 1, 1]."""


@pytest.mark.parametrize("cfg", [SKEWED, TILTED], ids=["generic", "tilted"])
def test_the_momentum_modes_place_holds_every_momentum_some_direction_holds(cfg: config.Config) -> None:
    """With the wheels off the body axes the momentum mode puts H_body on a vertex of the array (`law._vertex`):
    for |H| from small to past what any direction holds and H_body in every direction, where a direction of a fine
    grid over the sphere holds |H| at rest with the rates' share (an independent search), the chosen one does too
    (each wheel within psi_limit); where none does, the chosen one holds the most any does. Below what every
    direction holds, the vertex of the wheels' own pattern."""
    from rta_attitude.dynamics.spacecraft import wheel_rate_momentum
    from rta_attitude.filter.gatekeeper.law import _vertex

    b = backup_record(cfg)[0]
    p = b["law_plant"]
    Ai, D = p["wheel_axes_inverse"], float(p["wheel_inertia_kgm2"])
    rates = np.array([wheel_rate_momentum(p, i) for i in range(3)]) * float(b["omega_max_rad_s"])
    limit = float(b["psi_limit_rad_s"])

    def load(d: np.ndarray, hn: float) -> np.ndarray:  # (..., 3) unit directions: the most loaded wheel less its limit
        return np.max((np.abs(d @ Ai.T) * hn + rates) / D, axis=-1) - limit

    rng = np.random.default_rng(44)
    grid = rng.normal(size=(200_000, 3))
    grid /= np.linalg.norm(grid, axis=1, keepdims=True)
    most = float(np.max(1.0 / np.max(np.abs(grid @ Ai.T), axis=1)))  # |H| per unit of the best wheel's share
    everywhere = float(np.min(1.0 / np.max(np.abs(grid @ Ai.T), axis=1)))
    top = (limit * D - rates.max()) * most
    checked = 0
    for hn in np.linspace(0.05, 1.1, 12) * top:
        for h in rng.normal(size=(40, 3)):
            h = h / np.linalg.norm(h)
            d = np.array(_vertex(*(hn * h), hn, 1.0, p, b))
            assert np.linalg.norm(d) == pytest.approx(1.0, abs=1e-12)
            if np.min(load(grid, hn)) <= 0.0:
                assert load(d, hn) <= 1e-9
                checked += 1
            else:
                assert load(d, hn) <= np.min(load(grid, hn)) + 1e-9
            if hn * 1.001 < (limit * D - rates.max()) * everywhere:  # every vertex holds it: the wheels' own
                assert np.all(np.sign(Ai @ d) == np.sign(Ai @ h))
    assert checked > 300
