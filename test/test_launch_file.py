"""The launch file's logic (rta_attitude.ros.launch_file), driven without ros2launch: every argument is
checked before a node starts (one line naming it), and the run ends whatever ends it."""

from __future__ import annotations

import ast
import datetime as dt
import os
from pathlib import Path

import pytest

from rta_attitude import topics
from rta_attitude.errors import ConfigError
from rta_attitude.recording.bag import default_bag_name
from rta_attitude.ros.launch_file import ARGUMENTS, NODE_PARAMETERS, RunEnd, node_roles, validate

LAUNCH_FILE = Path(__file__).resolve().parents[1] / "launch" / "rta_attitude.launch.py"
EXE = topics.EXECUTABLES
PLANT, RECORDER, FILTER, CONTROLLER = (EXE[r] for r in (topics.PLANT, topics.RECORDER, topics.FILTER,
                                                         topics.CONTROLLER))
NOW = dt.datetime(2026, 11, 23, 21, 5, 7)


def test_defaults_are_valid_and_typed(tmp_path: Path) -> None:
    a = validate({}, cwd=tmp_path, now=NOW)
    assert a["rta"] is True and a["record"] is True and a["bag_overwrite"] is False
    assert a["real_time_factor"] == 1.0 and a["stepping"] == "lockstep" and a["scenario"] == "paper_example"
    assert a["bag"] == str(tmp_path / "rta_attitude_2026_11_23-21_05_07.mcap")  # rosbag2-style unique name
    assert Path(a["params_file"]).is_file()
    assert validate({"rta": "False", "stepping": "REALTIME", "discovery_range": "subnet", "domain_id": "42"},
                    cwd=tmp_path)["rta"] is False


@pytest.mark.parametrize(("name", "value", "words"), [
    ("stepping", "bogus", "stepping:='bogus': must be one of lockstep, realtime"),
    ("real_time_factor", "fast", "real_time_factor:='fast': must be a number"),
    ("real_time_factor", "-1", "must be a finite number > 0"),
    ("real_time_factor", "inf", "must be a finite number > 0"),
    ("rta", "yes", "rta:='yes': must be one of true, false"),
    ("domain_id", "300", "domain_id:='300': must be an integer 0-232"),
    ("domain_id", "x", "must be an integer"),
    ("discovery_range", "lan", "must be one of LOCALHOST, SUBNET, OFF"),
    ("namespace", "rta", "must be an absolute ROS name"),
    ("namespace", "/1sat", "must be an absolute ROS name"),
    ("params_file", "/nonexistent.yaml", "params_file:='/nonexistent.yaml': no such file"),
    ("scenario", "nope", "nope"),
    ("colour", "red", "unknown launch argument colour"),
])  # fmt: skip
def test_a_bad_argument_is_one_line_naming_it(tmp_path: Path, name: str, value: str, words: str) -> None:
    with pytest.raises(ConfigError) as err:
        validate({name: value}, cwd=tmp_path)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_a_bad_params_file_is_rejected_before_any_node(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    text = Path(validate({}, cwd=tmp_path)["params_file"]).read_text()
    assert "omega_max_deg_s: 1.0" in text
    bad.write_text(text.replace("omega_max_deg_s: 1.0", "omega_max_deg_s: -1.0"))
    with pytest.raises(ConfigError) as err:
        validate({"params_file": str(bad)}, cwd=tmp_path)
    assert f"params_file:={str(bad)!r}" in str(err.value) and "omega_max" in str(err.value)
    assert "\n" not in str(err.value)
    bad.write_text("/**:\n  ros__parameters: {filter: {preset: fast}}\n")  # an overlay with a bad value
    with pytest.raises(ConfigError, match=r"params_file.*filter\.preset must be one of"):
        validate({"params_file": str(bad)}, cwd=tmp_path)
    bad.write_text("/**:\n  ros__parameters: {}\n")  # an empty overlay: the defaults
    assert validate({"params_file": str(bad)}, cwd=tmp_path)["params_file"] == str(bad)


def test_the_bag_is_never_silently_reused(tmp_path: Path) -> None:
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"x")
    with pytest.raises(ConfigError, match=r"exists \(pass bag_overwrite:=true to replace it\)"):
        validate({"bag": str(bag)}, cwd=tmp_path)
    assert validate({"bag": str(bag), "bag_overwrite": "true"}, cwd=tmp_path)["bag"] == str(bag)
    assert validate({"bag": "rel.mcap"}, cwd=tmp_path)["bag"] == str(tmp_path / "rel.mcap")
    with pytest.raises(ConfigError, match="is a directory"):
        validate({"bag": str(tmp_path)}, cwd=tmp_path)
    with pytest.raises(ConfigError, match="does not exist"):
        validate({"bag": str(tmp_path / "no" / "run.mcap")}, cwd=tmp_path)
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        with pytest.raises(ConfigError, match="not writable"):
            validate({"bag": str(ro / "run.mcap")}, cwd=tmp_path)
    assert "bag" in validate({"record": "false", "bag": str(bag)}, cwd=tmp_path)  # not checked when not recording


def test_default_bag_names_are_time_stamped() -> None:
    assert default_bag_name(NOW) == "rta_attitude_2026_11_23-21_05_07.mcap"
    assert default_bag_name(NOW) != default_bag_name(NOW + dt.timedelta(seconds=1))


def test_a_normal_end_waits_for_the_recorder_and_ignores_the_shutdowns_exits() -> None:
    end = RunEnd(record=True)
    assert end.exited(PLANT, 0) == ("running", "")  # the recorder still closes the bag
    verdict, _ = end.exited(RECORDER, 0)
    assert verdict == "done"
    assert end.exited(FILTER, 0)[0] == "ignored" and end.exited(CONTROLLER, -2)[0] == "ignored"
    end = RunEnd(record=True)
    assert end.exited(RECORDER, 0)[0] == "running"  # the recorder saw the final run_status first: the plant's
    assert end.exited(PLANT, 0)[0] == "done"          # exit code decides
    end = RunEnd(record=False)
    assert end.exited(PLANT, 0)[0] == "done"


@pytest.mark.parametrize("record", [True, False])
def test_any_failure_ends_the_run_as_failed(record: bool) -> None:
    end = RunEnd(record=record)
    assert end.exited(PLANT, 2) == ("failed", f"{PLANT} exited with code 2")
    assert end.exited(RECORDER, 0)[0] == "ignored"
    end = RunEnd(record=record)
    assert end.exited(FILTER, 0) == ("failed", f"{FILTER} ended before the run did")
    end = RunEnd(record=record)
    assert end.exited(CONTROLLER, None)[0] == "failed"  # unknown exit code
    end = RunEnd(record=True)
    assert end.exited(PLANT, 0)[0] == "running"
    assert end.exited(CONTROLLER, 0)[0] == "running"  # after the plant is done: fine
    assert end.exited(RECORDER, 1) == ("failed", f"{RECORDER} exited with code 1")
    end = RunEnd(record=True)  # a failed run: the recorder closes the bag on the final `failed` status first
    assert end.exited(RECORDER, 0)[0] == "running"
    assert end.exited(PLANT, 1) == ("failed", f"{PLANT} exited with code 1")


def test_the_launch_file_declares_every_argument_and_uses_this_logic() -> None:
    """The launch file itself (parsed, not run: ros2launch is not a PyPI package) validates in an
    OpaqueFunction before creating nodes and wires every node's exit to RunEnd."""
    tree = ast.parse(LAUNCH_FILE.read_text())
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    assert {"validate", "RunEnd", "ARGUMENTS", "OpaqueFunction", "OnProcessExit"} <= names
    called = [n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    assert called.index("validate") < called.index("Node")  # nothing is built before the arguments are checked
    node_calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "Node"]
    assert all("sigterm_timeout" in {k.arg for k in n.keywords} for n in node_calls)  # no SIGTERM race on Ctrl-C
    assert "is_shutdown" in LAUNCH_FILE.read_text()  # exits after a user's shutdown are not failures
    assert len(ARGUMENTS) == len({a.name for a in ARGUMENTS}) == 13
    assert "node_roles(a)" in LAUNCH_FILE.read_text() and "NODE_PARAMETERS" in LAUNCH_FILE.read_text()


def test_controller_none_starts_no_controller_and_the_plant_waits_for_the_users(tmp_path: Path) -> None:
    """controller:=none: plant, filter and recorder (the scene hosted by the recorder); the plant's
    `external_controller` knob is set from it; a bad value is one line."""
    a = validate({"controller": "none"}, cwd=tmp_path)
    assert a["controller"] == "none"
    assert node_roles(a) == [topics.RECORDER, topics.FILTER, topics.PLANT]
    assert node_roles(validate({}, cwd=tmp_path)) == [topics.RECORDER, topics.FILTER, topics.CONTROLLER, topics.PLANT]
    assert node_roles(validate({"record": "false", "controller": "NONE"}, cwd=tmp_path)) == [
        topics.SCENE, topics.FILTER, topics.PLANT]  # no recorder: the scene is a process of its own
    assert node_roles(validate({"record": "false", "scene": "false"}, cwd=tmp_path)) == [
        topics.FILTER, topics.CONTROLLER, topics.PLANT]
    assert '"external_controller": a["controller"] == "none"' in LAUNCH_FILE.read_text()
    with pytest.raises(ConfigError, match=r"^launch argument controller:='lqr': must be one of pd, none$"):
        validate({"controller": "lqr"}, cwd=tmp_path)
    # every node the launch file starts declares the knobs it is given (a node ignores another role's knob)
    for role in (topics.PLANT, topics.FILTER, topics.CONTROLLER, topics.RECORDER, topics.SCENE):
        assert set(NODE_PARAMETERS) <= {k.name for k in topics.knobs_for(role)}
    assert "external_controller" in {k.name for k in topics.knobs_for(topics.PLANT)}
