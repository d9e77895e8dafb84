"""The compiled plant (rta_attitude.dynamics) against closed forms, hand calculations, conservation laws
and the independent numpy implementation (oracles.model)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import random_states
from oracles import model as oracle

from rta_attitude import config
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.controller import controller_record, desired_command
from rta_attitude.dynamics.environment import sun_hill
from rta_attitude.dynamics.state import ENERGY, OMEGA, PSI, TEMP, THETA_S, make_state

CFG = config.load()
P = spacecraft.plant_record(CFG)
RNG = np.random.default_rng(42)


def rodrigues(axis, angle):
    """Rotation matrix of a frame rotation (passive), matching A(q) for q = [sin(a/2) e, cos(a/2)]."""
    e = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    return np.cos(angle) * np.eye(3) + (1 - np.cos(angle)) * np.outer(e, e) - np.sin(angle) * K


def _integrate(x, u, t_s, substeps, p=P):
    return spacecraft.integrate(x, u, t_s, p, substeps)[0]


def test_attitude_matrix_against_rodrigues():
    e = RNG.normal(size=(200, 3))
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    a = RNG.uniform(-np.pi, np.pi, 200)
    q = np.c_[np.sin(a / 2)[:, None] * e, np.cos(a / 2)]
    A = quat.attitude_matrices(q)
    for k in range(200):
        np.testing.assert_allclose(A[k], rodrigues(e[k], a[k]), atol=1e-12)


def test_product_composes_attitude_matrices():
    q = quat.normalize(RNG.normal(size=(100, 4)))
    p = quat.normalize(RNG.normal(size=(100, 4)))
    qp = np.empty((100, 4))
    for k in range(100):
        quat.product(q[k], p[k], qp[k])
    np.testing.assert_allclose(quat.attitude_matrices(qp),
                               np.einsum("nij,njk->nik", quat.attitude_matrices(q), quat.attitude_matrices(p)),
                               atol=1e-12)


def test_error_vector_of_the_paper_commands():
    q = quat.normalize(np.array([0.680, -0.151, 0.630, 0.343]))
    np.testing.assert_allclose(quat.error_vectors(q, np.array([0, 0, 0, 1.0])), q[:3])
    q1, _q2, q3, q4 = q
    np.testing.assert_allclose(quat.error_vectors(q, np.array([0, 1.0, 0, 0])), [-q3, -q4, q1], atol=1e-15)


def test_pd_law_by_hand():
    """u_des = psi_dot_max tanh(-kp dq - kd omega)."""
    k = controller_record(CFG)
    x = make_state([0.680, -0.151, 0.630, 0.343], [0.001, -0.002, 0.0005])
    dq = quat.error_vectors(x[0:4], np.array([0, 0, 0, 1.0]))
    expect = 181.3 * np.tanh(-0.2 * dq - 1.5 * x[OMEGA])
    np.testing.assert_allclose(desired_command(x, np.array([0, 0, 0, 1.0]), k), expect, rtol=1e-14)
    assert np.all(desired_command(x, np.array([0, 0, 0, 1.0]), controller_record(CFG, pd=False)) == 0)


def test_kinematics_against_closed_form_rotation():
    """Constant body rate (torque-free about a principal axis): A(t) = R_axis(w t) A(0)."""
    for axis in range(3):
        w = np.zeros(3)
        w[axis] = 0.01
        x0 = make_state(quat.normalize(RNG.normal(size=4)), w, T_K=280.0, E_J=5000.0)
        x = _integrate(x0, np.zeros(3), 100.0, 100)
        e = np.zeros(3)
        e[axis] = 1.0
        expect = rodrigues(e, 0.01 * 100) @ quat.attitude_matrices(x0[0:4])
        np.testing.assert_allclose(quat.attitude_matrices(x[0:4]), expect, atol=1e-9)


def test_torque_free_motion_conserves_momentum_and_energy():
    J = CFG.spacecraft.J
    x = make_state(quat.normalize(RNG.normal(size=4)), [0.01, -0.012, 0.008], T_K=280.0, E_J=5000.0)
    H0_hill = quat.attitude_matrices(x[0:4]).T @ (J * x[OMEGA])
    K0 = 0.5 * np.sum(J * x[OMEGA] ** 2)
    x = _integrate(x, np.zeros(3), 500.0, 5000)
    H_hill = quat.attitude_matrices(x[0:4]).T @ (J * x[OMEGA])
    np.testing.assert_allclose(H_hill, H0_hill, rtol=1e-8, atol=1e-14)
    assert 0.5 * np.sum(J * x[OMEGA] ** 2) == pytest.approx(K0, rel=1e-10)


def test_control_enters_as_D_over_J():
    x = random_states(RNG, 5, CFG)
    u = RNG.normal(size=(5, 3))
    dx = spacecraft.state_derivative(x, u, P) - spacecraft.state_derivative(x, np.zeros(3), P)
    np.testing.assert_allclose(dx[:, OMEGA], 4.1e-5 / np.array([0.022, 0.044, 0.056]) * u)
    np.testing.assert_allclose(dx[:, PSI], u)
    assert np.all(dx[:, [0, 1, 2, 3, TEMP, ENERGY, THETA_S]] == 0)


def test_euler_rows_follow_the_vector_equation():
    """J w_dot + w x J w = D u (SPEC: the paper's printed rows 1-2 are a typo)."""
    J = CFG.spacecraft.J
    w = RNG.normal(size=3) * 0.01
    u = RNG.normal(size=3)
    wdot = spacecraft.omega_dot(make_state([0, 0, 0, 1], w), u, P)
    np.testing.assert_allclose(J * wdot + np.cross(w, J * w), 4.1e-5 * u, atol=1e-18)


def test_thermal_rate_by_hand():
    """-j_B face straight at the sun, Earth at 90 deg: only solar in, radiation out."""
    T = 280.0
    x = make_state([0, 0, 0, 1], T_K=T, E_J=5000.0, theta_S_rad=-math.pi / 2)  # sun along -y_Hill = -j_B
    q_solar = 0.13 * 0.03 * 1367.0
    q_rej = 5.67051e-8 * 0.06 * 0.03 * T**4
    assert spacecraft.state_derivative(x, np.zeros(3), P)[TEMP] == pytest.approx((q_solar - q_rej) / 1800.0, rel=1e-12)
    # face towards Earth (-x_Hill), sun behind: albedo + IR at F_E = 0.8
    q = quat.normalize(np.array([0, 0, -math.sin(math.pi / 4), math.cos(math.pi / 4)]))
    x = make_state(q, T_K=T, E_J=5000.0, theta_S_rad=0.0)
    assert np.allclose(quat.attitude_matrices(q).T @ [0, -1, 0], [-1, 0, 0])
    F = 0.8
    q_in = 0.13 * 0.03 * 1367.0 * 0.27 * F + 5.67051e-8 * 0.06 * 0.03 * F * 255.0**4
    assert spacecraft.state_derivative(x, np.zeros(3), P)[TEMP] == pytest.approx((q_in - q_rej) / 1800.0, rel=1e-12)


def test_power_by_hand():
    q = quat.normalize(np.array([-math.sin(math.pi / 4), 0, 0, math.cos(math.pi / 4)]))
    k_hill = quat.attitude_matrices(q).T @ [0, 0, 1]
    x = make_state(q, T_K=280.0, E_J=5000.0, theta_S_rad=math.atan2(k_hill[1], k_hill[0]))  # panel +k_B on the sun
    assert spacecraft.state_derivative(x, np.zeros(3), P)[ENERGY] == pytest.approx(983.3 * 0.77 * 0.03 - 15.0,
                                                                                   rel=1e-12)  # +7.71 W
    x[THETA_S] += math.pi  # sun behind the panel
    assert spacecraft.state_derivative(x, np.zeros(3), P)[ENERGY] == pytest.approx(-15.0)


def test_sun_turns_at_mean_motion_and_is_unit():
    x = make_state([0, 0, 0, 1], theta_S_rad=1.0)
    assert _integrate(x, np.zeros(3), 100.0, 10)[THETA_S] == pytest.approx(1.0 - 0.1027, abs=1e-12)
    for th in np.linspace(0, 7, 50):
        for beta in (0.0, math.radians(30.0), math.radians(-75.0)):
            r = sun_hill(th, math.cos(beta), math.sin(beta))
            assert math.hypot(*r) == pytest.approx(1.0, abs=1e-15)
            assert math.asin(r[2]) == pytest.approx(beta, abs=1e-12)  # beta above the orbit plane


def test_clohessy_wiltshire_closed_form():
    n = CFG.environment.mean_motion_rad_s
    x0 = make_state([0, 0, 0, 1], cw=[10.0, -5.0, 3.0, 0.01, -0.02, 0.005])
    t = 600.0
    x = _integrate(x0, np.zeros(3), t, 600)
    px, py, pz, vx, vy, vz = x0[13:19]
    s, c = math.sin(n * t), math.cos(n * t)
    ex = (4 - 3 * c) * px + s / n * vx + 2 / n * (1 - c) * vy
    ey = 6 * (s - n * t) * px + py - 2 / n * (1 - c) * vx + (4 * s - 3 * n * t) / n * vy
    ez = pz * c + vz / n * s
    np.testing.assert_allclose(x[13:16], [ex, ey, ez], rtol=1e-9, atol=1e-9)


def test_derivative_equals_the_numpy_oracle():
    """The compiled derivative and the first (numpy) implementation agree to rounding at random states."""
    x = random_states(RNG, 1000, CFG)
    u = RNG.uniform(-200, 200, (1000, 3))
    got = spacecraft.state_derivative(x, u, P)
    want = oracle.state_derivative(x, u, CFG)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-18)


def test_integrator_equals_rk4_of_the_oracle_with_saturation():
    """`integrate` (saturation + compiled RK4 + renormalisation) against a textbook RK4 over the oracle's
    derivative, at random states, beyond the actuator limit."""
    x = random_states(RNG, 50, CFG)
    u = RNG.uniform(-250.0, 250.0, (50, 3))
    us = np.clip(u, -181.3, 181.3)
    h = 1.0 / CFG.substeps
    for k in range(50):
        ref = x[k].copy()
        got_last, got_subs = spacecraft.integrate(x[k], u[k], 1.0, P, CFG.substeps)
        for j in range(CFG.substeps):
            k1 = oracle.state_derivative(ref, us[k], CFG)
            k2 = oracle.state_derivative(ref + 0.5 * h * k1, us[k], CFG)
            k3 = oracle.state_derivative(ref + 0.5 * h * k2, us[k], CFG)
            k4 = oracle.state_derivative(ref + h * k3, us[k], CFG)
            ref = ref + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            ref[0:4] /= np.linalg.norm(ref[0:4])
            np.testing.assert_allclose(got_subs[j], ref, rtol=1e-12, atol=1e-14)
        np.testing.assert_array_equal(got_last, got_subs[-1])


def test_saturated_is_the_actuator_clip_for_any_shape():
    """`saturated` (the Python face of the compiled `saturate`, used by the plant node, simulate's record,
    the bag analysis and the Basilisk plant) against numpy's clip at the configured limit, 181.3 rad/s^2
    written by hand: any shape (..., 3), the limit itself, signed zeros, +-inf clipped, NaN passed."""
    assert CFG.limits.wheel_accel_max_rad_s2 == 181.3
    u = RNG.uniform(-400.0, 400.0, (7, 5, 3))
    u[0, 0] = [181.3, -181.3, np.nextafter(181.3, 1e9)]
    u[0, 1] = [-0.0, np.inf, -np.inf]
    u[0, 2] = [np.nan, 1.0, -np.nan]
    got = spacecraft.saturated(u, P)
    assert got.shape == u.shape and got is not u
    np.testing.assert_array_equal(got, np.clip(u, -181.3, 181.3))
    assert np.signbit(got[0, 1, 0]) and got[0, 0, 2] == 181.3
    np.testing.assert_array_equal(spacecraft.saturated(u[3, 2], P), np.clip(u[3, 2], -181.3, 181.3))


def test_torque_interface_round_trip():
    D = CFG.spacecraft.wheel_inertia_kgm2
    u = RNG.uniform(-50, 50, 1000)
    tau = spacecraft.wheel_accel_to_torque(u, D)
    np.testing.assert_array_equal(tau, D * u)
    np.testing.assert_array_equal(spacecraft.torque_to_wheel_accel(tau, D), tau / D)
