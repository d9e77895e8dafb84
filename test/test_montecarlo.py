"""Monte Carlo: sampling, runs against `simulate` (bit for bit), backends, classification, CLI."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from rta_attitude import config
from rta_attitude.cli.main import main as cli_main
from rta_attitude.config.schema import Config, Scenario
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.state import ENERGY, OMEGA, PSI, TEMP, THETA_S, Q
from rta_attitude.errors import ConfigError
from rta_attitude.montecarlo.classify import unavoidable
from rta_attitude.montecarlo.runner import run_dask, run_local, run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation import closed_loop as simulation

NAMES = config.load().constraint_names
"""The default configuration's constraints, in row order."""


@pytest.fixture(scope="module")
def cfg() -> Config:
    return config.load()


@pytest.fixture(scope="module")
def states(cfg: Config) -> np.ndarray:
    x, _ = sample_initial_states(300, 11, cfg)
    return x


def _single_run(cfg: Config, x0: np.ndarray, duration_s: float) -> simulation.Trajectory:
    """The single-run reference: `simulate` of one sampled state, no primary controller."""
    return simulation.ClosedLoop(cfg, Scenario("mc", "", duration_s, x0, controller="none")).run()


# ----------------------------------------------------------------------------- sampling
def test_sampling_is_reproducible_and_independent_of_preset_and_sensors(cfg: Config) -> None:
    a, ra = sample_initial_states(64, 3, cfg)
    b, rb = sample_initial_states(64, 3, cfg.with_preset("paper"))
    # sensor errors widen the robust preset's margins: the states must not change with them (a noisy
    # campaign runs the nominal one's states; once they did not, 2 of 3 differed)
    n, rn = sample_initial_states(64, 3, cfg.with_noise())
    robust = cfg.with_preset("robust").with_models(filter="paper")
    assert np.any(ConstraintSet(robust.with_noise()).evaluate(a).psi0 < ConstraintSet(robust).evaluate(a).psi0)
    np.testing.assert_array_equal(a, n)
    np.testing.assert_array_equal(ra, rn)
    # Psi of either preset >= 0, with the paper model's margins (the sampler's rule: the same states for
    # every model; a gyrostat filter's larger exclusion-zone margin may start inside it, h >= 0)
    t = ConstraintSet(cfg.with_preset("robust").with_models(filter="paper")).evaluate(a)
    assert np.all(t.psi0 >= 0) and np.all(t.psi1 >= 0)
    c, _ = sample_initial_states(64, 3, cfg.with_preset("robust"))
    d, _ = sample_initial_states(64, 4, cfg)
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
    t = ConstraintSet(cfg.with_models(filter="paper")).evaluate(x)  # the sampler's margins (see above)
    assert np.all(t.h >= 0) and np.all(t.psi0 >= 0) and np.all(t.psi1 >= 0)
    # the hypercube spreads each variable: every tenth of the omega_x range is used
    bins = np.histogram(x[:, OMEGA.start], bins=10, range=(-0.95 * L.omega_max_rad_s, 0.95 * L.omega_max_rad_s))[0]
    assert np.all(bins > 0)


def test_bad_sampling_arguments(cfg: Config) -> None:
    with pytest.raises(ConfigError):
        sample_initial_states(0, 1, cfg)


# ----------------------------------------------------------------------------- whole runs == simulate
def _pole_states(states: np.ndarray) -> np.ndarray:
    """Sampled states plus attitudes at the arccos poles of the angle constraints."""
    x = states[:4].copy()
    x[0, Q], x[0, THETA_S] = (0.0, 0.0, 0.0, 1.0), math.pi  # sensor anti-sun
    x[1, Q], x[1, THETA_S] = (0.0, 0.0, 0.0, 1.0), 0.0  # sensor on the sun
    x[2, Q] = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))  # antenna (+j_B) on the Earth (-x Hill)
    x[3, Q], x[3, THETA_S] = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)), 0.5 * math.pi  # panel normal to the sun
    return np.concatenate([states, x])


def test_runs_equal_simulate_bit_for_bit(cfg: Config, states: np.ndarray) -> None:
    """A run of the Monte Carlo and `simulate` of its initial state run the same compiled step: the same
    numbers, bit for bit (poles included)."""
    x0 = _pole_states(states[:20])
    duration = 150.0
    out = run_runs(cfg, x0, duration, record=True)
    assert out.qp_steps.sum() > 0  # the QP path is exercised
    cs = ConstraintSet(cfg)
    for k in (0, 5, 11, 19, 20, 21, 22, 23):
        traj = _single_run(cfg, x0[k], duration)
        np.testing.assert_array_equal(traj.x, out.trajectory[k])
        np.testing.assert_array_equal(traj.h.min(axis=0), out.min_h_samples[k])
        np.testing.assert_array_equal((cs.safety_values(traj.x) < 0).any(axis=0), out.violated_samples[k])
        np.testing.assert_array_equal(traj.h_substep_min.min(axis=0) < 0, out.violated_substeps[k])


def test_batch_run_through_the_soften_fallback_equals_single_run(cfg: Config) -> None:
    """Run 132 of seed 1 hits infeasible QPs (soften fallback) within 120 s (53 steps; with the paper's model
    it was run 710)."""
    x, _ = sample_initial_states(1000, 1, cfg)
    x0 = x[[3, 132]]
    out = run_runs(cfg, x0, 120.0, record=True)
    assert out.fallback_steps[1] > 0 and out.qp_failures[1] == out.fallback_steps[1]
    traj = _single_run(cfg, x0[1], 120.0)
    np.testing.assert_array_equal(traj.x, out.trajectory[1])
    assert np.count_nonzero(traj.status == "fallback") == out.fallback_steps[1]


def test_full_length_run_equals_single_run(cfg: Config, states: np.ndarray) -> None:
    """One whole 2000 s run inside a small batch against the single-run loop."""
    x0 = states[30:33]
    out = run_runs(cfg, x0, 2000.0, record=True)
    traj = _single_run(cfg, x0[1], 2000.0)
    np.testing.assert_array_equal(traj.x, out.trajectory[1])


def test_proxsuite_batch_equals_simulate(cfg: Config, states: np.ndarray) -> None:
    """filter.solver proxsuite: the runs go through the same pipeline with proxsuite: identical with simulate
    on proxsuite."""
    x0 = states[40:43]
    c = cfg.with_solver("proxsuite")
    out = run_runs(c, x0, 60.0, record=True)
    for k in range(3):
        np.testing.assert_array_equal(_single_run(c, x0[k], 60.0).x, out.trajectory[k])


def test_chunking_and_process_backend_do_not_change_results(cfg: Config, states: np.ndarray) -> None:
    x0 = states[:10]
    one = run_local(cfg, x0, 40.0, workers=1)
    two = run_local(cfg, x0, 40.0, workers=2, chunk_runs=3)
    for name in ("violated_samples", "violated_substeps", "min_h_samples", "qp_steps", "x_final"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))


def test_dask_backend_equals_local_backend(cfg: Config, states: np.ndarray) -> None:
    distributed = pytest.importorskip("distributed")
    x0 = states[:10]
    local = run_local(cfg, x0, 40.0, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        remote = run_dask(cfg, x0, 40.0, client, chunk_runs=4)
        by_address = run_dask(cfg, x0, 40.0, cluster.scheduler_address, chunk_runs=6)
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
    rules = unavoidable(x, cfg, 2000.0)
    battery = rules["battery_energy"][:, NAMES.index("battery")]
    np.testing.assert_array_equal(battery, [True, False, False])
    # the bound: turning at sqrt(3) omega_max from 90 deg, the loss is P_out t - integral of P_in
    P, P_out = cfg.power.peak_W, cfg.power.load_W
    rate = math.sqrt(3) * cfg.limits.omega_max_rad_s + cfg.environment.mean_motion_rad_s
    th_star = math.acos(P_out / P)
    loss = (P_out * (math.pi / 2 - th_star) - P * (1.0 - math.sin(th_star))) / rate
    assert 1050.0 - loss < cfg.limits.energy_min_J < 1400.0 - loss


def test_sampled_states_are_never_doomed(cfg: Config, states: np.ndarray) -> None:
    """The Psi >= 0 rejection at t = 0 already removes every state the rules can prove lost."""
    rules = unavoidable(states, cfg, 2000.0)
    assert not any(v.any() for v in rules.values())


# ----------------------------------------------------------------------------- CLI and outputs
def test_stepped_runs_over_the_compiled_plant_equal_the_compiled_batch(cfg: Config, states: np.ndarray) -> None:
    """`run_runs_stepped` (the Monte Carlo of another simulator: one Python-stepped run per state) marks
    its outcome as the compiled batch does: over `CompiledPlant` every field is equal, bit for bit, in
    both presets (paper: violations and their first times are exercised)."""
    from dataclasses import fields

    from rta_attitude.dynamics.plant import CompiledPlant
    from rta_attitude.montecarlo.runner import run_runs_stepped

    for preset in ("robust", "paper"):
        c = cfg.with_preset(preset)
        x0 = _pole_states(states[:8])
        batch = run_runs(c, x0, 150.0, record=True)
        stepped = run_runs_stepped(c, x0, 150.0, plant=CompiledPlant, record=True)
        if preset == "paper":
            assert batch.violated_substeps.any() and np.isfinite(batch.first_violation_s).any()
        for f in fields(batch):
            np.testing.assert_array_equal(getattr(stepped, f.name), getattr(batch, f.name), err_msg=f.name)


def test_max_runs_runs_the_first_states_of_the_campaign(cfg: Config) -> None:
    from rta_attitude.montecarlo.campaign import montecarlo

    sub = montecarlo(cfg, 12, 30.0, seed=2, max_runs=3)
    full, _ = sample_initial_states(12, 2, cfg)
    np.testing.assert_array_equal(sub.x0, full[:3])
    assert sub.outcome.x_final.shape == (3, full.shape[1])
    with pytest.raises(ConfigError, match="max_runs must be >= 1"):
        montecarlo(cfg, 12, 30.0, seed=2, max_runs=0)


def test_cli_writes_json_csv_png_with_consistent_counts(tmp_path, capsys) -> None:
    out = tmp_path / "mc"
    status = cli_main(["montecarlo", "--runs", "12", "--duration", "40", "--seed", "2", "--workers", "1",
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
    x0, _ = sample_initial_states(12, 2, config.load())
    np.testing.assert_array_equal(np.array([[float(r[n]) for n in ("q1", "omega_y", "psi_z", "E")] for r in rows]),
                                  x0[:, [0, 5, 9, 11]])
    printed = capsys.readouterr().out
    assert "success rate" in printed and "98.32%" not in printed  # 40 s is not the paper's protocol


def test_the_papers_column_is_printed_for_the_papers_protocol_only() -> None:
    """The paper's table beside ours only where the campaign is the paper's: its vehicle and limits, its sensor
    cone (whatever its name), 2,000 s."""
    import dataclasses

    from rta_attitude.montecarlo.report import paper_names, paper_protocol

    cfg = config.load()
    assert paper_protocol(cfg, 2000.0) and not paper_protocol(cfg, 40.0)
    twelve_u = dataclasses.replace(cfg, spacecraft=dataclasses.replace(cfg.spacecraft, inertia_kgm2=(0.2, 0.25, 0.15)))
    assert not paper_protocol(twelve_u, 2000.0)
    beta = dataclasses.replace(cfg, environment=dataclasses.replace(cfg.environment, sun_beta_rad=0.5))
    assert not paper_protocol(beta, 2000.0)  # the sun out of the orbit plane: not the paper's orbit
    renamed = dataclasses.replace(cfg.pointing[0], name="sun_sensor")
    plain = dataclasses.replace(cfg.filter, priorities=())  # (the default's name the paper's cones)
    other = dataclasses.replace(cfg, pointing=(renamed, cfg.pointing[1]), scenarios={}, filter=plain)
    assert paper_protocol(other, 2000.0) and paper_names(other)["sensor keep-out"] == "sun_sensor"
    moved = dataclasses.replace(cfg.pointing[0], boresight_body=(0.0, 0.0, -1.0))
    assert not paper_protocol(dataclasses.replace(cfg, pointing=(moved, cfg.pointing[1]), scenarios={}, filter=plain),
                              2000.0)


def test_cli_rejects_bad_arguments(tmp_path, capsys) -> None:
    assert cli_main(["montecarlo", "--runs", "0", "--out", str(tmp_path)]) == 1
    assert capsys.readouterr().err.startswith("ERROR: --runs")
    assert cli_main(["montecarlo", "--runs", "2", "--duration", "5", "--backend", "dask", "--out", str(tmp_path)]) == 1
    assert "--scheduler" in capsys.readouterr().err



def test_classify_proves_the_momentum_battery_failures(cfg: Config) -> None:
    """Runs 841 and 985 of seed 1 (|J w - D psi| / D = 888 and 893 rad/s: the wheels hold the total
    momentum only with the panel far from the sun) are proved lost by the viability oracle's
    `momentum_battery` rule where the run lost the battery (or a rate or wheel speed: the rule is about
    keeping all of them), never where it lost only a constraint the rule says nothing about; a state whose
    momentum the wheels hold anywhere is never proved lost by it."""
    from rta_attitude.montecarlo.classify import classify

    x0, _ = sample_initial_states(5000, 1, cfg)
    sc = cfg.spacecraft
    hd = np.linalg.norm(sc.J * x0[:, OMEGA] - sc.torque_sign * sc.wheel_inertia_kgm2 * x0[:, PSI], axis=1)
    hd /= sc.wheel_inertia_kgm2
    small = int(np.flatnonzero(hd < 400.0)[0])
    assert hd[841] > 880.0 and hd[985] > 880.0
    x = x0[[841, 985, small]]
    for lost_name, expect in (("battery", [True, True, False]), ("omega_y", [True, True, False]),
                              ("communication", [False, False, False])):
        violated = np.zeros((3, len(NAMES)), dtype=bool)
        violated[:, NAMES.index(lost_name)] = True
        lost, rules = classify(x, violated, cfg, 2000.0)
        assert lost.tolist() == expect, lost_name
        assert [r == "momentum_battery" for r in rules] == expect
