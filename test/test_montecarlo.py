"""Monte Carlo: sampling, the batch engine against the single-run code, backends, classification, CLI."""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest

from rta_attitude import batch, config, montecarlo, simulation
from rta_attitude.constraints import ConstraintSet
from rta_attitude.params import CONSTRAINT_NAMES, BarrierGains, Config, Scenario
from rta_attitude.state import ENERGY, OMEGA, PSI, TEMP, THETA_S, Q


@pytest.fixture(scope="module")
def cfg() -> Config:
    return config.load()


@pytest.fixture(scope="module")
def states(cfg: Config) -> np.ndarray:
    x, _ = montecarlo.sample_initial_states(300, 11, cfg)
    return x


def _single_run(cfg: Config, x0: np.ndarray, duration_s: float, solver: str) -> simulation.Trajectory:
    """The single-run reference: ClosedLoop on one sampled state, no primary controller."""
    c = cfg.with_solver("active_set" if solver == "active-set" else "proxsuite")
    return simulation.ClosedLoop(c, Scenario("mc", "", duration_s, x0, controller="none")).run()


# ----------------------------------------------------------------------------- sampling
def test_sampling_is_reproducible_and_independent_of_preset(cfg: Config) -> None:
    a, ra = montecarlo.sample_initial_states(64, 3, cfg)
    b, rb = montecarlo.sample_initial_states(64, 3, cfg.with_preset("paper"))
    t = ConstraintSet.from_config(cfg.with_preset("robust")).evaluate(a)  # Psi of either preset >= 0
    assert np.all(t.psi0 >= 0) and np.all(t.psi1 >= 0)
    c, _ = montecarlo.sample_initial_states(64, 3, cfg.with_preset("robust"))
    d, _ = montecarlo.sample_initial_states(64, 4, cfg)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    np.testing.assert_array_equal(ra, rb)
    assert not np.array_equal(a, d)
    assert ra.sum() > 0  # the rejection step is exercised


def test_samples_lie_inside_the_safe_set_with_the_buffer(cfg: Config, states: np.ndarray) -> None:
    L = cfg.limits
    x = states
    np.testing.assert_allclose(np.linalg.norm(x[:, Q], axis=1), 1.0, atol=1e-12)
    assert np.all(np.abs(x[:, OMEGA]) <= 0.95 * L.omega_max_rad_s)
    assert np.all(np.abs(x[:, PSI]) <= 0.95 * L.psi_max_rad_s)
    assert np.all((x[:, TEMP] >= 273.15 - 10.0) & (x[:, TEMP] <= 273.15 + 9.5))
    assert np.all((x[:, ENERGY] >= 1.05 * L.energy_min_J) & (x[:, ENERGY] <= 10_000.0))
    assert np.all((x[:, THETA_S] >= 0.0) & (x[:, THETA_S] < 2 * math.pi))
    assert np.all(x[:, 13:] == 0.0)
    t = ConstraintSet.from_config(cfg).evaluate(x)
    assert np.all(t.h >= 0) and np.all(t.psi0 >= 0) and np.all(t.psi1 >= 0)
    # the hypercube spreads each variable: every tenth of the omega_x range is used
    bins = np.histogram(x[:, OMEGA.start], bins=10, range=(-0.95 * L.omega_max_rad_s, 0.95 * L.omega_max_rad_s))[0]
    assert np.all(bins > 0)


def test_bad_sampling_arguments(cfg: Config) -> None:
    with pytest.raises(montecarlo.ConfigError):
        montecarlo.sample_initial_states(0, 1, cfg)


# ----------------------------------------------------------------------------- the batch engine vs the core
def _pole_states(states: np.ndarray) -> np.ndarray:
    """Sampled states plus attitudes at the arccos poles of the angle constraints."""
    x = states[:8].copy()
    x[0, Q], x[0, THETA_S] = (0.0, 0.0, 0.0, 1.0), math.pi  # sensor anti-sun
    x[1, Q], x[1, THETA_S] = (0.0, 0.0, 0.0, 1.0), 0.0  # sensor on the sun
    x[2, Q] = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))  # antenna (+j_B) on the Earth (-x Hill)
    x[3, Q], x[3, THETA_S] = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)), 0.5 * math.pi  # panel normal to the sun
    return np.concatenate([states, x])


def _with_margins(cfg: Config) -> Config:
    """The config with a sampled-data margin on every HOCBF (skips where the core has none)."""
    if "margin" not in {f.name for f in dataclasses.fields(BarrierGains)}:
        pytest.skip("this core has no sampled-data margins")
    margins = {"exclusion_zone": 1e-3, "communication": 2e-3, "temperature": 0.1, "battery": 20.0}
    barriers = {k: dataclasses.replace(v, margin=margins[k]) if k in margins else v for k, v in cfg.barriers.items()}
    return dataclasses.replace(cfg, barriers=barriers)


@pytest.mark.parametrize("preset", ["robust", "paper", "robust-with-margins"])
def test_batch_safety_values_equal_the_core_bit_for_bit(cfg: Config, states: np.ndarray, preset: str) -> None:
    c = _with_margins(cfg.with_preset("robust")) if preset == "robust-with-margins" else cfg.with_preset(preset)
    x = _pole_states(states)
    sim = batch.BatchSimulator(c)
    np.testing.assert_array_equal(sim.safety_values(np.ascontiguousarray(x.T)),
                                  ConstraintSet.from_config(c).safety_values(x))


def test_plant_equals_integrate_bit_for_bit(cfg: Config, states: np.ndarray) -> None:
    rng = np.random.default_rng(5)
    u = rng.uniform(-5.0, 5.0, (len(states), 3))
    x_next, _ = simulation.integrate(states, u, 1.0, cfg)
    X = np.ascontiguousarray(states.T)
    Y = X[[0, 1, 2, 3, 4, 5, 6, TEMP, ENERGY]].copy()
    Y1, psi1, th1 = batch._Plant(cfg).integrate(Y, X[PSI].copy(), X[THETA_S].copy(), np.ascontiguousarray(u.T),
                                                1.0, cfg.substeps)
    np.testing.assert_array_equal(Y1, x_next.T[[0, 1, 2, 3, 4, 5, 6, TEMP, ENERGY]])
    np.testing.assert_array_equal(psi1, x_next.T[PSI])
    np.testing.assert_array_equal(th1, x_next.T[THETA_S])


# ----------------------------------------------------------------------------- whole runs: batch == single run
def test_batch_runs_equal_single_runs(cfg: Config, states: np.ndarray) -> None:
    x0 = states[:24]
    duration = 150.0
    out = batch.BatchSimulator(cfg).run(x0, duration, record=True)
    assert out.qp_steps.sum() > 0  # the QP path is exercised
    cs = ConstraintSet.from_config(cfg)
    for k in (0, 5, 11, 23):
        traj = _single_run(cfg, x0[k], duration, "active-set")
        assert np.max(np.abs(traj.x - out.trajectory[k])) <= 1e-9
        np.testing.assert_array_equal(traj.x, out.trajectory[k])  # in fact bit-identical
        np.testing.assert_array_equal(traj.h.min(axis=0), out.min_h_samples[k])
        np.testing.assert_array_equal((cs.safety_values(traj.x) < 0).any(axis=0), out.violated_samples[k])
        np.testing.assert_array_equal(traj.h_substep_min.min(axis=0) < 0, out.violated_substeps[k])


def test_batch_run_through_the_soften_fallback_equals_single_run(cfg: Config) -> None:
    """Run 710 of seed 1 hits infeasible QPs (soften fallback) within 120 s."""
    x, _ = montecarlo.sample_initial_states(1000, 1, cfg)
    x0 = x[[3, 710]]
    out = batch.BatchSimulator(cfg).run(x0, 120.0, record=True)
    assert out.fallback_steps[1] > 0 and out.qp_failures[1] == out.fallback_steps[1]
    traj = _single_run(cfg, x0[1], 120.0, "active-set")
    assert np.max(np.abs(traj.x - out.trajectory[1])) <= 1e-9
    assert np.count_nonzero(traj.status == "fallback") == out.fallback_steps[1]


def test_full_length_run_equals_single_run(cfg: Config, states: np.ndarray) -> None:
    """One whole 2000 s run inside a small batch against the single-run loop."""
    x0 = states[30:33]
    out = batch.BatchSimulator(cfg).run(x0, 2000.0, record=True)
    traj = _single_run(cfg, x0[1], 2000.0, "active-set")
    assert np.max(np.abs(traj.x - out.trajectory[1])) <= 1e-9


def test_proxsuite_batch_equals_simulate(cfg: Config, states: np.ndarray) -> None:
    """solver='proxsuite' runs filter_batch with proxsuite: identical with simulate on proxsuite."""
    x0 = states[40:43]
    out = batch.BatchSimulator(cfg, "proxsuite").run(x0, 60.0, record=True)
    for k in range(3):
        traj = simulation.simulate(cfg.with_solver("proxsuite"), Scenario("mc", "", 60.0, x0[k], controller="none"))
        assert np.max(np.abs(traj.x - out.trajectory[k])) <= 1e-9


def test_chunking_and_process_backend_do_not_change_results(cfg: Config, states: np.ndarray) -> None:
    x0 = states[:10]
    one = montecarlo.run_local(cfg, x0, 40.0, workers=1)
    two = montecarlo.run_local(cfg, x0, 40.0, workers=2, chunk_runs=3)
    for name in ("violated_samples", "violated_substeps", "min_h_samples", "qp_steps", "x_final"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))


def test_dask_backend_equals_local_backend(cfg: Config, states: np.ndarray) -> None:
    distributed = pytest.importorskip("distributed")
    x0 = states[:10]
    local = montecarlo.run_local(cfg, x0, 40.0, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        remote = montecarlo.run_dask(cfg, x0, 40.0, client, chunk_runs=4)
        by_address = montecarlo.run_dask(cfg, x0, 40.0, cluster.scheduler_address, chunk_runs=6)
    for name in ("violated_samples", "violated_substeps", "first_violation_s", "min_h_samples", "qp_steps",
                 "fallback_steps", "qp_failures", "max_comm_slack", "x_final"):
        np.testing.assert_array_equal(getattr(local, name), getattr(remote, name))
        np.testing.assert_array_equal(getattr(local, name), getattr(by_address, name))


# ----------------------------------------------------------------------------- classification
def test_battery_rule_flags_only_what_no_command_can_save(cfg: Config) -> None:
    x = np.zeros((3, 19))
    x[:, Q] = (0.0, 0.0, 0.0, 1.0)  # panel +k_B along +z Hill: 90 deg from the sun, in the x-y plane
    x[:, TEMP] = 273.15
    x[:, ENERGY] = (1050.0, 1400.0, 5000.0)
    rules = montecarlo.unavoidable(x, cfg, 2000.0)
    battery = rules["battery_energy"][:, CONSTRAINT_NAMES.index("battery")]
    np.testing.assert_array_equal(battery, [True, False, False])
    # the bound: turning at sqrt(3) omega_max from 90 deg, the loss is P_out t - integral of P_in
    P, P_out = cfg.power.peak_W, cfg.power.load_W
    rate = math.sqrt(3) * cfg.limits.omega_max_rad_s + cfg.environment.mean_motion_rad_s
    th_star = math.acos(P_out / P)
    loss = (P_out * (math.pi / 2 - th_star) - P * (1.0 - math.sin(th_star))) / rate
    assert 1050.0 - loss < cfg.limits.energy_min_J < 1400.0 - loss


def test_sampled_states_are_never_doomed(cfg: Config, states: np.ndarray) -> None:
    """The Psi >= 0 rejection at t = 0 already removes every state the rules can prove lost."""
    rules = montecarlo.unavoidable(states, cfg, 2000.0)
    assert not any(v.any() for v in rules.values())


# ----------------------------------------------------------------------------- CLI and outputs
def test_cli_writes_json_csv_png_with_consistent_counts(tmp_path, capsys) -> None:
    out = tmp_path / "mc"
    status = montecarlo.main(["--runs", "12", "--duration", "40", "--seed", "2", "--workers", "1",
                              "--out", str(out), "--no-progress", "--preset", "paper"])
    assert status == 0
    summary = json.loads((out / "summary.json").read_text())
    rows = list(csv.DictReader((out / "runs.csv").open()))
    assert len(rows) == 12 == summary["setup"]["runs"]
    failed = sum(int(r["failed"]) for r in rows)
    assert summary["at_samples"]["failed"] == failed
    assert summary["at_samples"]["success_rate"] == pytest.approx((12 - failed) / 12)
    assert summary["classification"]["failed"] == failed
    assert (summary["classification"]["physically_unrecoverable"] + summary["classification"]["filter_shortfall"]
            == failed)
    by = summary["at_samples"]["by_constraint_counts"]
    for name, count in by.items():
        assert count == sum(1 for r in rows if int(r["failed"]) and name in r["violated"].split(";"))
    assert "communication" not in by  # slacked: reported apart
    png = out / "initial_conditions.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    x0, _ = montecarlo.sample_initial_states(12, 2, config.load())
    np.testing.assert_array_equal(np.array([[float(r[n]) for n in ("q1", "omega_y", "psi_z", "E")] for r in rows]),
                                  x0[:, [0, 5, 9, 11]])
    printed = capsys.readouterr().out
    assert "success rate" in printed and "98.32%" in printed


def test_cli_rejects_bad_arguments(tmp_path, capsys) -> None:
    assert montecarlo.main(["--runs", "0", "--out", str(tmp_path)]) == 1
    assert capsys.readouterr().err.startswith("ERROR: --runs")
    assert montecarlo.main(["--runs", "2", "--duration", "5", "--backend", "dask", "--out", str(tmp_path)]) == 1
    assert "--scheduler" in capsys.readouterr().err

