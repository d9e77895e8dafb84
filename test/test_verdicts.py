"""Verdicts a CI job can use: `simulate`, `analyze` and `montecarlo` exit 0 on SAFE, 2 on UNSAFE (0 with
--allow-unsafe), 1 on bad input with one `ERROR:` line (argument errors included), and the three give the
same verdict on the same run.

The run: run 0 of seed 1 with the PD law slewing to its random target for 30 s, without the gatekeeper. With
the `paper` preset its continuous-time rate barrier breaks omega_x and omega_y within a second (h = -2.6e-4
rad^2/s^2 at a sample, 1.4x the rate limit); the `robust` preset keeps every rate a third of the way inside
its limit. The Monte Carlo runs it (`--max-runs 1`), `simulate` runs it as a scenario written from the
Monte Carlo's outputs (initial state and target, converted to the YAML's units), and `analyze` reads a bag
of `simulate`'s run, written as the recorder writes one. The commands run through the CLI's main() in
this process.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml

from rta_attitude.cli.main import main as cli_main

Cli = Callable[..., subprocess.CompletedProcess[str]]
SEED, DURATION_S = 1, 30.0
NO_GATE = ("--backup-law", "none")


@pytest.fixture()
def cli(capsys: pytest.CaptureFixture[str]) -> Cli:
    """main() of the CLI in this process: (returncode, stdout, stderr); argparse's exits are caught."""

    def call(*args: str) -> subprocess.CompletedProcess[str]:
        capsys.readouterr()
        try:
            code = cli_main([str(a) for a in args])
        except SystemExit as exc:  # argparse: --help, or its error (Parser.error)
            code = int(exc.code or 0)
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(list(args), code, out, err)

    return call


def _one_error_line(proc: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert proc.returncode == 1, (proc.args, proc.returncode, proc.stdout[-1500:], proc.stderr[-1500:])
    err = proc.stderr
    assert err.startswith("ERROR: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, (n, err)


def _scenario_overlay(path: Path, name: str, x0: np.ndarray, times: np.ndarray, targets: np.ndarray) -> Path:
    """A config overlay with one scenario: the state x0 and the PD law toward the targets, in the YAML's units."""
    schedule = [float(v) for t, q in zip(times, targets) for v in (t, *q)]
    scenario = {
        "description": "Monte Carlo run 0 of seed 1", "duration_s": DURATION_S,
        "q": [float(v) for v in x0[0:4]], "omega_deg_s": [math.degrees(v) for v in x0[4:7]],
        "psi_rad_s": [float(v) for v in x0[7:10]], "temperature_degC": float(x0[10]) - 273.15,
        "energy_J": float(x0[11]), "theta_S_deg": math.degrees(x0[12]), "controller": "pd",
        "command_schedule": schedule,
    }
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"scenarios": {name: scenario}}}}))
    return path


def _bag_of(timeseries: Path, bag: Path) -> Path:
    """The run of simulate's timeseries.npz as the recorder writes it: the state at every sample, the desired
    and the applied torque (tau = D u) of every step."""
    from rta_attitude import config
    from rta_attitude.recording.bag import BagWriter
    from rta_attitude.ros import convert

    D = config.load().spacecraft.wheel_inertia_kgm2
    with np.load(timeseries) as z:
        t_s, x, u, u_des = z["t_s"], z["x"], z["u"], z["u_des"]
    with BagWriter(bag) as w:
        w.add_topic("/rta/state", "sensor_msgs/msg/JointState")
        w.add_topic("/rta/torque_des", "geometry_msgs/msg/Vector3Stamped")
        w.add_topic("/rta/torque_cmd", "geometry_msgs/msg/Vector3Stamped")
        for k in range(len(t_s)):
            t_ns = round(float(t_s[k]) * 1e9)
            w.write_message("/rta/state", convert.state_msg(x[k], t_ns), t_ns)
            if k < len(u):
                w.write_message("/rta/torque_des", convert.torque_msg(D * u_des[k], t_ns), t_ns)
                w.write_message("/rta/torque_cmd", convert.torque_msg(D * u[k], t_ns), t_ns)
    return bag


@pytest.mark.parametrize(("preset", "unsafe"), [("paper", True), ("robust", False)])
def test_simulate_analyze_and_montecarlo_agree_on_one_run(cli: Cli, tmp_path: Path, preset: str, unsafe: bool) -> None:
    expected = 2 if unsafe else 0
    mc_args = ("montecarlo", "--runs", 4, "--max-runs", 1, "--seed", SEED, "--duration", DURATION_S, "--controller",
               "pd", "--workers", 1, "--no-plot", "--no-progress", "--preset", preset, *NO_GATE)
    mc = cli(*mc_args, "--out", tmp_path / "mc")
    assert mc.returncode == expected, mc.stderr
    with np.load(tmp_path / "mc" / "outcome.npz") as z:
        x0, times, targets = z["x0"][0], z["target_times_s"], z["targets_q"][0]
    counted = set(json.loads((tmp_path / "mc" / "summary.json").read_text())["setup"]["constraints_counted"])
    row = next(csv.DictReader((tmp_path / "mc" / "runs.csv").open()))
    mc_violated = {n for n in row["violated_incl_substeps"].split(";") if n} & counted
    assert bool(mc_violated) == unsafe
    if unsafe:
        assert mc_violated >= {"omega_x", "omega_y"}

    overlay = _scenario_overlay(tmp_path / "run0.yaml", "mc_run_0", x0, times, targets)
    sim_args = ("simulate", "--config", overlay, "--scenario", "mc-run-0", "--no-plot", "--preset", preset, *NO_GATE)
    sim = cli(*sim_args, "--out", tmp_path / "sim")
    assert sim.returncode == expected, sim.stderr
    assert set(json.loads((tmp_path / "sim" / "summary.json").read_text())["violated"]) == mc_violated

    bag = _bag_of(tmp_path / "sim" / "timeseries.npz", tmp_path / "run0.mcap")
    an = cli("analyze", bag, "--no-plot", "--out", tmp_path / "an")
    assert an.returncode == expected, an.stderr
    assert set(json.loads((tmp_path / "an" / "summary.json").read_text())["violated"]) == mc_violated

    for proc in (mc, sim, an):
        assert "ERROR" not in proc.stderr and "Traceback" not in proc.stderr
        if unsafe:  # one line says why the status is not 0; every output was written before it
            assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("UNSAFE: "), proc.stderr
            assert "exit status 2; --allow-unsafe exits 0" in proc.stderr
            assert "UNSAFE" in proc.stdout
        else:
            assert proc.stderr == ""
            assert "SAFE" in proc.stdout and "UNSAFE" not in proc.stdout
    if unsafe:  # --allow-unsafe: the same verdict printed, exit 0, nothing on stderr
        for args in (mc_args, sim_args, ("analyze", bag, "--no-plot")):
            ok = cli(*args, "--allow-unsafe", "--out", tmp_path / f"allowed-{args[0]}")
            assert ok.returncode == 0 and ok.stderr == "" and "UNSAFE" in ok.stdout, (args[0], ok.stderr)


def test_the_campaign_gate_is_the_share_of_runs_kept_safe_against_min_safe_rate(cli: Cli, tmp_path: Path) -> None:
    """--min-safe-rate: SAFE exactly when the share of runs without a counted violation at any sample or
    substep (runs.csv, counted independently here) reaches it; default 1 (any failed run is UNSAFE). The
    campaign: the paper's model and preset without the gatekeeper, 8 runs of seed 1 for 60 s (run 4 breaks a
    rate limit)."""
    runs = 8
    args = ("montecarlo", "--runs", runs, "--seed", SEED, "--duration", 60, "--workers", 1, "--no-plot",
            "--no-progress", "--preset", "paper", "--plant-model", "paper", "--filter-model", "paper", *NO_GATE)
    default = cli(*args, "--out", tmp_path / "default")
    rows = list(csv.DictReader((tmp_path / "default" / "runs.csv").open()))
    safe_runs = sum(1 for r in rows if r["failed_incl_substeps"] == "0")
    assert 0 < safe_runs < len(rows) == runs, safe_runs  # the gate has both sides to tell apart
    rate = safe_runs / runs
    assert default.returncode == 2
    verdict = json.loads((tmp_path / "default" / "summary.json").read_text())["verdict"]
    assert (verdict["safe"], verdict["safe_runs"], verdict["runs"]) == (False, safe_runs, runs)
    assert verdict["min_safe_rate"] == 1.0
    assert f"UNSAFE: {runs - safe_runs} of {runs} runs violated" in default.stdout
    at_rate = cli(*args, "--min-safe-rate", repr(rate), "--out", tmp_path / "at")
    assert at_rate.returncode == 0 and at_rate.stderr == "", at_rate.stderr
    assert json.loads((tmp_path / "at" / "summary.json").read_text())["verdict"]["safe"] is True
    assert f"SAFE: {runs - safe_runs} of {runs} runs violated" in at_rate.stdout
    above = cli(*args, "--min-safe-rate", repr(rate + 0.01), "--out", tmp_path / "above")
    assert above.returncode == 2 and above.stderr.startswith("UNSAFE: ")


@pytest.mark.parametrize(("args", "needle"), [
    (("simulate", "--duration", "abc"), "argument --duration: invalid float value: 'abc'"),
    (("simulate", "--duration", "-1"), "--duration must be > 0 s"),
    (("simulate", "--scenario", "moon-landing"), "unknown scenario 'moon-landing'"),
    (("simulate", "--allow-unsafe", "--bogus"), "unrecognized arguments: --bogus"),
    (("analyze", "NOPE.mcap"), "no such file"),
    (("analyze",), "the following arguments are required: bag"),
    (("montecarlo", "--runs", "abc"), "argument --runs: invalid int value: 'abc'"),
    (("montecarlo", "--runs", "0"), "--runs must be >= 1"),
    (("montecarlo", "--min-safe-rate", "99.5"), "--min-safe-rate must be a fraction in [0, 1]"),
    (("montecarlo", "--retarget", "100"), "--retarget needs a controller"),
    (("montecarlo", "--controller", "pd", "--retarget", "0"), "--retarget must be > 0 s"),
    (("montecarlo", "--controller", "lqr"), "--controller must be none, pd or module:function, got 'lqr'"),
    (("montecarlo", "--controller", "no_such_module_xyz:f"), "cannot import 'no_such_module_xyz'"),
    (("montecarlo", "--controller", "math:no_such_function"), "'math' has no attribute 'no_such_function'"),
    (("montecarlo", "--controller", "math:pi"), "'pi' is not callable"),
    (("montecarlo", "--seed", "-1"), "--seed must be >= 0"),
    (("check-config", "--bogus"), "unrecognized arguments: --bogus"),
    ((), "the following arguments are required: COMMAND"),
])
def test_bad_input_is_exit_1_with_one_error_line_and_no_output_folder(cli: Cli, tmp_path: Path, args: tuple[str, ...],
                                                                      needle: str) -> None:
    out = tmp_path / "new" / "out"
    argv = (*args, "--out", out) if args[:1] in (("simulate",), ("analyze",), ("montecarlo",)) else args
    _one_error_line(cli(*argv), needle)
    assert not (tmp_path / "new").exists()


def test_help_documents_the_exit_status_of_the_three_commands(cli: Cli) -> None:
    for command in ("simulate", "analyze", "montecarlo"):
        proc = cli(command, "--help")
        assert proc.returncode == 0
        text = " ".join(proc.stdout.split())
        assert "--allow-unsafe" in text and "exit status:" in text
        for code in ("0 SAFE", "1 the command could not run", "2 UNSAFE", "130 interrupted"):
            assert code in text, (command, code)
    assert "--min-safe-rate" in cli("montecarlo", "--help").stdout
