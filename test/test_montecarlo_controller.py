"""The Monte Carlo of a primary controller (`montecarlo --controller pd | module:function`): each run equals
`simulate` of its initial state and targets bit for bit; a user's Python function runs through the stepped loop
to the compiled loop's numbers; the targets are seeded per run; the outputs say which controller flew."""

from __future__ import annotations

import csv
import json
import pickle
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rta_attitude import config
from rta_attitude.cli.main import main as cli_main
from rta_attitude.config.schema import Config
from rta_attitude.dynamics.controller import ControllerError
from rta_attitude.errors import ConfigError
from rta_attitude.montecarlo.controllers import RunController
from rta_attitude.montecarlo.runner import run_local, run_runs
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.closed_loop import ClosedLoop


@pytest.fixture(scope="module")
def cfg() -> Config:
    return config.load()


@pytest.fixture(scope="module")
def states(cfg: Config) -> np.ndarray:
    x, _ = sample_initial_states(40, 5, cfg)
    return x


def _module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, source: str) -> str:
    """A user's controller module `name` in tmp_path, importable (and imported afresh) for this test."""
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(source))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, name, raising=False)
    return name


# ----------------------------------------------------------------------------- the PD law, compiled
def test_pd_runs_equal_simulate_of_their_state_and_targets_bit_for_bit(cfg: Config, states: np.ndarray) -> None:
    """The compiled loop's PD branch is `simulate`'s loop: every state, commanded attitude, desired and
    applied command of a run equals `ClosedLoop(cfg, controller.scenario(...)).run()`, retargets included,
    in both presets and with sensor errors (the law reads the measured state)."""
    duration = 150.0
    # (configuration, controller, index of the first run, runs compared); `simulate` draws the sensors' noise
    # sequence 0, the Monte Carlo the run's index: with sensor errors, run 0 is compared
    for c, ctrl, first, ks in ((cfg, RunController("pd", 5, 40.0), 10, (0, 3, 5)),
                               (cfg.with_preset("paper"), RunController("pd", 5), 10, (0, 3, 5)),
                               (cfg.with_noise(), RunController("pd", 9, 60.0), 0, (0,))):
        x0 = states[:6]
        out = run_runs(c, x0, duration, record=True, controller=ctrl, first_run=first)
        assert out.qp_steps.sum() > 0
        for k in ks:
            scenario = ctrl.scenario(x0[k], first + k, duration)
            traj = ClosedLoop(c, scenario).run()
            np.testing.assert_array_equal(traj.x, out.trajectory[k])
            np.testing.assert_array_equal(traj.h.min(axis=0), out.min_h_samples[k])
            np.testing.assert_array_equal(traj.h_substep_min.min(axis=0) < 0, out.violated_substeps[k])
            # the law flew: it asked for motion, toward the run's targets in force at each sample
            times, q = ctrl.target_times(duration), ctrl.targets(first + k, 1, duration)[0]
            rows = np.searchsorted(times, traj.t_s[:-1], side="right") - 1
            np.testing.assert_array_equal(traj.q_c, q[rows])
            assert np.abs(traj.u_des).max() > 1.0
    assert len(RunController("pd", 5, 40.0).target_times(duration)) == 4  # 0, 40, 80, 120 s


def test_without_a_controller_the_runs_are_todays(cfg: Config, states: np.ndarray) -> None:
    """--controller none is u_des = 0: the same outcome as the runs of the paper's protocol (test_equivalence
    holds their records), whatever seed the targets would have had."""
    a = run_runs(cfg, states[:3], 60.0, record=True)
    b = run_runs(cfg, states[:3], 60.0, record=True, controller=RunController("none", 77))
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    traj = ClosedLoop(cfg, RunController().scenario(states[1], 1, 60.0)).run()
    assert not traj.u_des.any()
    np.testing.assert_array_equal(traj.x, a.trajectory[1])


def test_pd_campaign_chunks_and_workers_do_not_change_results(cfg: Config, states: np.ndarray) -> None:
    ctrl = RunController("pd", 3, 20.0)
    one = run_local(cfg, states[:8], 40.0, workers=1, controller=ctrl)
    two = run_local(cfg, states[:8], 40.0, workers=2, chunk_runs=3, controller=ctrl)
    for name in ("violated_samples", "violated_substeps", "min_h_samples", "qp_steps", "x_final"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))
    assert pickle.loads(pickle.dumps(ctrl)) == ctrl  # it travels to worker processes and Dask workers


# ----------------------------------------------------------------------------- targets
def test_targets_are_uniform_attitudes_seeded_per_run() -> None:
    ctrl = RunController("pd", 7, 500.0)
    q = ctrl.targets(0, 2000, 2000.0)
    assert q.shape == (2000, 4, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=2), 1.0, atol=1e-15)
    assert np.all(q[..., 3] >= 0)
    # per run: the same targets whichever chunk asks for them
    np.testing.assert_array_equal(ctrl.targets(1234, 3, 2000.0), q[1234:1237])
    assert not np.array_equal(RunController("pd", 8, 500.0).targets(0, 3, 2000.0), q[:3])
    np.testing.assert_array_equal(ctrl.target_times(2000.0), [0.0, 500.0, 1000.0, 1500.0])
    np.testing.assert_array_equal(RunController("pd", 7).target_times(2000.0), [0.0])
    # uniform on SO(3): the rotation angle a from the identity has the density (1 - cos a) / pi on [0, pi],
    # so its mean is pi/2 + 2/pi (126.5 deg) and its distribution function (a - sin a) / pi (8,000 draws)
    angle = Rotation.from_quat(q.reshape(-1, 4)).magnitude()
    assert abs(np.degrees(angle.mean()) - np.degrees(np.pi / 2 + 2 / np.pi)) < 1.5
    for a in (np.pi / 2, 2.0, 2.5):
        assert abs(np.mean(angle <= a) - (a - np.sin(a)) / np.pi) < 0.02


def test_the_initial_states_do_not_depend_on_the_controller(cfg: Config) -> None:
    from rta_attitude.montecarlo.campaign import montecarlo

    with_pd = montecarlo(cfg, 12, 5.0, seed=4, controller="pd", retarget_s=2.0)
    x0, _ = sample_initial_states(12, 4, cfg)
    np.testing.assert_array_equal(with_pd.x0, x0)


def test_bad_controller_arguments_are_one_line(cfg: Config) -> None:
    for args, message in ((("lqr", 1), "must be none, pd or module:function"), (("pd", 1, -5.0), "must be > 0 s"),
                          (("none", 1, 10.0), "--retarget needs a controller"), (("pd", -1), "integer >= 0"),
                          ((":f", 1), "module:function")):
        with pytest.raises(ConfigError, match=message) as exc:
            RunController(*args)
        assert "\n" not in str(exc.value)


# ----------------------------------------------------------------------------- a user's Python function
def test_a_python_controller_runs_the_stepped_loop_to_the_compiled_numbers(cfg: Config, states: np.ndarray,
                                                                           tmp_path: Path,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """A function that computes the PD law in Python (through `desired_command`) gives the compiled PD runs
    bit for bit: the stepped loop calls it with the measured state, the run's targets and the time, sends
    its answer across the torque interface as the compiled loop does; it gets copies, and its reset() runs
    before each run."""
    name = _module(tmp_path, monkeypatch, "user_pd_law", """
        import numpy as np

        from rta_attitude import config
        from rta_attitude.dynamics.controller import controller_record, desired_command

        LAW = controller_record(config.load())
        calls = []
        resets = []


        def pd(y, q_c, t_s):
            calls.append((t_s, q_c.copy()))
            u = desired_command(y, q_c, LAW)
            y[:] = np.nan  # its own copy: the filter must not see this
            q_c[:] = np.nan
            return list(u)


        def reset():
            resets.append(len(calls))


        pd.reset = reset
    """)
    duration = 100.0
    python = RunController(f"{name}:pd", 5, 30.0)
    compiled = RunController("pd", 5, 30.0)
    x0 = states[10:13]
    a = run_runs(cfg, x0, duration, record=True, controller=compiled, first_run=10)
    b = run_runs(cfg, x0, duration, record=True, controller=python, first_run=10)
    for f in ("trajectory", "violated_samples", "violated_substeps", "first_violation_s", "min_h_samples",
              "qp_steps", "fallback_steps", "qp_failures", "max_comm_slack", "gate_steps", "x_final"):
        np.testing.assert_array_equal(getattr(b, f), getattr(a, f), err_msg=f)
    module = sys.modules[name]
    steps = round(duration / cfg.filter.sample_time_s)
    assert module.resets == [0, steps, 2 * steps]
    t = np.array([c[0] for c in module.calls])
    np.testing.assert_array_equal(t[:steps], np.arange(steps) * cfg.filter.sample_time_s)
    targets = compiled.targets(11, 1, duration)[0]
    np.testing.assert_array_equal(module.calls[steps + 31][1], targets[1])  # run 11 at t = 31 s: its second target


@pytest.mark.parametrize(("body", "message"), [
    ("return [0.0, float('nan'), 0.0]", r"returned \[0\.0, nan, 0\.0\] at t = 0 s: it must return 3 finite"),
    ("return np.zeros(4)", r"returned array\(\[0\., 0\., 0\., 0\.\]\) at t = 0 s"),
    ("return 'fast'", r"returned 'fast' at t = 0 s"),
    ("raise KeyError('gain')", r"it raised KeyError: 'gain'"),
    ("return np.zeros(3) if t_s < 3 else None", r"returned None at t = 3 s"),
])
def test_a_python_controller_that_answers_wrongly_stops_the_campaign_in_one_line(
        cfg: Config, states: np.ndarray, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, body: str,
        message: str) -> None:
    name = _module(tmp_path, monkeypatch, "user_bad_law", f"""
        import numpy as np


        def law(y, q_c, t_s):
            {body}
    """)
    with pytest.raises(ControllerError, match=rf"^--controller {name}:law, run 2: .*{message}") as exc:
        run_runs(cfg, states[:1], 10.0, controller=RunController(f"{name}:law", 1), first_run=2)
    assert "\n" not in str(exc.value)


# ----------------------------------------------------------------------------- the command
def test_cli_records_the_controller_its_targets_and_where_the_runs_ended(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mc"
    status = cli_main(["montecarlo", "--runs", "6", "--duration", "60", "--seed", "3", "--controller", "pd",
                       "--retarget", "25", "--workers", "1", "--no-progress", "--no-plot", "--out", str(out)])
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert status == (0 if summary["verdict"]["safe"] else 2)
    assert summary["setup"]["controller"] == {"name": "pd", "kind": "pd", "retarget_s": 25.0, "target_seed": 3}
    assert summary["controller"]["targets_per_run"] == 3
    assert "primary controller pd, a new random target every 25 s" in printed
    with np.load(out / "outcome.npz") as z:
        np.testing.assert_array_equal(z["target_times_s"], [0.0, 25.0, 50.0])
        np.testing.assert_array_equal(z["targets_q"], RunController("pd", 3, 25.0).targets(0, 6, 60.0))
        assert str(z["controller"]) == "pd"
        q_end, target = z["x_final"][:, :4], z["targets_q"][:, -1]
    # the final attitude error, independently: the angle of the rotation between target and attitude
    expect = np.degrees((Rotation.from_quat(target).inv() * Rotation.from_quat(q_end)).magnitude())
    rows = list(csv.DictReader((out / "runs.csv").open()))
    np.testing.assert_allclose([float(r["final_attitude_error_deg"]) for r in rows], expect, atol=1e-6)
    assert summary["controller"]["final_attitude_error_deg"]["max"] == pytest.approx(expect.max(), abs=1e-6)


def test_the_papers_protocol_has_no_primary_controller(cfg: Config) -> None:
    from rta_attitude.montecarlo.report import paper_protocol

    assert paper_protocol(cfg, 2000.0) and paper_protocol(cfg, 2000.0, "none")
    assert not paper_protocol(cfg, 2000.0, "pd") and not paper_protocol(cfg, 2000.0, "mine:law")


def test_a_python_controller_from_the_command_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """`--controller module:function` from the working directory (as a user runs it), and a controller
    that fails mid-campaign: one ERROR line, exit 1, and no output folder left behind."""
    (tmp_path / "my_controller.py").write_text(textwrap.dedent("""
        import numpy as np


        def hold(y, q_c, t_s):
            return -0.5 * np.asarray(y[4:7]) / 0.01  # damp the body rates


        def broken(y, q_c, t_s):
            return [0.0, 0.0, float('inf')] if t_s >= 2 else [0.0, 0.0, 0.0]
    """))
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, "my_controller", raising=False)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    args = ["montecarlo", "--runs", "2", "--duration", "5", "--seed", "1", "--workers", "1", "--no-progress",
            "--no-plot"]
    status = cli_main([*args, "--controller", "my_controller:hold", "--out", "ok"])
    assert status in (0, 2)
    assert json.loads((tmp_path / "ok" / "summary.json").read_text())["setup"]["controller"]["name"] == \
        "my_controller:hold"
    capsys.readouterr()
    assert cli_main([*args, "--controller", "my_controller:broken", "--out", "new/broken"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("ERROR: --controller my_controller:broken, run 0: the primary controller returned "
                          "[0.0, 0.0, inf] at t = 2 s") and err.count("\n") == 1, err
    assert not (tmp_path / "new").exists()
