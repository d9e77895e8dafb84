"""Barrier values, HOCBF levels and Lie derivatives against central finite differences.

For relative degree 2:  Psi_1 = d/dt Psi_0 + k1 Psi_0  and  BC(u) = d/dt Psi_1 |_(f+gu) + k2 Psi_1 + bias.
For relative degree 1:  BC(u) = d/dt h |_(f+gu) + k1 h + bias.
The time derivatives are taken numerically along x_dot = f(x) + g(x) u, at >= 1000 random states
and random u, independent of the analytic chain rule in rta_attitude.constraints.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_states
from oracles.constraints import ConstraintSet as OracleSet

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.sensors import interface_energy_error
from rta_attitude.dynamics.state import THETA_S

CFG = config.load()
CS = ConstraintSet(CFG)
P = spacecraft.plant_record(CFG)
EPS = 1e-5
DEGREE = {c.name: 2 if c.kind in ("keep_out", "keep_in", "temperature", "battery") else 1 for c in CS.registry}
"""Relative degree of each barrier as enforced (HOCBF for the cones, the temperature and the battery)."""
EARTH = np.array([-1.0, 0.0, 0.0])


def _sun(theta_S: float) -> np.ndarray:
    return np.array([np.cos(theta_S), np.sin(theta_S), 0.0])


def _xdot(x, u):
    return spacecraft.state_derivative(x, u, P)


def _fd(fun, x, xdot, eps=EPS):
    return (fun(x + eps * xdot) - fun(x - eps * xdot)) / (2 * eps)


def _kinks(x):
    """Distance (rad) of each state to the nearest non-smooth point of any barrier (clamps, poles)."""
    d = []
    for th in CS.angles(x).values():
        d.append(np.minimum.reduce([th, np.pi - th, np.abs(th - np.pi / 2)]))
    return np.min(d, axis=0)


@pytest.fixture(scope="module")
def states():
    rng = np.random.default_rng(20240301)
    x = random_states(rng, 3000, CFG)
    x = x[_kinks(x) > 0.02][:1500]
    u = rng.uniform(-1, 1, (len(x), 3)) * CFG.u_max_rad_s2
    return x, u


def test_enough_states(states):
    assert len(states[0]) >= 1000


def test_psi1_is_derivative_of_psi0(states):
    x, u = states
    tab = CS.evaluate(x)
    xdot = _xdot(x, u)
    dpsi0 = _fd(lambda z: CS.evaluate(z).psi0, x, xdot)
    for i, name in enumerate(CS.names):
        if DEGREE[name] != 2:
            continue
        expect = dpsi0[:, i] + CFG.gains(name).k1 * tab.psi0[:, i]
        scale = 1e-6 + np.abs(expect)
        np.testing.assert_array_less(np.abs(tab.psi1[:, i] - expect), 1e-5 * scale + 1e-8, err_msg=name)


def test_barrier_condition_is_derivative_of_last_level(states):
    x, u = states
    tab = CS.evaluate(x)
    xdot = _xdot(x, u)
    level = _fd(lambda z: CS.evaluate(z).psi1, x, xdot)
    bc = tab.drift + np.einsum("nmk,nk->nm", tab.gain, u)
    for i, name in enumerate(CS.names):
        g = CFG.gains(name)
        k = g.k2 if DEGREE[name] == 2 else g.k1
        expect = level[:, i] + k * tab.psi1[:, i] + g.bias
        err = np.abs(bc[:, i] - expect)
        scale = np.abs(expect) + np.abs(tab.drift[:, i]) + 1e-9
        assert np.quantile(err / scale, 0.99) < 1e-5, name
        assert np.max(err / scale) < 1e-3, name


def test_gain_is_derivative_in_u(states):
    """dBC/du: BC is affine in u, so BC(u + e_j) - BC(u) must equal gain_j."""
    x, _ = states
    tab = CS.evaluate(x)
    xdot0 = _xdot(x, np.zeros((len(x), 3)))
    base = _fd(lambda z: CS.evaluate(z).psi1, x, xdot0)
    for j in range(3):
        du = np.zeros((len(x), 3))
        du[:, j] = 1.0
        xdot = _xdot(x, du)
        diff = _fd(lambda z: CS.evaluate(z).psi1, x, xdot) - base
        scale = np.abs(tab.gain[:, :, j]) + 1e-7 * np.abs(tab.drift) + 1e-12
        assert np.quantile(np.abs(diff - tab.gain[:, :, j]) / scale, 0.99) < 1e-4


def test_h_matches_definitions(states):
    """The paper's constraints by their definitions (SPEC sec. 4): the sensor +i_B >= 40 deg from the sun, the
    antenna +j_B <= 90 deg from the Earth, T <= 10 degC, E >= 1 kJ, |omega_i| <= 1 deg/s, |psi_i| <= 576 rad/s."""
    x, _ = states
    h = CS.safety_values(x)
    col = {n: i for i, n in enumerate(CS.names)}
    A = quat.attitude_matrices(x[:, 0:4])
    sensor = A[:, 0, :]
    antenna = A[:, 1, :]
    sun = np.stack([np.cos(x[:, THETA_S]), np.sin(x[:, THETA_S]), 0 * x[:, THETA_S]], axis=-1)
    th_ez = np.degrees(np.arccos(np.clip(np.sum(sensor * sun, 1), -1, 1)))
    th_gs = np.degrees(np.arccos(np.clip(-antenna[:, 0], -1, 1)))
    ez, comm = CFG.pointing  # the default configuration's two cones: the paper's
    assert (ez.kind, ez.boresight_body, ez.target) == ("keep_out", (1.0, 0.0, 0.0), "sun")
    assert (comm.kind, comm.boresight_body, comm.target) == ("keep_in", (0.0, 1.0, 0.0), "earth")
    np.testing.assert_allclose(np.degrees(h[:, col[ez.name]]), th_ez - 40.0, atol=1e-9)
    np.testing.assert_allclose(np.degrees(h[:, col[comm.name]]), 90.0 - th_gs, atol=1e-9)
    np.testing.assert_allclose(h[:, col["temperature"]], 283.15 - x[:, 10])
    np.testing.assert_allclose(h[:, col["battery"]], x[:, 11] - 1000.0)
    np.testing.assert_allclose(h[:, [col[f"omega_{a}"] for a in "xyz"]], np.radians(1.0) ** 2 - x[:, 4:7] ** 2)
    np.testing.assert_allclose(h[:, [col[f"psi_{a}"] for a in "xyz"]], 576.0**2 - x[:, 7:10] ** 2)


def test_augmented_barriers_never_exceed_h(states):
    x, _ = states
    tab = CS.evaluate(x)
    t, b = CS.names.index("temperature"), CS.names.index("battery")
    assert np.all(tab.psi0[:, t] <= tab.h[:, t] + 1e-12)
    assert np.all(tab.psi0[:, b] <= tab.h[:, b] + 1e-12)


def _state_with_axis_on(axis_body, target_hill, theta_S=0.3, flip=False):
    """A unit quaternion whose body axis points exactly at (or away from) a Hill direction."""
    t = np.asarray(target_hill, float) * (-1 if flip else 1)
    a = np.asarray(axis_body, float)
    # rotation taking the Hill vector t to the body vector a: A(q) t = a
    v = np.cross(t, a)
    c = float(np.dot(t, a))
    if np.linalg.norm(v) < 1e-12:
        perp = np.cross(t, [0.0, 0.0, 1.0] if abs(t[2]) < 0.9 else [1.0, 0.0, 0.0])
        perp /= np.linalg.norm(perp)
        q_rot = np.r_[perp, 0.0] if c < 0 else np.array([0.0, 0.0, 0.0, 1.0])
    else:
        q_rot = np.r_[-v, 1.0 + c]
    q = quat.normalize(q_rot)
    x = np.zeros(19)
    x[0:4] = q
    x[4:7] = [0.004, -0.006, 0.003]
    x[10], x[11], x[12] = 270.0, 5000.0, theta_S
    A = quat.attitude_matrices(q)
    assert np.allclose(A @ t, a, atol=1e-9)
    return x


@pytest.mark.parametrize("axis_body, target, flip", [
    ((1, 0, 0), "sun", True),     # exclusion zone at its safest pole, theta_EZ = pi
    ((1, 0, 0), "sun", False),    # exclusion zone at theta_EZ = 0
    ((0, 1, 0), "earth", False),  # communication at its safest pole, theta_GS = 0
    ((0, 1, 0), "earth", True),   # communication at theta_GS = pi
    ((0, 0, 1), "sun", False),    # battery panel on the sun, theta_SI = 0
    ((0, -1, 0), "sun", False),   # thermal face on the sun
])
def test_poles_are_finite_and_continuous(axis_body, target, flip):
    theta_S = 0.3
    tvec = _sun(theta_S) if target == "sun" else EARTH
    x = _state_with_axis_on(axis_body, tvec, theta_S, flip)
    tab = CS.evaluate(x)
    for arr in (tab.h, tab.psi0, tab.psi1, tab.drift, tab.gain):
        assert np.all(np.isfinite(arr))
    # continuity: values a small rotation away from the pole are close to the pole's
    rot = quat.normalize(np.array([1e-4, 2e-4, -1e-4, 1.0]))
    x2 = x.copy()
    quat.product(rot, x[0:4], x2[0:4])
    tab2 = CS.evaluate(x2)
    np.testing.assert_allclose(tab2.h, tab.h, rtol=1e-3, atol=1e-3)
    np.testing.assert_allclose(tab2.psi0, tab.psi0, rtol=1e-3, atol=1e-3)


def test_safe_poles_do_not_make_the_filter_intervene():
    """At the safest attitudes (sensor anti-sun; antenna on Earth) with u = 0 the rows hold."""
    from rta_attitude.filter.asif import AsifFilter

    f = AsifFilter(CFG)
    x = _state_with_axis_on((1, 0, 0), _sun(0.3), 0.3, flip=True)
    x[4:7] = 0.0
    r = f.filter(x, np.zeros(3))
    assert np.all(np.isfinite(r.u))
    assert r.bc[0] >= 0 and r.h[0] > 2.0
    assert not r.intervening[0]


def test_batch_equals_single():
    rng = np.random.default_rng(3)
    x = random_states(rng, 7, CFG)
    tab = CS.evaluate(x)
    for k in range(len(x)):
        one = CS.evaluate(x[k])
        np.testing.assert_array_equal(one.drift, tab.drift[k])
        np.testing.assert_array_equal(one.gain, tab.gain[k])


def test_sampled_data_margin_only_in_the_robust_preset_and_by_the_filters_model():
    import dataclasses

    first, second = CFG.pointing
    first = dataclasses.replace(first, gains=dataclasses.replace(first.gains, margin=2e-3, margin_gyrostat=7e-3))
    cfg = dataclasses.replace(CFG, pointing=(first, second))
    x = random_states(np.random.default_rng(2), 50, CFG)
    assert second.gains.margin_gyrostat == second.gains.margin  # not in the YAML: the paper model's
    names = cfg.constraint_names
    for model, first_margin in (("paper", 2e-3), ("gyrostat", 7e-3)):
        c = cfg.with_models(filter=model)
        robust = ConstraintSet(c.with_preset("robust")).evaluate(x)
        paper = ConstraintSet(c.with_preset("paper")).evaluate(x)
        np.testing.assert_array_equal(robust.h, paper.h)
        np.testing.assert_allclose(paper.psi0[:, 0] - robust.psi0[:, 0], first_margin, rtol=1e-9)
        np.testing.assert_allclose(paper.psi0[:, 1] - robust.psi0[:, 1], second.gains.margin, rtol=1e-9, atol=1e-15)
        # the battery also keeps the float32 interface's bound in the robust preset
        bat = names.index("battery")
        np.testing.assert_allclose(paper.psi0[:, bat] - robust.psi0[:, bat], interface_energy_error(c), rtol=1e-6)
        others = [i for i in range(2, len(names)) if i != bat]
        np.testing.assert_array_equal(robust.psi0[:, others], paper.psi0[:, others])


def test_compiled_rows_equal_the_numpy_oracle(states):
    """The compiled barriers and the first, numpy implementation (tests/oracles) agree to rounding, in both
    presets, at the same random states."""
    x, _ = states
    for preset in ("robust", "paper"):
        cfg = CFG.with_preset(preset)
        got, want = ConstraintSet(cfg).evaluate(x), OracleSet.from_config(cfg).evaluate(x)
        for f in ("h", "psi0", "psi1", "drift", "gain"):
            np.testing.assert_allclose(getattr(got, f), getattr(want, f), rtol=1e-12, atol=1e-15, err_msg=f)
        # to rounding, not bit for bit: on CPUs with AVX-512 numpy's arccos (SIMD, SVML) differs from libm's
        # acos, which the compiled code calls, by up to 1 ulp in ~10 % of arguments
        np.testing.assert_allclose(ConstraintSet(cfg).safety_values(x), OracleSet.from_config(cfg).safety_values(x),
                                   rtol=1e-13, atol=1e-15)
