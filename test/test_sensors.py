"""Sensor and actuator errors (`dynamics.sensors`) and the filter's measurement-robust margins,
checked against their parameters and against independent computations (quadrature, finite
differences, a closed-form attitude matrix)."""

from __future__ import annotations

import dataclasses as dc
import math
import struct

import numpy as np
import pytest
from scipy import integrate, stats

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.base import angle_rate_error, constraint_record, measurement_errors
from rta_attitude.dynamics.plant import make_plant
from rta_attitude.dynamics.sensors import (
    FIELD_SIZE,
    Instruments,
    interface_energy_error,
    message_fields,
    normals,
    sensors_record,
    state_from_fields,
)
from rta_attitude.dynamics.state import make_state
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.filter.drive import drive_box
from rta_attitude.filter.records import filter_record, new_workspace
from rta_attitude.montecarlo.runner import run_runs, run_runs_stepped
from rta_attitude.simulation.closed_loop import run_stepped, simulate


@pytest.fixture(scope="module")
def cfg() -> config.Config:
    return config.load()


def _sensors(cfg: config.Config, **kw: float) -> config.Config:
    """cfg with the sensors on and only the named errors (others 0)."""
    zero = dict.fromkeys(("attitude_noise_rad", "gyro_noise_rad_s", "gyro_bias_rad_s", "gyro_bias_walk_rad_s_sqrt_s",
                          "wheel_speed_noise_rad_s", "temperature_noise_K", "energy_noise_J", "torque_noise_rad_s2",
                          "actuator_lag_s"), 0.0)
    return dc.replace(cfg, sensors=dc.replace(cfg.sensors, enabled=True, **{**zero, **kw}))


def _attitude_matrix(q: np.ndarray) -> np.ndarray:
    """A(q), Hill -> body, scalar last (Markley's closed form, written here)."""
    v, s = q[:3], q[3]
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return (s * s - v @ v) * np.eye(3) + 2 * np.outer(v, v) - 2 * s * vx


def test_draws_are_standard_normal_and_independent() -> None:
    a = normals(7, 0, 200_000, channel=0)
    b = normals(7, 0, 200_000, channel=1)
    c = normals(7, 1, 200_000, channel=0)
    assert stats.kstest(a, "norm").pvalue > 1e-4
    assert abs(a.mean()) < 5 / math.sqrt(a.size) and abs(a.std() - 1) < 0.01
    for other in (b, c, a[1:]):  # another channel, another stream, the next sample
        assert abs(np.corrcoef(a[: other.size], other)[0, 1]) < 0.015
    assert np.array_equal(a, normals(7, 0, 200_000, channel=0))  # a pure function of its key
    assert not np.array_equal(a, normals(8, 0, 200_000, channel=0))


def test_sensors_off_give_the_exact_state_and_command(cfg: config.Config) -> None:
    ins = Instruments(cfg)
    x = make_state([0.1, 0.2, 0.3, 0.9], [0.01, -0.02, 0.003], [100.0, -50.0, 3.0], 280.0, 5000.0, 1.0)
    u = np.array([1.5, -2.0, 0.25])
    for k in range(3):
        assert np.array_equal(ins.measure(x, k), x)
        assert np.array_equal(ins.actuate(u, k), u)


def test_measurement_noise_statistics_match_their_parameters(cfg: config.Config) -> None:
    sig = {"attitude_noise_rad": 2e-4, "gyro_noise_rad_s": 3e-5, "wheel_speed_noise_rad_s": 0.2,
           "temperature_noise_K": 0.3, "energy_noise_J": 7.0}
    c = _sensors(cfg, **sig)
    ins = Instruments(c)
    x = make_state([0.3, -0.1, 0.2, 0.9], [0.005, -0.002, 0.001], [200.0, -100.0, 50.0], 270.0, 4000.0, 2.0)
    n = 20_000
    Y = np.array([ins.measure(x, k) for k in range(n)])
    A = _attitude_matrix(x[:4])
    # the error rotation dA = A(y) A(x)^T, its small-angle vector from the skew part
    err = np.empty((n, 3))
    for k in range(n):
        dA = _attitude_matrix(Y[k, :4]) @ A.T
        err[k] = 0.5 * np.array([dA[1, 2] - dA[2, 1], dA[2, 0] - dA[0, 2], dA[0, 1] - dA[1, 0]])
    tol = 0.03  # relative, 20,000 draws: the std of a std estimate is 0.5 %
    assert np.allclose(err.std(axis=0), sig["attitude_noise_rad"], rtol=tol)
    assert np.allclose(np.linalg.norm(Y[:, :4], axis=1), 1.0, atol=1e-15)
    assert np.allclose((Y[:, 4:7] - x[4:7]).std(axis=0), sig["gyro_noise_rad_s"], rtol=tol)
    assert np.allclose((Y[:, 7:10] - x[7:10]).std(axis=0), sig["wheel_speed_noise_rad_s"], rtol=tol)
    assert (Y[:, 10] - x[10]).std() == pytest.approx(sig["temperature_noise_K"], rel=tol)
    assert (Y[:, 11] - x[11]).std() == pytest.approx(sig["energy_noise_J"], rel=tol)
    assert np.array_equal(Y[:, 12:], np.broadcast_to(x[12:], (n, 7)))  # ephemeris: exact


def test_gyro_bias_is_drawn_once_and_walks_with_its_variance(cfg: config.Config) -> None:
    b0, walk, steps, runs = 1e-4, 2e-6, 400, 2000
    c = _sensors(cfg, gyro_bias_rad_s=b0, gyro_bias_walk_rad_s_sqrt_s=walk)
    x = make_state([0, 0, 0, 1])
    first, last = np.empty((runs, 3)), np.empty((runs, 3))
    for r in range(runs):
        ins = Instruments(c, stream=r)
        first[r] = ins.measure(x, 0)[4:7]
        for k in range(1, steps):
            ins.measure(x, k)
        last[r] = ins.measure(x, steps)[4:7]
    assert np.allclose(first.std(axis=0), b0, rtol=0.06)
    # b_steps - b_0: sum of `steps` increments of walk sqrt(dt) each
    expected = walk * math.sqrt(steps * c.filter.sample_time_s)
    assert np.allclose((last - first).std(axis=0), expected, rtol=0.06)


def test_actuator_lag_delivers_the_exact_lag_response(cfg: config.Config) -> None:
    tau, dt = 0.3, cfg.filter.sample_time_s
    c = _sensors(cfg, actuator_lag_s=tau)
    ins = Instruments(c)
    commands = [np.array([2.0, -1.0, 0.5]), np.array([-3.0, 0.0, 1.0]), np.array([0.0, 4.0, -2.0])]
    v = np.zeros(3)  # the lag's output, integrated here by quadrature of its closed form
    for k, u in enumerate(commands):
        held = ins.actuate(u, k)
        for a in range(3):
            cmd, start = float(u[a]), float(v[a])
            mean, _ = integrate.quad(lambda s, c=cmd, v0=start: c + (v0 - c) * math.exp(-s / tau), 0.0, dt,
                                     epsabs=1e-13)
            assert held[a] == pytest.approx(mean / dt, abs=1e-12)  # the momentum of the hold
        v = u + (v - u) * math.exp(-dt / tau)


@pytest.mark.parametrize("tau", [0.02, 0.3])
def test_the_filter_sends_the_command_whose_lagged_hold_is_its_answer(cfg: config.Config, tau: float) -> None:
    """With the drive's lag compensated (the default), what the wheels hold over each sample -- the plant's
    `actuate`, an exact lag, tested above against quadrature -- is the filter's answer u_held, and every command
    stays inside U; with `bound` the command is the answer and the lag moves the hold away from it. The paper
    example on the gyrostat, PD on, torque noise off (so the hold is the lag's alone)."""
    scen = dc.replace(cfg.scenario("paper_example"), model="gyrostat")
    base = _sensors(cfg.for_scenario(scen), actuator_lag_s=tau, attitude_noise_rad=1e-5)
    U = base.u_max_rad_s2
    lag = (tau / base.filter.sample_time_s) * (1 - math.exp(-base.filter.sample_time_s / tau))
    steps = 400
    held = {}
    for mode in ("compensate", "bound"):
        c = dc.replace(base, filter=dc.replace(base.filter, actuator_lag=mode))
        run = run_stepped(c, scen, steps, make_plant(c, scen.x0), AsifFilter(c))
        u, answer = run.results["u"], run.results["u_held"]
        assert np.all(np.abs(u) <= U * (1 + 1e-12))
        held[mode] = np.abs(run.u - answer).max() / U.max()
        if mode == "compensate":
            assert np.abs(u - answer).max() > 0.1 * lag * U.max()  # the commands do differ from the answers
            # the answer's box is what this drive state reaches: all of U on the side the drive already
            # pushes; a rollout's later samples keep (1 - 2c) U, what every drive state reaches
            f = filter_record(c)
            for v in (U, -U):
                wsa = new_workspace()
                wsa[0]["gate"]["drive"] = v
                drive_box(f[0], wsa)
                edge = lag * v - (1 - lag) * U if v[0] > 0 else lag * v + (1 - lag) * U
                lo, hi = (edge, U) if v[0] > 0 else (-U, edge)
                assert np.allclose(wsa[0]["lo0"], lo, rtol=1e-12) and np.allclose(wsa[0]["hi0"], hi, rtol=1e-12)
                assert np.allclose(wsa[1]["hi0"], (1 - 2 * lag) * U, rtol=1e-12)
                assert np.allclose(wsa[1]["lo0"], -(1 - 2 * lag) * U, rtol=1e-12)
        else:
            assert np.array_equal(u, answer)
    assert held["compensate"] < 1e-12
    assert held["bound"] > 0.1 * lag  # the lag's departure the margin bounds (a PD slew reverses the command)
    assert measurement_errors(base)["err_u_rad_s2"] == pytest.approx(np.zeros(3))  # torque noise off
    bound = dc.replace(base, filter=dc.replace(base.filter, actuator_lag="bound"))
    assert measurement_errors(bound)["err_u_rad_s2"] == pytest.approx(2 * lag * U)


def test_robust_margins_are_zero_without_sensor_errors(cfg: config.Config) -> None:
    """Without sensor errors the only margin is the battery's float32 interface (robust preset only)."""
    rec = constraint_record(cfg)[0]
    names = [n for n in rec.dtype.names if n.startswith("err_")]
    assert names and all(np.all(rec[n] == 0) for n in names if n != "err_E_J")
    assert rec["err_E_J"] == interface_energy_error(cfg) and 0 < rec["err_E_J"] < 1e-3
    assert np.all(constraint_record(cfg.with_preset("paper"))[0]["err_E_J"] == 0)
    on = constraint_record(cfg.with_noise())[0]
    assert all(np.all(on[n] > 0) for n in names)
    assert np.all(constraint_record(cfg.with_noise().with_preset("paper"))[0]["err_att_rad"] == 0)


def _boresight_angle(q: np.ndarray, sun: np.ndarray) -> float:
    return math.acos(float(np.clip(_attitude_matrix(q)[0] @ sun, -1, 1)))


def _rotate(q: np.ndarray, w: np.ndarray, t: float) -> np.ndarray:
    """q after turning at constant body rate w for t (closed form of the kinematics)."""
    ang = np.linalg.norm(w) * t
    if ang == 0:
        return q
    e = w / np.linalg.norm(w)
    dq = np.append(e * math.sin(ang / 2), math.cos(ang / 2))  # body-frame rotation: dq (x) q
    v, s = dq[:3], dq[3]
    pv, ps = q[:3], q[3]
    return np.append(s * pv + ps * v - np.cross(v, pv), s * ps - v @ pv)


def test_angle_rate_error_bounds_every_sampled_error(cfg: config.Config) -> None:
    """|theta_dot(true) - theta_dot(measured)| <= the bound, theta_dot by central differences of the
    angle along the closed-form rotation (the sun held still, n = 0 in the record's bound is an upper
    bound too), for random states and errors at the bound."""
    c = cfg.with_noise()
    rec = constraint_record(c)[0]
    e, dw = rec["err_att_rad"], rec["err_omega_rad_s"]
    rng = np.random.default_rng(3)
    sun = np.array([1.0, 0.0, 0.0])
    worst = 0.0
    for _ in range(3000):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w = rng.normal(size=3)
        w *= rng.uniform(0, c.limits.omega_max_rad_s) / np.linalg.norm(w)
        ax = rng.normal(size=3)
        q_m = _rotate(q, ax / np.linalg.norm(ax) * e, 1.0)  # the measured attitude, e away
        dwv = rng.normal(size=3)
        w_m = w + dwv / np.linalg.norm(dwv) * dw * rng.uniform(0.5, 1)
        h = 1e-3
        rate = (_boresight_angle(_rotate(q, w, h), sun) - _boresight_angle(_rotate(q, w, -h), sun)) / (2 * h)
        rate_m = (_boresight_angle(_rotate(q_m, w_m, h), sun) - _boresight_angle(_rotate(q_m, w_m, -h), sun)) / (2 * h)
        th_m = _boresight_angle(q_m, sun)
        y = np.zeros(19)
        y[4:7] = w_m
        bound = angle_rate_error(math.sin(th_m), y, rec)
        if math.sin(th_m) > 0.05:
            worst = max(worst, abs(rate - rate_m) / bound)
        assert abs(rate - rate_m) <= bound * (1 + 1e-6) + 1e-9
    assert 0.2 < worst <= 1.0  # the bound is not vacuous


def test_noise_breaks_the_filter_without_margins_and_not_with_them(cfg: config.Config) -> None:
    """The paper example on the gyrostat, with the configured sensor errors: without the margins
    (bound_sigma 0, no lag) the filter lets constraints go; with them every substep is safe."""
    noisy = cfg.with_noise()
    scen = dc.replace(noisy.scenario("paper_example"), model="gyrostat")
    bare = dc.replace(noisy, sensors=dc.replace(noisy.sensors, bound_sigma=0.0, actuator_lag_s=0.0))
    t0 = simulate(bare, scen)
    t1 = simulate(noisy, scen)
    assert t1.y is not None and np.abs(t1.y - t1.x[:-1]).max() > 0
    assert (t0.h_substep_min.min(axis=0) < 0).any()
    assert (t1.h_substep_min.min(axis=0) >= 0).all()
    assert not (t1.status == "fallback").any()


def test_a_monte_carlo_run_has_its_own_noise_sequence(cfg: config.Config) -> None:
    """Run k of a batch (stream first_run + k) equals the stepped loop of that stream bit for bit."""
    c = cfg.with_noise()
    rng = np.random.default_rng(5)
    x0 = np.array([make_state(rng.normal(size=4), [0.002, -0.001, 0.0], [50.0, -20.0, 10.0], 270.0, 5000.0, 1.0)
                   for _ in range(3)])
    batch = run_runs(c, x0, 40.0, record=True, first_run=10)
    stepped = run_runs_stepped(c, x0, 40.0, record=True, first_run=10)
    assert np.array_equal(batch.trajectory, stepped.trajectory)
    shifted = run_runs(c, x0, 40.0, record=True, first_run=11)  # same states, other sequences
    assert not np.array_equal(batch.trajectory[1], shifted.trajectory[1])
    alone = run_runs(c, x0[1:], 40.0, record=True, first_run=11)  # run 11 of the campaign, alone
    assert np.array_equal(batch.trajectory[1], alone.trajectory[0])


def test_measurement_errors_follow_the_parameters(cfg: config.Config) -> None:
    c = _sensors(cfg, attitude_noise_rad=1e-4, gyro_noise_rad_s=2e-5, temperature_noise_K=0.5)
    err = measurement_errors(c)
    b = c.sensors.bound_sigma
    assert err["err_att_rad"] == pytest.approx(math.sqrt(3) * b * 1e-4)
    assert err["err_omega_axis_rad_s"] == pytest.approx(b * 2e-5)
    assert err["err_T_K"] == pytest.approx(b * 0.5)
    assert np.all(err["err_u_rad_s2"] == 0)
    # a safety value is the truth's: the margins change the filter's rows, not h
    cs = ConstraintSet(c)
    x = make_state([0.1, 0.2, 0.3, 0.9])
    assert np.array_equal(cs.safety_values(x), ConstraintSet(cfg).safety_values(x))
    assert cs.safety_values(x)[0] == ConstraintSet(cfg).safety_values(x)[0]


# ----------------------------------------------------------------------------- the message interface


def _f32(v: float) -> float:
    """v rounded to float32 the way a serialized float32 field carries it (IEEE binary32, little endian)."""
    return struct.unpack("<f", struct.pack("<f", v))[0]


def test_interface_fields_against_an_independent_encoding(cfg: config.Config) -> None:
    """encode / decode against numpy, struct's float32 and the attitude matrix written out here: the exact
    entries come back exactly, E to its float32 bound, theta_S through atan2 (wrapped into (-pi, pi])."""
    rec = sensors_record(cfg)
    V, s = cfg.power.bus_voltage_V, cfg.spacecraft.torque_sign
    rng = np.random.default_rng(5)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        x = np.concatenate([q, rng.normal(0, 0.02, 3), rng.uniform(-576, 576, 3), [rng.uniform(150, 400),
                            rng.uniform(0, 2e4), rng.uniform(-20, 20)], rng.normal(0, 100, 3), rng.normal(0, 1, 3)])
        f = message_fields(x, rec)
        A = _attitude_matrix(q)
        expect = np.concatenate([q, x[4:7], x[13:16], A @ x[16:19], -s * x[7:10], [x[10] - 273.15,
                                 _f32(x[11] / (V * 3600.0)), math.cos(x[12]), math.sin(x[12]), 0.0]])
        assert f.shape == (FIELD_SIZE,)
        np.testing.assert_allclose(f, expect, rtol=1e-15, atol=1e-15)
        assert f[17] == _f32(x[11] / (V * 3600.0))  # the charge is exactly a float32
        y = state_from_fields(f, rec)
        assert np.array_equal(y[:10], x[:10]) and np.array_equal(y[13:16], x[13:16])
        assert y[10] == x[10]  # degC and back is exact here (Sterbenz: 136.6-546.3 K)
        assert abs(y[11] - x[11]) <= 2.0**-24 * 1.0001 * abs(x[11])
        assert abs(math.remainder(y[12] - x[12], 2 * math.pi)) <= 4 * np.spacing(math.pi)
        assert -math.pi < y[12] <= math.pi
        np.testing.assert_allclose(y[16:19], x[16:19], rtol=0, atol=1e-14)


def test_interface_energy_bound_holds_below_the_limit(cfg: config.Config) -> None:
    """Where a battery violation could hide (E < E_min), the read E exceeds E_min + bound never; the bound is
    within 2.1x of the largest error seen (it is not loose)."""
    rec = sensors_record(cfg)
    e_min, bound = cfg.limits.energy_min_J, interface_energy_error(cfg)
    worst = 0.0
    for E in np.linspace(e_min * (1 - 1e-6), e_min, 20001):
        x = make_state([0.0, 0.0, 0.0, 1.0], E_J=float(E))
        read = state_from_fields(message_fields(x, rec), rec)[11]
        assert read < e_min + bound
        worst = max(worst, abs(read - E))
    assert bound / 2.1 <= worst <= bound  # half a float32 ulp is 2^-25..2^-24 of the value
