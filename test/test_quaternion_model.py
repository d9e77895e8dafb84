"""Quaternion algebra and plant physics against closed forms and hand calculations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import random_states

from rta_attitude import config, model
from rta_attitude import quaternion as quat
from rta_attitude.simulation import integrate, rk4_step
from rta_attitude.state import ENERGY, OMEGA, PSI, TEMP, THETA_S, make_state

CFG = config.load()
RNG = np.random.default_rng(42)


def rodrigues(axis, angle):
    """Rotation matrix of a frame rotation (passive), matching A(q) for q = [sin(a/2) e, cos(a/2)]."""
    e = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    return np.cos(angle) * np.eye(3) + (1 - np.cos(angle)) * np.outer(e, e) - np.sin(angle) * K


def test_attitude_matrix_against_rodrigues():
    for _ in range(200):
        e = RNG.normal(size=3)
        e /= np.linalg.norm(e)
        a = RNG.uniform(-np.pi, np.pi)
        q = np.r_[np.sin(a / 2) * e, np.cos(a / 2)]
        np.testing.assert_allclose(quat.attitude_matrix(q), rodrigues(e, a), atol=1e-12)


def test_product_composes_attitude_matrices():
    q = quat.normalize(RNG.normal(size=(100, 4)))
    p = quat.normalize(RNG.normal(size=(100, 4)))
    lhs = quat.attitude_matrix(quat.product(q, p))
    rhs = np.einsum("nij,njk->nik", quat.attitude_matrix(q), quat.attitude_matrix(p))
    np.testing.assert_allclose(lhs, rhs, atol=1e-12)
    np.testing.assert_allclose(quat.kinematics(q, p[:, :3]), 0.5 * np.einsum("nij,nj->ni", quat.xi(q), p[:, :3]),
                               atol=1e-15)


def test_error_vector_of_the_paper_commands():
    q = quat.normalize(np.array([0.680, -0.151, 0.630, 0.343]))
    np.testing.assert_allclose(quat.error_vector(q, np.array([0, 0, 0, 1.0])), q[:3])
    q1, _q2, q3, q4 = q
    np.testing.assert_allclose(quat.error_vector(q, np.array([0, 1.0, 0, 0])), [-q3, -q4, q1], atol=1e-15)


def test_kinematics_against_closed_form_rotation():
    """Constant body rate (torque-free about a principal axis): A(t) = R_axis(w t) A(0)."""
    for axis in range(3):
        w = np.zeros(3)
        w[axis] = 0.01
        x0 = make_state(quat.normalize(RNG.normal(size=4)), w, T_K=280.0, E_J=5000.0)
        x = x0.copy()
        for _ in range(100):
            x = rk4_step(x, np.zeros(3), 1.0, CFG)
        e = np.zeros(3)
        e[axis] = 1.0
        expect = rodrigues(e, 0.01 * 100) @ quat.attitude_matrix(x0[0:4])
        np.testing.assert_allclose(quat.attitude_matrix(x[0:4]), expect, atol=1e-9)


def test_torque_free_motion_conserves_momentum_and_energy():
    J = CFG.spacecraft.J
    x = make_state(quat.normalize(RNG.normal(size=4)), [0.01, -0.012, 0.008], T_K=280.0, E_J=5000.0)
    H0_body = J * x[OMEGA]
    H0_hill = quat.attitude_matrix(x[0:4]).T @ H0_body
    K0 = 0.5 * np.sum(J * x[OMEGA] ** 2)
    x, _ = integrate(x, np.zeros(3), 500.0, CFG, substeps=5000)
    H_hill = quat.attitude_matrix(x[0:4]).T @ (J * x[OMEGA])
    np.testing.assert_allclose(H_hill, H0_hill, rtol=1e-8, atol=1e-14)
    assert 0.5 * np.sum(J * x[OMEGA] ** 2) == pytest.approx(K0, rel=1e-10)


def test_control_enters_as_D_over_J():
    x = random_states(RNG, 5, CFG)
    u = RNG.normal(size=(5, 3))
    dx = model.state_derivative(x, u, CFG) - model.drift(x, CFG)
    np.testing.assert_allclose(dx[:, OMEGA], 4.1e-5 / np.array([0.022, 0.044, 0.056]) * u)
    np.testing.assert_allclose(dx[:, PSI], u)
    assert np.all(dx[:, [0, 1, 2, 3, TEMP, ENERGY, THETA_S]] == 0)
    g = model.control_matrix(x, CFG)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", g, u), dx, atol=1e-15)


def test_euler_rows_follow_the_vector_equation():
    """J w_dot + w x J w = D u (SPEC: the paper's printed rows 1-2 are a typo)."""
    J = CFG.spacecraft.J
    w = RNG.normal(size=3) * 0.01
    u = RNG.normal(size=3)
    wdot = model.omega_dot(make_state([0, 0, 0, 1], w), u, CFG)
    np.testing.assert_allclose(J * wdot + np.cross(w, J * w), 4.1e-5 * u, atol=1e-18)


def test_thermal_rate_by_hand():
    """-j_B face straight at the sun, Earth at 90 deg: only solar in, radiation out."""
    # q = identity: -j_B = -y_Hill; sun along -y_Hill needs theta_S = -90 deg
    T = 280.0
    x = make_state([0, 0, 0, 1], T_K=T, E_J=5000.0, theta_S_rad=-math.pi / 2)
    q_solar = 0.13 * 0.03 * 1367.0
    q_rej = 5.67051e-8 * 0.06 * 0.03 * T**4
    assert model.temperature_rate(x, CFG) == pytest.approx((q_solar - q_rej) / (2.0 * 900.0), rel=1e-12)
    # face towards Earth (-x_Hill), sun behind: albedo + IR at F_E = 0.8
    q = quat.normalize(np.array([0, 0, -math.sin(math.pi / 4), math.cos(math.pi / 4)]))
    x = make_state(q, T_K=T, E_J=5000.0, theta_S_rad=0.0)
    A = quat.attitude_matrix(q)
    assert np.allclose(A.T @ [0, -1, 0], [-1, 0, 0])
    F = 0.8
    q_in = 0.13 * 0.03 * 1367.0 * 0.27 * F + 5.67051e-8 * 0.06 * 0.03 * F * 255.0**4
    assert model.temperature_rate(x, CFG) == pytest.approx((q_in - q_rej) / 1800.0, rel=1e-12)


def test_power_by_hand():
    # panel +k_B on the sun: q rotates z_Hill... use theta_S and q so that k_B = r_S
    q = quat.normalize(np.array([-math.sin(math.pi / 4), 0, 0, math.cos(math.pi / 4)]))
    A = quat.attitude_matrix(q)
    k_hill = A.T @ [0, 0, 1]
    theta_S = math.atan2(k_hill[1], k_hill[0])
    x = make_state(q, T_K=280.0, E_J=5000.0, theta_S_rad=theta_S)
    assert model.drift(x, CFG)[ENERGY] == pytest.approx(983.3 * 0.77 * 0.03 - 15.0, rel=1e-12)  # +7.71 W
    x[THETA_S] += math.pi  # sun behind the panel
    assert model.drift(x, CFG)[ENERGY] == pytest.approx(-15.0)


def test_sun_turns_at_mean_motion_and_is_unit():
    x = make_state([0, 0, 0, 1], theta_S_rad=1.0)
    x2, _ = integrate(x, np.zeros(3), 100.0, CFG)
    assert x2[THETA_S] == pytest.approx(1.0 - 0.1027, abs=1e-12)
    np.testing.assert_allclose(np.linalg.norm(model.sun_direction(np.linspace(0, 7, 50)), axis=-1), 1.0)


def test_clohessy_wiltshire_closed_form():
    n = CFG.environment.mean_motion_rad_s
    x0 = make_state([0, 0, 0, 1], cw=[10.0, -5.0, 3.0, 0.01, -0.02, 0.005])
    t = 600.0
    x, _ = integrate(x0, np.zeros(3), t, CFG, substeps=600)
    px, py, pz, vx, vy, vz = x0[13:19]
    s, c = math.sin(n * t), math.cos(n * t)
    ex = (4 - 3 * c) * px + s / n * vx + 2 / n * (1 - c) * vy
    ey = 6 * (s - n * t) * px + py - 2 / n * (1 - c) * vx + (4 * s - 3 * n * t) / n * vy
    ez = pz * c + vz / n * s
    np.testing.assert_allclose(x[13:16], [ex, ey, ez], rtol=1e-9, atol=1e-9)


def test_batch_equals_single():
    x = random_states(RNG, 6, CFG)
    u = RNG.normal(size=(6, 3))
    batch = model.state_derivative(x, u, CFG)
    for k in range(6):
        np.testing.assert_array_equal(model.state_derivative(x[k], u[k], CFG), batch[k])


def test_single_state_drift_is_bit_identical_to_the_batch():
    x = random_states(RNG, 500, CFG)
    batch = model.drift(x, CFG)
    for k in range(len(x)):
        np.testing.assert_array_equal(model.drift(x[k], CFG), batch[k])


def test_compiled_integrator_equals_the_numpy_rk4_bit_for_bit():
    """`integrate` runs the compiled `plant_kernel`; it must give exactly the numbers of the numpy
    `rk4_step` (model.state_derivative) it ports, one state at a time and batched, with saturation,
    over random states including past-limit rates and CW motion."""
    from helpers import random_states

    from rta_attitude.simulation import saturate

    rng = np.random.default_rng(21)
    x = random_states(rng, 200, CFG)
    u = rng.uniform(-250.0, 250.0, (200, 3))  # beyond the actuator limit: saturated
    x_next, subs = integrate(x, u, 1.0, CFG)
    ref, ref_subs = x, []
    us = saturate(u, CFG)
    for _ in range(CFG.substeps):
        ref = rk4_step(ref, us, 1.0 / CFG.substeps, CFG)
        ref_subs.append(ref)
    np.testing.assert_array_equal(subs, np.stack(ref_subs))
    np.testing.assert_array_equal(x_next, ref)
    for k in (0, 57, 199):  # one state: the numpy path through model._drift_one
        one, one_subs = integrate(x[k], u[k], 1.0, CFG)
        r = x[k]
        for j in range(CFG.substeps):
            r = rk4_step(r, us[k], 1.0 / CFG.substeps, CFG)
            np.testing.assert_array_equal(one_subs[j], r)
        np.testing.assert_array_equal(one, r)
