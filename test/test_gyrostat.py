"""The gyrostat plant, the rotating Hill frame and the gravity gradient against independent
computations: barrier rows against central finite differences along the plant's derivative,
conservation of the inertial angular momentum, the reaction sign by hand, the gravity-gradient
torque by hand, and the difference between the paper's model and the gyrostat.

Sign convention (docs/gyrostat.md): with tau = s D u (s = spacecraft.torque_sign) the wheels hold the
angular momentum -s D psi, so H = J omega - s D psi and
    J omega_dot = -omega x (J omega - s D psi) + s D u,   psi_dot = u,
    dH/dt (body) = J omega_dot - s D u = -omega x H   =>   d/dt (A(q)^T H) = 0 (Hill inertial).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from helpers import SKEWED_AXES, random_states, turned_vehicle, with_wheels

from rta_attitude import config
from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import OMEGA, PSI, make_state

BASE = config.load()
D = BASE.spacecraft.wheel_inertia_kgm2
J = BASE.spacecraft.J
N_ORB = BASE.environment.mean_motion_rad_s


def variant(model: str = "gyrostat", rotating_hill: bool = False, gravity_gradient: bool = False,
            torque_sign: float = 1.0, turn_deg: float = 0.0, skewed: bool = False) -> Config:
    """The default configuration with the plant (and the filter's model) set as asked; turn_deg: the vehicle's
    principal axes that far from the body axes (products of inertia, `helpers.turned_vehicle`); skewed: its
    wheels on `helpers.SKEWED_AXES`."""
    sc = dataclasses.replace(BASE.spacecraft, model=model, torque_sign=torque_sign)
    env = dataclasses.replace(BASE.environment, rotating_hill=rotating_hill, gravity_gradient=gravity_gradient)
    cfg = dataclasses.replace(BASE, spacecraft=sc, environment=env).with_models(model, model)
    cfg = turned_vehicle(cfg, turn_deg)[0] if turn_deg else cfg
    return with_wheels(cfg, SKEWED_AXES) if skewed else cfg


VARIANTS = {f"hill={'rot' if r else 'inertial'}-gg={'on' if g else 'off'}": (r, g)
            for r in (False, True) for g in (False, True)}
ROW_VARIANTS = {**{k: (r, g, 0.0, False) for k, (r, g) in VARIANTS.items()},
                "tensor-25deg-hill=rot-gg=on": (True, True, 25.0, False),
                "tensor-60deg-hill=inertial-gg=off": (False, False, 60.0, False),
                "skewed-wheels-hill=rot-gg=on": (True, True, 0.0, True),
                "skewed-wheels-tensor-25deg-hill=inertial-gg=off": (False, False, 25.0, True)}
"""VARIANTS, two vehicles with products of inertia (principal axes 25 and 60 deg off the body axes) and two with
skewed wheels (`helpers.SKEWED_AXES`: every wheel turns every axis, its momentum on every axis)."""


# ----------------------------------------------------------------------------- (i) rows vs finite differences
EPS = 1e-5
DEGREE = (2, 2, 2, 2, 1, 1, 1, 1, 1, 1)
"""Relative degree of each row as enforced, CONSTRAINT_NAMES order."""


def _kink_distance(cs: ConstraintSet, x: np.ndarray) -> np.ndarray:
    """Distance (rad) of each state to the nearest non-smooth point of any barrier (clamps, poles)."""
    d = [np.minimum.reduce([th, np.pi - th, np.abs(th - np.pi / 2)]) for th in cs.angles(x).values()]
    return np.min(d, axis=0)


def _along(fun, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    """d/dt fun(x(t)) at t = 0 along the plant's derivative x_dot = f(x) + g u: central differences of
    fun at x -+ eps x_dot (independent of the rows' chain rule)."""
    xdot = spacecraft.state_derivative(x, u, p)
    return (fun(x + EPS * xdot) - fun(x - EPS * xdot)) / (2 * EPS)


@pytest.mark.parametrize("name", list(ROW_VARIANTS))
def test_gyrostat_rows_are_the_derivatives_of_their_levels(name: str) -> None:
    """h = safety value; Psi_1 = d/dt Psi_0 + k1 Psi_0; drift + gain . u = d/dt Psi_1 + k2 Psi_1 + bias
    (relative degree 1: d/dt h + k1 h + bias), the derivatives taken numerically along the gyrostat
    plant's derivative, with the Hill frame rotating or not, gravity gradient on or off, and with products of
    inertia (every row's gain then reaches every wheel)."""
    r, g, turn, skewed = ROW_VARIANTS[name]
    cfg = variant("gyrostat", r, g, turn_deg=turn, skewed=skewed)
    cs = ConstraintSet(cfg)
    p = spacecraft.plant_record(cfg)
    assert p[0]["wheel_gyroscopic"] == 1
    rng = np.random.default_rng(18)
    x = random_states(rng, 1600, cfg)
    x = x[_kink_distance(cs, x) > 0.02][:800]
    assert len(x) >= 600
    u = rng.uniform(-1, 1, (len(x), 3)) * cfg.u_max_rad_s2
    tab = cs.evaluate(x)
    np.testing.assert_array_equal(tab.h, cs.safety_values(x))
    dpsi0 = _along(lambda z: cs.evaluate(z).psi0, x, u, p)
    dpsi1 = _along(lambda z: cs.evaluate(z).psi1, x, u, p)
    bc = tab.drift + np.einsum("nmk,nk->nm", tab.gain, u)
    for i, cname in enumerate(cs.names):
        g = cfg.gains(cname)
        if DEGREE[i] == 2:
            expect = dpsi0[:, i] + g.k1 * tab.psi0[:, i]
            err = np.abs(tab.psi1[:, i] - expect)
            assert np.max(err / (np.abs(expect) + 1e-6)) < 1e-4, f"{cname} psi1"
        k = g.k2 if DEGREE[i] == 2 else g.k1
        expect = dpsi1[:, i] + k * tab.psi1[:, i] + g.bias
        err = np.abs(bc[:, i] - expect)
        scale = np.abs(expect) + np.abs(tab.drift[:, i]) + 1e-9
        assert np.quantile(err / scale, 0.99) < 1e-5, f"{cname} bc"
        assert np.max(err / scale) < 1e-3, f"{cname} bc"


@pytest.mark.parametrize("name", list(VARIANTS))
def test_gyrostat_rate_row_drift_is_the_wheel_torque(name: str) -> None:
    """The omega rows' drift differs between gyrostat and paper models by exactly the wheel term
    -2 omega_i (D omega x psi)_i / J_i, by hand (gravity gradient and frame enter both alike)."""
    r, g = VARIANTS[name]
    x = random_states(np.random.default_rng(5), 200, BASE)
    gy = ConstraintSet(variant("gyrostat", r, g)).evaluate(x)
    pa = ConstraintSet(variant("paper", r, g)).evaluate(x)
    wheel = D * np.cross(x[:, OMEGA], x[:, PSI]) / J
    np.testing.assert_allclose(gy.drift[:, 4:7] - pa.drift[:, 4:7], -2 * x[:, OMEGA] * wheel, rtol=1e-9, atol=1e-16)


# ----------------------------------------------------------------------------- (ii) conservation
def _commands(rng: np.random.Generator, steps: int) -> np.ndarray:
    return rng.uniform(-20.0, 20.0, (steps, 3))


def _momentum_drift(torque_sign: float, substeps: int) -> float:
    """|A^T H(2000 s) - A^T H(0)| / |H(0)| and |H| likewise over 2,000 random held commands (1 s holds),
    H = J omega - s D psi; the largest of the two relative changes."""
    cfg = variant("gyrostat", rotating_hill=False, gravity_gradient=False, torque_sign=torque_sign)
    p = spacecraft.plant_record(cfg)
    rng = np.random.default_rng(2000)
    x = make_state(quat.normalize(rng.normal(size=4)), [0.01, -0.012, 0.008], [300.0, -200.0, 100.0],
                   T_K=280.0, E_J=5000.0)
    u = _commands(rng, 2000)

    def body(z: np.ndarray) -> np.ndarray:
        return J * z[OMEGA] - torque_sign * D * z[PSI]

    H0 = quat.attitude_matrices(x[0:4]).T @ body(x)
    for k in range(2000):
        # arbitrary commands, with a pull-back that keeps the wheels (and so the body rate) bounded
        x = spacecraft.integrate(x, u[k] - 0.05 * x[PSI], 1.0, p, substeps)[0]
    assert np.max(np.abs(x[PSI] - [300.0, -200.0, 100.0])) > 100.0  # the wheels did exchange momentum
    H = quat.attitude_matrices(x[0:4]).T @ body(x)
    return max(np.linalg.norm(H - H0), abs(np.linalg.norm(body(x)) - np.linalg.norm(H0))) / np.linalg.norm(H0)


@pytest.mark.parametrize("torque_sign", [1.0, -1.0])
def test_inertial_momentum_is_conserved_with_arbitrary_commands(torque_sign: float) -> None:
    """No external torque (no gravity gradient, Hill inertial): A(q)^T (J omega - s D psi) and its norm stay
    constant over 2,000 s of random commands to RK4 accuracy: the change is small with 10 substeps (body
    rates reach ~0.7 rad/s here) and falls by more than 10x with twice the substeps (RK4's 16x)."""
    coarse, fine = _momentum_drift(torque_sign, 10), _momentum_drift(torque_sign, 20)
    assert coarse < 1e-6
    assert fine < coarse / 10


def test_paper_model_does_not_conserve_the_momentum() -> None:
    """The same run under the paper's model: the wheel term missing, A^T (J omega - D psi) drifts (this is
    what the dropped term costs, and shows the test above can fail)."""
    cfg = variant("paper")
    p = spacecraft.plant_record(cfg)
    x = make_state([0, 0, 0, 1], [0.01, -0.012, 0.008], [300.0, -200.0, 100.0], T_K=280.0, E_J=5000.0)
    H0 = quat.attitude_matrices(x[0:4]).T @ (J * x[OMEGA] - D * x[PSI])
    for _ in range(100):
        x = spacecraft.integrate(x, np.zeros(3), 1.0, p, 10)[0]
    H = quat.attitude_matrices(x[0:4]).T @ (J * x[OMEGA] - D * x[PSI])
    assert np.linalg.norm(H - H0) > 1e-4 * np.linalg.norm(H0)


# ----------------------------------------------------------------------------- (iii) reaction sign by hand
@pytest.mark.parametrize("model", ["gyrostat", "paper"])
@pytest.mark.parametrize("torque_sign", [1.0, -1.0])
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_reaction_from_rest_by_hand(model: str, torque_sign: float, axis: int) -> None:
    """From rest, u = 10 rad/s^2 on one wheel for 1 s: psi = 10 rad/s, omega = s D 10 / J_axis rad/s about
    that axis only (the wheel momentum is parallel to omega, so no gyroscopic torque), and J omega - s D psi
    stays 0."""
    cfg = variant(model, torque_sign=torque_sign)
    p = spacecraft.plant_record(cfg)
    x0 = make_state([0, 0, 0, 1], T_K=280.0, E_J=5000.0)
    u = np.zeros(3)
    u[axis] = 10.0
    x = spacecraft.integrate(x0, u, 1.0, p, 10)[0]
    psi = np.zeros(3)
    psi[axis] = 10.0
    w = np.zeros(3)
    w[axis] = torque_sign * 4.1e-5 * 10.0 / (0.022, 0.044, 0.056)[axis]
    np.testing.assert_allclose(x[PSI], psi, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(x[OMEGA], w, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(J * x[OMEGA] - torque_sign * D * x[PSI], 0.0, atol=1e-18)


# ----------------------------------------------------------------------------- (iv) paper vs gyrostat
def test_paper_model_drops_exactly_the_wheel_term() -> None:
    """omega_dot(gyrostat) - omega_dot(paper) = D omega x psi / J at any state and u, and after one short
    RK4 step omega differs by that times the step (to second order)."""
    gy, pa = spacecraft.plant_record(variant("gyrostat")), spacecraft.plant_record(variant("paper"))
    rng = np.random.default_rng(4)
    x = random_states(rng, 500, BASE)
    u = rng.uniform(-18, 18, (500, 3))
    wheel = D * np.cross(x[:, OMEGA], x[:, PSI]) / J
    np.testing.assert_allclose(spacecraft.omega_dot(x, u, gy) - spacecraft.omega_dot(x, u, pa), wheel,
                               rtol=1e-9, atol=1e-18)
    # one 10 ms step: the omega difference is h wheel + h^2/2 d/dt(wheel) + ..., with
    # |d/dt(D omega x psi / J)| <= D/J (|omega_dot| |psi| + |omega| |u|)
    h = 0.01
    for k in range(50):
        a = spacecraft.integrate(x[k], u[k], h, gy, 1)[0]
        b = spacecraft.integrate(x[k], u[k], h, pa, 1)[0]
        wdot = np.linalg.norm(spacecraft.omega_dot(x[k], u[k], gy))
        rate = D / J * (wdot * np.linalg.norm(x[k, PSI]) + np.linalg.norm(x[k, OMEGA]) * np.linalg.norm(u[k]))
        assert np.all(np.abs(a[OMEGA] - b[OMEGA] - h * wheel[k]) <= h**2 * rate)


def test_wheel_torque_magnitude_of_the_issue() -> None:
    """The issue's numbers: D psi_max = 0.0236 N m s; at |omega| = 1 deg/s across a wheel at 576 rad/s the
    gyroscopic torque is D omega psi = 4.1e-4 N m (half of J1 2 deg/s^2 = 7.7e-4 N m)."""
    x = make_state([0, 0, 0, 1], [0.0, math.radians(1.0), 0.0], [0.0, 0.0, 576.0])
    gy, pa = spacecraft.plant_record(variant("gyrostat")), spacecraft.plant_record(variant("paper"))
    tau = J * (spacecraft.omega_dot(x, np.zeros(3), gy) - spacecraft.omega_dot(x, np.zeros(3), pa))
    assert tau[0] == pytest.approx(4.1e-5 * math.radians(1.0) * 576.0, rel=1e-12)
    assert tau[0] == pytest.approx(4.12e-4, rel=1e-2)


# ----------------------------------------------------------------------------- gravity gradient, rotating Hill
def test_gravity_gradient_by_hand_and_restoring() -> None:
    """Body rotated by a about Hill z (A = R_z(a), passive): zenith in body = [cos a, -sin a, 0], so
    tau_z = 3 n^2 (J2 - J1) cos a (-sin a): restoring (J1 < J2: the minimum axis seeks the zenith)."""
    cfg = variant("paper", gravity_gradient=True)
    cfg0 = variant("paper", gravity_gradient=False)
    for a in (0.1, -0.3, 1.0):
        q = [0.0, 0.0, math.sin(a / 2), math.cos(a / 2)]
        x = make_state(q, T_K=280.0, E_J=5000.0)
        tau = J * (spacecraft.omega_dot(x, np.zeros(3), spacecraft.plant_record(cfg))
                   - spacecraft.omega_dot(x, np.zeros(3), spacecraft.plant_record(cfg0)))
        expect = 3 * N_ORB**2 * (0.044 - 0.022) * math.cos(a) * (-math.sin(a))
        np.testing.assert_allclose(tau, [0.0, 0.0, expect], rtol=1e-12, atol=1e-22)
        assert np.sign(tau[2]) == -np.sign(a)


def test_body_locked_to_the_rotating_hill_frame_keeps_its_attitude() -> None:
    """Rotating Hill frame: a body turning at n about Hill z (a principal axis) keeps q constant, while
    with the Hill frame inertial the same rate turns it by n t."""
    q0 = [0.0, 0.0, 0.0, 1.0]
    x0 = make_state(q0, [0.0, 0.0, N_ORB], T_K=280.0, E_J=5000.0)
    x = spacecraft.integrate(x0, np.zeros(3), 1000.0, spacecraft.plant_record(variant(rotating_hill=True)), 100)[0]
    np.testing.assert_allclose(x[0:4], q0, atol=1e-13)
    x = spacecraft.integrate(x0, np.zeros(3), 1000.0, spacecraft.plant_record(variant(rotating_hill=False)), 100)[0]
    np.testing.assert_allclose(x[0:4], [0.0, 0.0, math.sin(N_ORB * 500.0), math.cos(N_ORB * 500.0)], atol=1e-12)
