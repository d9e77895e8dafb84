"""Configuration errors are one line naming the parameter; the CLI exits non-zero without a
traceback; the core imports without rclpy; package.xml and setup.py agree."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from rta_attitude import config
from rta_attitude.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "config" / "rta_attitude.yaml"


def _params():
    return yaml.safe_load(DEFAULT.read_text())["/**"]["ros__parameters"]


def _write(tmp_path, params):
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return p


@pytest.mark.parametrize("edit, message", [
    (lambda p: p["filter"].__setitem__("gain", 1), r"parameters\.filter: unknown key 'gain'"),
    (lambda p: p["thermal"].__setitem__("mass_kg", "two"), r"thermal\.mass_kg must be a finite number, got 'two'"),
    (lambda p: p["thermal"].__setitem__("mass_kg", -2.0), r"thermal\.mass_kg must be > 0, got -2\.0"),
    (lambda p: p["filter"].__setitem__("fallback", "pray"), r"filter\.fallback must be one of .*got 'pray'"),
    (lambda p: p["constraints"]["omega"].__setitem__("k1", 0.0), r"constraints\.omega\.k1 must be > 0"),
    (lambda p: p["spacecraft"].__setitem__("inertia_kgm2", [1.0, 2.0]), r"inertia_kgm2 must be a list of 3"),
    (lambda p: p["integrator"].__setitem__("substeps", 2.5), r"integrator\.substeps must be an integer"),
    (lambda p: p.__setitem__("limits", 5), r"parameters\.limits must be a mapping"),
    (lambda p: p["constraints"]["pointing"].__setitem__("exclusion_zone", [1, 2]),
     r"constraints\.pointing\.exclusion_zone must be a mapping"),
])
def test_config_errors_name_the_parameter(tmp_path, edit, message):
    params = _params()
    edit(params)
    with pytest.raises(ConfigError, match=message) as exc:
        config.load(_write(tmp_path, params))
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("epoch, message", [
    ("2024-03-02T00:00:00+01:00", r"scenarios\.paper_example\.epoch_utc must be in UTC"),
    ("March 2nd", r"scenarios\.paper_example\.epoch_utc must be an ISO 8601 UTC date-time"),
    ("1969-12-31T23:59:59Z", r"epoch_utc must not be before 1970-01-01"),
])
def test_a_bad_scenario_names_itself_and_leaves_the_others(tmp_path, epoch, message):
    """A scenario's error names it and is raised where that scenario is used; the others run, and
    check-config reports it with exit 1."""
    params = _params()
    params["scenarios"]["paper_example"]["epoch_utc"] = epoch
    path = _write(tmp_path, params)
    cfg = config.load(path)
    with pytest.raises(ConfigError, match=message) as exc:
        cfg.scenario("paper-example")
    assert "\n" not in str(exc.value)
    assert cfg.scenario("passed-example").name == "passed_example"
    r = _cli("check-config", "--config", str(path))
    assert r.returncode == 1 and re.search(message, r.stderr) and r.stderr.count("ERROR") == 1


def test_an_overlay_holds_only_what_differs(tmp_path):
    """A user's file merged onto the defaults: a new cone added, a gain changed, a default cone removed
    (null); -p sets one key on top; the result is validated as one."""
    overlay = {"constraints": {"pointing": {"star_tracker": {
        "kind": "keep_out", "boresight_body": [0.0, 0.0, -1.0], "target": "earth", "half_angle_deg": 30.0,
        "k1": 0.1, "k2": 0.3}, "communication": None}, "omega": {"k1": 0.3}},
        "filter": {"priorities": ["omega, psi, exclusion_zone", "battery", "temperature"]}}  # (it named the removed)
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": overlay}}))
    cfg = config.load(path, overrides=config.parse_overrides(["constraints.pointing.star_tracker.half_angle_deg=35",
                                                              "filter.preset=paper"]))
    assert cfg.constraint_names[:2] == ("exclusion_zone", "star_tracker")
    assert math.isclose(math.degrees(cfg.pointing_constraint("star_tracker").half_angle_rad), 35.0)
    assert cfg.gains("omega_y").k1 == 0.3 and cfg.filter.preset == "paper"
    assert cfg.limits == config.load().limits  # the rest: the defaults
    assert "star_tracker" in cfg.priority_levels[0]  # a hard cone the priorities leave out: the first level
    with pytest.raises(ConfigError, match=r"-p 'filter\.preset': expected KEY=VALUE"):
        config.parse_overrides(["filter.preset"])
    with pytest.raises(ConfigError, match=r"filter\.preset must be one of"):
        config.load(path, overrides={"filter.preset": "fast"})
    r = _cli("simulate", "--config", str(path), "-p", "scenarios.paper_example.duration_s=3", "--no-plot",
             "--out", str(tmp_path / "sim"))
    assert r.returncode == 0, r.stderr
    assert "star_tracker" in r.stdout


def test_scenario_epoch_is_its_utc_date_in_ros_time(tmp_path):
    """t = 0 of a run is the scenario's epoch_utc in ROS time (ns since 1970-01-01Z), checked against the C
    library's calendar (timegm); a scenario without one gets the fixed default."""
    import calendar

    cfg = config.load()
    assert cfg.scenario("paper_example").epoch_ns == calendar.timegm((2024, 3, 2, 0, 0, 0)) * 10**9
    assert cfg.scenario("passed_example").epoch_ns == cfg.scenario("paper_example").epoch_ns
    params = _params()
    params["scenarios"]["paper_example"]["epoch_utc"] = "2030-07-14T06:30:00.25Z"
    moved = config.load(_write(tmp_path, params)).scenario("paper_example").epoch_ns
    assert moved == calendar.timegm((2030, 7, 14, 6, 30, 0)) * 10**9 + 250_000_000


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        config.load(tmp_path / "nope.yaml")


def test_units_are_converted_once():
    cfg = config.load()
    assert cfg.limits.omega_max_rad_s == pytest.approx(np.radians(1.0))
    assert cfg.limits.temperature_max_K == pytest.approx(283.15)
    assert cfg.pointing_constraint("exclusion_zone").half_angle_rad == pytest.approx(np.radians(40.0))
    x0 = cfg.scenario("paper-example").x0
    assert x0[10] == pytest.approx(281.65) and x0[12] == pytest.approx(np.radians(525.0))
    assert cfg.scenario("slack-on-exclusion-zone").slack_weights == (("exclusion_zone", 1e12),)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "rta_attitude.cli", *args], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=300)


def test_cli_bad_config_is_one_line_and_exit_1(tmp_path):
    params = _params()
    params["filter"]["preset"] = "fastest"
    r = _cli("check-config", "--config", str(_write(tmp_path, params)))
    assert r.returncode == 1
    assert r.stderr.strip().count("\n") == 0 and r.stderr.startswith("ERROR: ")
    assert "filter.preset must be one of robust, paper, got 'fastest'" in r.stderr
    assert "Traceback" not in r.stderr


def test_cli_unknown_scenario(tmp_path):
    r = _cli("simulate", "--scenario", "moon-landing", "--out", str(tmp_path))
    assert r.returncode == 1 and "unknown scenario 'moon-landing'" in r.stderr and "Traceback" not in r.stderr


def test_cli_simulate_writes_summary_timeseries_and_figure(tmp_path):
    r = _cli("simulate", "--scenario", "passed-example", "--duration", "60", "--out", str(tmp_path))
    s = json.loads((tmp_path / "summary.json").read_text())
    # the verdict is the exit status (its printed omega starts above w_max: UNSAFE, 2; docs/decisions.md)
    assert r.returncode == (0 if s["safe"] else 2), r.stderr
    assert s["steps"] == 60 and s["scenario"] == "passed_example"
    assert "exclusion_zone" in s["constraints"] and "intervening_steps" in s
    data = np.load(tmp_path / "timeseries.npz")
    assert data["x"].shape == (61, 19) and list(data["state_names"][:4]) == ["q1", "q2", "q3", "q4"]
    png = (tmp_path / "figure.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 50_000
    assert "SAFE" in r.stdout or "UNSAFE" in r.stdout


def test_core_imports_without_rclpy():
    code = ("import sys, rta_attitude.simulation.closed_loop, rta_attitude.filter.asif, "
            "rta_attitude.simulation.metrics, rta_attitude.config.loader, rta_attitude.montecarlo.campaign, "
            "rta_attitude.recording.analysis, rta_attitude.cli.launcher; print('rclpy' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.stdout.strip() == "False", r.stderr


def test_package_xml_and_setup_py_agree():
    xml = (ROOT / "package.xml").read_text()
    setup = (ROOT / "setup.py").read_text()
    v_xml = re.search(r"<version>([^<]+)</version>", xml).group(1)
    v_setup = re.search(r'version="([^"]+)"', setup).group(1)
    assert v_xml == v_setup
    assert re.search(r"<name>rta_attitude</name>", xml)


def test_setup_finds_every_package():
    """setup.py's find_packages must see the core, the constraints and the nodes (each needs an
    __init__.py), or an installed rta-attitude cannot import itself."""
    from setuptools import find_packages

    found = set(find_packages(str(ROOT), exclude=["test", "test.*", "bench", "bench.*"]))
    assert {"rta_attitude", "rta_attitude.constraints", "rta_attitude.ros"} <= found
