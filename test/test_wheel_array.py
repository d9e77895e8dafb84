"""Arrays of more than three wheels (`spacecraft.wheel_spin_axes_body` with N >= 4 named wheels) in the plant model,
against independent computations.

- the array as data: a user's file replaces the paper's three wheels with its own (names in the order written), a
  `-p` key adds one; the check at load; 3-axis control while the working wheels span the body's axes;
- the state layout: wheels past the third after z_dot, every three-wheel entry where it was;
- superposition: two wheels on one axis sharing its command move the body as the one wheel of the paper's array
  with the sum of their speeds (the momentum sum and the torque map of N wheels against the three-wheel kernels);
- the inertial momentum A^T (J omega - s D A psi) of a 12U with a 4-wheel pyramid and products of inertia conserved
  to RK4's order;
- the torque interface: a body torque reaches the wheels as the smallest (2-norm) split, numpy's least squares;
- Basilisk's rwFactory with the pyramid, the tensor and a failed wheel agrees over 2,000 s;
- what takes three wheels so far (the filter, the nodes and the launcher, the Monte Carlo, the viability oracle,
  check-config) says so in one line and runs nothing.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import against_basilisk, max_angle

from rta_attitude import config
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.state import OMEGA, PSI, STATE_SIZE, Q, make_state, state_size, wheel_columns
from rta_attitude.errors import ConfigError
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.viability.params import from_config

HAVE_BSK = importlib.util.find_spec("Basilisk") is not None
S = 1.0 / math.sqrt(3.0)
PYRAMID = {"rw1": [S, S, S], "rw2": [-S, S, S], "rw3": [-S, -S, S], "rw4": [S, -S, S]}
"""Four wheels 35.26 deg above the body's x-y plane, 90 deg apart about +z (A A^T = 4/3 I)."""
TWELVE_U = """/**:
  ros__parameters:
    spacecraft:
      inertia_kgm2: [0.2, 0.25, 0.15]
      products_of_inertia_kgm2: [0.004, -0.003, 0.002]
      wheel_inertia_kgm2: 1.0e-4
      wheel_spin_axes_body:
"""


@pytest.fixture(scope="module")
def pyramid(tmp_path_factory: pytest.TempPathFactory) -> config.Config:
    """A 12U (J = [0.2, 0.25, 0.15] kg m^2 with products of inertia, D = 1e-4) with the 4-wheel pyramid, from a
    user's file that holds only what differs from the defaults."""
    path = tmp_path_factory.mktemp("pyramid") / "pyramid.yaml"
    path.write_text(TWELVE_U + "".join(f"        {k}: {v}\n" for k, v in PYRAMID.items()))
    return config.load(path)


def _with(cfg: config.Config, **spacecraft_fields: object) -> config.Config:
    return dataclasses.replace(cfg, spacecraft=dataclasses.replace(cfg.spacecraft, **spacecraft_fields))


def test_a_users_array_replaces_the_papers_and_a_key_adds_a_wheel(pyramid: config.Config) -> None:
    """The user's four wheels, in the order written, are the array (not added to the paper's three); a `-p` key on
    the defaults adds a fourth wheel to the paper's three; the paper's array stays the default."""
    sc = pyramid.spacecraft
    assert sc.wheel_names == ("rw1", "rw2", "rw3", "rw4") and sc.n_wheels == 4
    np.testing.assert_allclose(sc.wheel_axes, np.array(list(PYRAMID.values())).T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(sc.wheel_axes @ sc.wheel_axes.T, 4.0 / 3.0 * np.eye(3), atol=1e-14)
    added = config.load(overrides={"spacecraft.wheel_spin_axes_body.wheel_s": [S, S, S]})
    assert added.spacecraft.wheel_names == ("wheel_x", "wheel_y", "wheel_z", "wheel_s")
    assert config.load().spacecraft.wheel_names == ("wheel_x", "wheel_y", "wheel_z")


def test_the_array_is_checked_at_load(pyramid: config.Config) -> None:
    """One ConfigError line each: fewer than three wheels, a name that is not a ROS name, a failed wheel the array
    does not have. Three-axis control holds while the working wheels span the body's axes: any three of the
    pyramid do, two do not."""
    with pytest.raises(ConfigError, match="at least 3 wheels, got 2"):
        _with(pyramid, wheel_axes_body=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)), wheel_names=("a", "b"))
    with pytest.raises(ConfigError, match="a wheel's name must be"):
        _with(pyramid, wheel_names=("rw1", "rw 2", "rw3", "rw4"))
    with pytest.raises(ConfigError, match="unknown wheel 'wheel_x'; the wheels are rw1, rw2, rw3, rw4"):
        _with(pyramid, failed_wheels=("wheel_x",))
    one, two = _with(pyramid, failed_wheels=("rw2",)), _with(pyramid, failed_wheels=("rw2", "rw4"))
    assert one.spacecraft.control_lost == ""
    assert two.spacecraft.control_lost == "lost 3-axis control: rw2, rw4 failed, 2 wheels left"
    assert _with(config.load(), failed_wheels=("wheel_y",)).spacecraft.control_lost.startswith("lost 3-axis")


def test_wheels_past_the_third_follow_the_papers_layout() -> None:
    """Every entry of the three-wheel state keeps its index; wheel i > 3 is entry 16 + i."""
    assert state_size(3) == STATE_SIZE == 19 and state_size(4) == 20
    assert wheel_columns(3) == tuple(range(PSI.start, PSI.stop))
    assert wheel_columns(5) == (7, 8, 9, 19, 20)


def test_two_wheels_on_one_axis_move_the_body_as_one() -> None:
    """The paper's 6U with a fourth wheel on +z beside wheel_z, each of the two given half of wheel_z's command and
    half its speed: the body, the attitude and every other entry move as the paper's three-wheel plant, and the two
    speeds add up to wheel_z's. The four-wheel kernels (a general momentum sum and torque map) against the
    three-wheel per-axis ones, with the gyrostat's wheel term and the gravity gradient in the rotating Hill frame."""
    base = config.load()
    base = dataclasses.replace(base, environment=dataclasses.replace(base.environment, gravity_gradient=True,
                                                                     rotating_hill=True))
    four = _with(base, wheel_axes_body=(*base.spacecraft.wheel_axes_body, (0.0, 0.0, 1.0)),
                 wheel_names=("wheel_x", "wheel_y", "wheel_z", "wheel_z2"))
    rng = np.random.default_rng(4)
    w0 = math.radians(0.5) * rng.uniform(-1, 1, 3)
    x3 = make_state(quat.normalize(rng.normal(size=4)), w0, [200.0, -150.0, 90.0])
    x4 = np.concatenate([x3, [0.0]])
    x4[PSI.start + 2] = x4[19] = 45.0
    p3, p4 = spacecraft.plant_record(base), spacecraft.plant_record(four)
    assert not p4[0]["diagonal"]  # the general kernels
    for u in rng.uniform(-30.0, 30.0, (300, 3)):
        x3 = spacecraft.integrate(x3, u, 1.0, p3, 10)[0]
        x4 = spacecraft.integrate(x4, np.array([u[0], u[1], 0.5 * u[2], 0.5 * u[2]]), 1.0, p4, 10)[0]
    assert abs(x3[PSI.start + 2] - 90.0) > 20.0  # the z wheels exchanged momentum with the body
    merged = x4[:19].copy()
    merged[PSI.start + 2] = x4[PSI.start + 2] + x4[19]
    np.testing.assert_allclose(merged, x3, rtol=1e-9, atol=1e-12)
    assert x4[PSI.start + 2] == pytest.approx(x4[19], rel=1e-12)


def test_any_array_moves_the_body_as_three_orthogonal_wheels_holding_its_momentum(pyramid: config.Config) -> None:
    """The reduction a filter over N wheels can stand on: the body sees an array only through the wheels' momentum
    along the body axes, psi_b = A psi, and its rate, u_b = A u (one wheel inertia D). The 12U with the pyramid and
    products of inertia, driven by 300 random held commands u (4), and the same 12U with three wheels on the body
    axes driven by A u from psi_b = A psi: the attitude, rates, temperature, battery and orbit agree, and A psi
    stays the three wheels' speeds (the gyrostat's wheel term, the gravity gradient, the rotating Hill frame)."""
    cfg = dataclasses.replace(pyramid, environment=dataclasses.replace(pyramid.environment, gravity_gradient=True,
                                                                       rotating_hill=True))
    orth = _with(cfg, wheel_axes_body=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
                 wheel_names=("wheel_x", "wheel_y", "wheel_z"))
    A = cfg.spacecraft.wheel_axes
    wheels = list(wheel_columns(4))
    rng = np.random.default_rng(43)
    x4 = np.concatenate([make_state(quat.normalize(rng.normal(size=4)), math.radians(0.5) * rng.uniform(-1, 1, 3),
                                    [0.0, 0.0, 0.0]), [0.0]])
    x4[wheels] = rng.uniform(-300.0, 300.0, 4)
    x3 = x4[:STATE_SIZE].copy()
    x3[PSI] = A @ x4[wheels]
    p4, p3 = spacecraft.plant_record(cfg), spacecraft.plant_record(orth)
    for u in rng.uniform(-20.0, 20.0, (300, 4)):
        x4 = spacecraft.integrate(x4, u, 1.0, p4, 10)[0]
        x3 = spacecraft.integrate(x3, A @ u, 1.0, p3, 10)[0]
    assert max_angle(x4[Q], x3[Q]) < 1e-9 and np.max(np.abs(x4[OMEGA])) > 1e-3  # the body moved
    body = [i for i in range(STATE_SIZE) if i not in range(PSI.start, PSI.stop)]
    np.testing.assert_allclose(x4[body], x3[body], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(A @ x4[wheels], x3[PSI], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("torque_sign", [1.0, -1.0])
def test_inertial_momentum_is_conserved_with_a_pyramid(pyramid: config.Config, torque_sign: float) -> None:
    """No external torque: A^T (J omega - s D A psi) of the 12U with the pyramid and products of inertia stays
    constant to RK4's accuracy under 2,000 random held commands (the change falls > 1,000x with 16x the substeps);
    a wheel past the third left out of the momentum sum or the torque map breaks it."""
    cfg = _with(pyramid, torque_sign=torque_sign)
    p = spacecraft.plant_record(cfg)
    J, sD, A = cfg.spacecraft.inertia_matrix, torque_sign * cfg.spacecraft.wheel_inertia_kgm2, cfg.spacecraft.wheel_axes
    wheels = list(wheel_columns(4))

    def drift(substeps: int) -> float:
        rng = np.random.default_rng(2000)
        x = np.concatenate([make_state(quat.normalize(rng.normal(size=4)), [0.02, -0.025, 0.015],
                                       [300.0, -200.0, 100.0]), [-250.0]])

        def inertial(z: np.ndarray) -> np.ndarray:
            return quat.attitude_matrices(z[Q]).T @ (J @ z[OMEGA] - sD * A @ z[wheels])

        H0 = inertial(x)
        start = x[wheels].copy()
        for u in rng.uniform(-20.0, 20.0, (2000, 4)):
            x = spacecraft.integrate(x, u - 0.05 * x[wheels], 1.0, p, substeps)[0]
        assert np.max(np.abs(x[wheels] - start)) > 100.0  # the wheels exchanged momentum
        return float(np.linalg.norm(inertial(x) - H0) / np.linalg.norm(H0))

    coarse, fine = drift(10), drift(160)
    assert coarse < 1e-6
    assert fine < coarse / 1000


def test_a_body_torque_reaches_the_wheels_as_the_smallest_split(pyramid: config.Config) -> None:
    """torque_to_wheels gives the least-norm u with D A u = tau (numpy's lstsq, an SVD), and wheels_to_torque
    takes it back to tau; with three wheels both are the plain inverse."""
    p = spacecraft.plant_record(pyramid)
    D, A = pyramid.spacecraft.wheel_inertia_kgm2, pyramid.spacecraft.wheel_axes
    tau = np.random.default_rng(7).normal(scale=1e-3, size=(50, 3))
    u = spacecraft.torque_to_wheels(tau, p)
    assert u.shape == (50, 4)
    expected = np.stack([np.linalg.lstsq(D * A, t, rcond=None)[0] for t in tau])
    np.testing.assert_allclose(u, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(spacecraft.wheels_to_torque(u, p), tau, rtol=1e-12, atol=1e-18)


@pytest.mark.skipif(not HAVE_BSK, reason="Basilisk is not installed (pip install rta_attitude[basilisk])")
@pytest.mark.parametrize("failed", ["", "rw2"])
def test_basilisk_with_the_pyramid_agrees_over_2000_s(pyramid: config.Config, failed: str) -> None:
    """Basilisk's hub (J + D A A^T) with the four wheels on the pyramid's axes through rwFactory, products of
    inertia, rotating Hill frame, random commands held 1 s for 2,000 s (a failed wheel's motor torque 0): both
    integrate the same ODE with RK4 at 0.1 s, so the rates and the four wheel speeds agree to accumulated
    round-off and the attitude well inside the compiled plant's own h vs h/2 difference."""
    cfg = _with(pyramid, failed_wheels=(failed,) if failed else ())
    cfg = dataclasses.replace(cfg, environment=dataclasses.replace(cfg.environment, rotating_hill=True))
    wheels = list(wheel_columns(4))
    x0 = np.concatenate([cfg.scenario("paper-example").x0, [0.0]])
    x0[OMEGA] = math.radians(0.5) * np.array([0.6, -0.48, 0.64])
    x0[wheels] = [120.0, -80.0, 60.0, -40.0]
    rng = np.random.default_rng(12)
    us = rng.uniform(-1.0, 1.0, (2000, 4)) * 0.2 * cfg.limits.wheel_accel_max_rad_s2
    us -= 0.002 * np.cumsum(us, axis=0)  # a pull-back that keeps the wheels within a few hundred rad/s

    ours, fine, bsk = against_basilisk(cfg, x0, us)

    assert np.abs(ours[:, wheels] - x0[wheels]).max() > 50.0  # the wheels exchanged momentum
    att, truncation = max_angle(bsk[:, Q], ours[:, Q]), max_angle(fine[:, Q], ours[:, Q])
    assert att < 0.1 * truncation, (att, truncation)
    assert np.abs(bsk[:, OMEGA] - ours[:, OMEGA]).max() < 1e-10
    assert np.abs(bsk[:, wheels] - ours[:, wheels]).max() < 1e-10
    if failed:  # the failed wheel coasts in both
        assert np.all(ours[:, wheels[1]] == x0[wheels[1]])
        np.testing.assert_allclose(bsk[:, wheels[1]], x0[wheels[1]], rtol=0, atol=1e-10)


def test_what_takes_three_wheels_says_so(pyramid: config.Config, tmp_path: Path) -> None:
    """The three-wheel filter and the viability oracle raise one ConfigError line naming the array; the CLI's
    commands (the launcher too) and a node exit 1 with one line, before writing anything: the Monte Carlo and the
    launcher that they take three wheels, check-config (the filter over the array) what that filter does not take
    (here the default's gatekeeper). simulate runs the paper's example, whose scenario turns the gatekeeper off."""
    line = "takes three reaction wheels; spacecraft.wheel_spin_axes_body gives 4 (rw1, rw2, rw3, rw4)"
    array_line = "the filter over 4 wheels (rw1, rw2, rw3, rw4) does not take the gatekeeper"
    with pytest.raises(ConfigError, match=r"the filter takes three reaction wheels; .* gives 4 \(rw1"):
        AsifFilter(pyramid)
    with pytest.raises(ConfigError, match="the viability oracle takes three"):
        from_config(pyramid)
    path = tmp_path / "pyramid.yaml"
    path.write_text(TWELVE_U + "".join(f"        {k}: {v}\n" for k, v in PYRAMID.items()))
    out = tmp_path / "out"
    for command in (["check-config"], ["montecarlo", "--runs", "2", "--no-plot", "--out", str(out)],
                    ["launch", "--bag", str(tmp_path / "run.mcap"), "--out", str(out)]):
        done = subprocess.run([sys.executable, "-m", "rta_attitude.cli", *command, "--config", str(path)],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 1, (command, done.stdout, done.stderr)
        expected = array_line if command[0] == "check-config" else line
        assert expected in done.stderr and len(done.stderr.strip().splitlines()) == 1, (command, done.stderr)
    assert not out.exists() and not (tmp_path / "run.mcap").exists()
    sim = tmp_path / "sim"
    done = subprocess.run([sys.executable, "-m", "rta_attitude.cli", "simulate", "--scenario", "paper-example",
                           "--no-plot", "--out", str(sim), "--config", str(path)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0 and "psi_rw4" in done.stdout, (done.stdout, done.stderr)
    node = subprocess.run([sys.executable, "-m", "rta_attitude.ros.plant_node", "--ros-args", "-p",
                           f"config_file:={path}", "-p", "record:=false"], capture_output=True, text=True, timeout=600)
    errors = [ln for ln in (node.stdout + node.stderr).splitlines() if "ERROR" in ln]
    assert node.returncode == 1 and len(errors) == 1 and "the plant node takes three reaction wheels" in errors[0]


def test_joint_states_carry_the_configured_names() -> None:
    """A wheel's JointState name is its configured name: the plant's serialised messages read back to the same
    fields with those names, and a message with other names is refused in one line."""
    pytest.importorskip("rclpy")
    from rta_attitude.dynamics.sensors import F_Q, F_WHEEL, FIELD_SIZE
    from rta_attitude.errors import MessageError
    from rta_attitude.ros import convert

    names = ("rw_a", "rw_b", "rw_c")
    f = np.linspace(0.1, 1.0, FIELD_SIZE)
    f[F_Q:F_Q + 4] = quat.normalize(np.array([0.1, 0.2, 0.3, 0.9]))
    raw = convert.state_messages_cdr(f, 5_000_000_000, 8.0, 0.5, np.array([1e-4, -2e-4, 3e-4]), names)
    objects = convert.state_messages(f, 5_000_000_000, 8.0, 0.5, np.array([1e-4, -2e-4, 3e-4]), names)
    assert list(objects["joint_states"].name) == list(names)
    back = convert.state_fields(raw, names)
    np.testing.assert_array_equal(back[F_WHEEL:F_WHEEL + 3], f[F_WHEEL:F_WHEEL + 3])
    np.testing.assert_array_equal(convert.state_fields(objects, names)[F_WHEEL:F_WHEEL + 3], f[F_WHEEL:F_WHEEL + 3])
    with pytest.raises(MessageError, match=r"wheels must be joints \('wheel_x', 'wheel_y', 'wheel_z'\)"):
        convert.state_fields(objects)
