"""rta_attitude.recording.analysis: bag -> series and summary, checked against the in-process run.

Bags are written here the way the nodes publish and the recorder records a lockstep run: messages
built by the nodes' own converters (nodes/convert.py) from an in-process ClosedLoop run, in the
order the nodes publish them, into rta_attitude.recording.bag.BagWriter; one bag is written instead with the
independent `rosbags` writer and serializer. The summary of each bag must equal `simulate`'s
summary of the same run (metrics.summarize_trajectory), key by key and value by value, apart from
the analysis' own `bag` section. Bad inputs go through the real CLI in subprocesses. No mocks.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rta_attitude import config, topics
from rta_attitude.cli.main import main as cli_main
from rta_attitude.dynamics import spacecraft
from rta_attitude.dynamics.controller import controller_record, desired_command
from rta_attitude.errors import BagError
from rta_attitude.recording import analysis
from rta_attitude.recording import summary as bag_summary
from rta_attitude.recording.bag import BagWriter, Qos
from rta_attitude.simulation.closed_loop import ClosedLoop, Trajectory
from rta_attitude.simulation.metrics import format_summary, summarize_trajectory

DURATION_S = 150.0
NS = "/rta"
REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


@pytest.fixture(scope="module")
def cfg() -> Any:
    return config.load()


@dataclasses.dataclass
class Run:
    loop: ClosedLoop
    traj: Trajectory
    summary: dict[str, Any]


def _reference(cfg: Any, rta: bool, duration_s: float = DURATION_S) -> Run:
    scenario = dataclasses.replace(cfg.scenario("paper-example"), duration_s=duration_s)
    loop = ClosedLoop(cfg, scenario, rta=rta)
    traj = loop.run()
    summary = summarize_trajectory(traj, loop.cfg)
    return Run(loop, traj, summary)


@pytest.fixture(scope="module")
def runs(cfg: Any) -> dict[bool, Run]:
    """{rta: in-process run of paper-example, 150 s} with and without RTA."""
    return {rta: _reference(cfg, rta) for rta in (True, False)}


def _messages(run: Run, rejected: int = 0) -> list[tuple[str, Any, int]]:
    """(topic, rclpy message, time [ns]) of the run, in the order the nodes publish them.

    Per step k: plant state + /clock (t_k) and, from k = 1, torque_applied (t_k-1); controller
    torque_des; filter torque_cmd + filter_status (RTA) or the pass-through torque_cmd. The chain
    also answers the final state, as in the DDS run. run_status at the start and the end. `rejected`:
    the first that many torque_des go out in frame `base_link`, and filter_status counts them as the filter
    node does (`torque_des_rejected`, the reason).
    """
    from rta_attitude.ros import convert

    loop, traj = run.loop, run.traj
    cfg, n = loop.cfg, traj.steps
    D = cfg.spacecraft.wheel_inertia_kgm2

    def to_tau(u: np.ndarray) -> np.ndarray:
        return spacecraft.wheel_accel_to_torque(u, D)

    def through_dds(u: np.ndarray) -> np.ndarray:
        return spacecraft.torque_to_wheel_accel(to_tau(u), D)
    t_ns = [round(float(t) * 1e9) for t in traj.t_s]
    slacked = tuple(name for name, s in zip(loop.filter.names, loop.filter.slacked) if s)
    values = {"scenario": loop.scenario.name, "rta": loop.rta, "stepping": "lockstep", "steps": n, "step": 0,
              "dt_s": 1.0}
    out: list[tuple[str, Any, int]] = [
        (f"{NS}/run_status", convert.run_status_msg(0, topics.RUN_RUNNING, values), 0)]
    for k in range(n + 1):
        t = t_ns[k]
        out += [(f"{NS}/state", convert.state_msg(traj.x[k], t), t), ("/clock", convert.clock_msg(t), t)]
        if k > 0:
            tau_prev = to_tau(traj.u[k - 1])
            out.append((f"{NS}/torque_applied", convert.torque_msg(tau_prev, t_ns[k - 1]), t_ns[k - 1]))
        if k < n:
            u_des = traj.u_des[k]
        else:
            q_c = loop.scenario.command_at(float(traj.t_s[k]))
            law = controller_record(cfg, loop.scenario.controller == "pd")
            u_des = through_dds(desired_command(traj.x[k], q_c, law))
        desired = convert.torque_msg(to_tau(u_des), t)
        if k < rejected:
            desired.header.frame_id = "base_link"
        out.append((f"{NS}/torque_des", desired, t))
        if not loop.rta:
            out.append((f"{NS}/torque_cmd", convert.torque_msg(to_tau(u_des), t), t))
            continue
        res = loop.filter.filter(traj.x[k], u_des)
        if k < n:  # the filter is deterministic: the re-filtered command is the run's
            assert np.array_equal(np.clip(through_dds(res.u), -181.3, 181.3), traj.u[k])
            res.record["solve_time_s"] = float(traj.solve_time_s[k])
        tau = to_tau(res.u)
        out.append((f"{NS}/torque_cmd", convert.torque_msg(tau, t), t))
        inputs = {"torque_des_rejected": min(k + 1, rejected)}
        out.append((f"{NS}/filter_status",
                    convert.filter_status_msg(res, t, loop.filter.counters, cfg.filter.preset, slacked, inputs,
                                              rejection="frame 'base_link'" if rejected else ""), t))
    done = {**values, "step": n}
    out.append((f"{NS}/run_status", convert.run_status_msg(t_ns[-1], topics.RUN_DONE, done), t_ns[-1]))
    return out


def _write(run: Run, path: Path, chunk_size: int = 256 * 1024, metadata: bool = True, rejected: int = 0) -> Path:
    """A bag as bag_recorder_node writes it (BagWriter; the `rta_attitude` metadata record)."""

    msgs = _messages(run, rejected)
    with BagWriter(path, chunk_size=chunk_size) as bag:
        for spec in topics.recorded(run.loop.rta):
            name = spec.name if spec.name.startswith("/") else f"{NS}/{spec.name}"
            bag.add_topic(name, spec.type_name, Qos(history=spec.qos.history, depth=spec.qos.depth,
                                                    reliability=spec.qos.reliability, durability=spec.qos.durability))
        for topic, msg, t in msgs:
            bag.write_message(topic, msg, t)
        if metadata:
            bag.add_metadata("rta_attitude", {
                "scenario": run.loop.scenario.name, "rta": str(run.loop.rta).lower(),
                "preset": run.loop.cfg.filter.preset, "config": run.loop.cfg.source,
                "duration_s": repr(run.loop.scenario.duration_s), "dt_s": "1.0", "namespace": NS})
    return path


@pytest.fixture(scope="module")
def bags(runs: dict[bool, Run], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bags")
    good = _write(runs[True], d / "rta.mcap", chunk_size=8 * 1024)
    data = good.read_bytes()
    (d / "truncated.mcap").write_bytes(data[: int(0.6 * len(data))])
    with BagWriter(d / "foreign.mcap") as bag:
        bag.add_topic("/chatter", "std_msgs/msg/String")
        for k in range(5):
            bag.write_message("/chatter", {"data": f"hello {k}"}, k * 1_000_000_000)
    (d / "empty.mcap").write_bytes(b"")
    (d / "notes.mcap").write_text("this is a text file, not a bag\n" * 20)
    return {"rta": good, "no_rta": _write(runs[False], d / "no_rta.mcap"), "truncated": d / "truncated.mcap",
            "foreign": d / "foreign.mcap", "empty": d / "empty.mcap", "text": d / "notes.mcap",
            "missing": d / "missing.mcap"}


def _without_bag(summary: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in summary.items() if k != "bag"}


# ----------------------------------------------------------------------------- equality with simulate


@pytest.mark.parametrize("rta", [True, False], ids=["rta", "no_rta"])
def test_bag_summary_equals_in_process_summary(rta: bool, runs: dict[bool, Run], bags: dict[str, Path],
                                               cfg: Any) -> None:
    run = analysis.load_run(bags["rta" if rta else "no_rta"], cfg)
    summary = bag_summary.summarize_run(run, cfg)
    assert _without_bag(summary) == runs[rta].summary  # every key, every value, exactly
    traj = runs[rta].traj
    np.testing.assert_array_equal(run.x, traj.x)
    np.testing.assert_array_equal(run.u, traj.u)
    np.testing.assert_array_equal(run.u_des, traj.u_des)
    np.testing.assert_array_equal(run.h_substep_min, traj.h_substep_min)  # recomputed between samples
    np.testing.assert_array_equal(run.h_substep_argmin_s, traj.h_substep_argmin_s)
    b = summary["bag"]
    assert b["reintegration_residual"] == 0.0 and b["substep_minima"].startswith("recomputed exactly")
    assert not b["truncated"] and b["data_ends_s"] == DURATION_S and b["notes"] == []
    assert summary["scenario"] == "paper_example" and summary["steps"] == traj.steps
    if rta:  # the interesting parts really are there
        assert summary["intervening_steps"] > 0 and summary["safe"]
        np.testing.assert_array_equal(run.intervening, traj.intervening)
        np.testing.assert_array_equal(run.slack, traj.slack)
    else:
        assert not summary["safe"] and "omega_x" in summary["violated"]
        assert summary["angular_acceleration"]["omega_dot_x"]["first_exceed_s"] == 0.0


def test_rosbags_writer_bag_gives_the_same_summary(runs: dict[bool, Run], tmp_path: Path, cfg: Any) -> None:
    """A rosbag2 bag directory from the independent rosbags writer and CDR serializer (little- and
    big-endian messages mixed), no metadata record (as `ros2 bag record -s mcap` would leave):
    scenario and step count come from run_status."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)

    def convert(msg: Any, type_name: str) -> Any:
        """rclpy message -> rosbags dataclass of the same type, field by field."""
        cls = store.types[type_name]
        fields = {}
        for name, ftype in msg.get_fields_and_field_types().items():
            value = getattr(msg, name)
            base = ftype.split("<")[-1].split("[")[0].rstrip(">")
            if "/" in base:
                nested = base.replace("/", "/msg/")
                if isinstance(value, (list, tuple)):
                    fields[name] = [convert(v, nested) for v in value]
                else:
                    fields[name] = convert(value, nested)
            elif isinstance(value, bytes):
                fields[name] = value[0]
            elif not isinstance(value, (str, int, float, bool)) and base not in ("string",):
                fields[name] = np.asarray(value, dtype=np.float64 if base == "double" else None)
            else:
                fields[name] = value
        return cls(**fields)

    msgs = _messages(runs[True])
    path = tmp_path / "rosbags_run"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns: dict[str, Any] = {}
        for i, (topic, msg, t) in enumerate(msgs):
            type_name = f"{type(msg).__module__.split('.')[0]}/msg/{type(msg).__name__}"
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, type_name, typestore=store)
            data = store.serialize_cdr(convert(msg, type_name), type_name, little_endian=i % 3 != 0)  # both orders
            writer.write(conns[topic], t, data)
    assert (path / "metadata.yaml").is_file()
    run = analysis.load_run(path, cfg)  # a bag directory is accepted
    assert run.path.suffix == ".mcap"
    assert _without_bag(bag_summary.summarize_run(run, cfg)) == runs[True].summary


def test_filter_status_layout_matches_the_filter_node(runs: dict[bool, Run], cfg: Any) -> None:
    """parse_diagnostics + load_run read what nodes/convert.filter_status_msg writes (any mismatch in
    key names would show up as zeros here)."""
    from rta_attitude.ros import convert

    loop, traj = runs[True].loop, runs[True].traj
    k = int(np.flatnonzero(traj.intervening.any(axis=1))[0])
    res = loop.filter.filter(traj.x[k], traj.u_des[k])
    msg = convert.filter_status_msg(res, 7, loop.filter.counters, "robust", ("communication",))
    parsed = analysis.parse_diagnostics(msg)
    record = convert.filter_record(msg, res.names)
    top = parsed["filter"]
    assert top["status"] == record["status"] and top["preset"] == "robust"
    assert [parsed[n]["intervening"] == "true" for n in res.names] == record["intervening"].tolist()
    assert [float(parsed[n]["slack"]) for n in res.names] == record["slack"].tolist()
    assert parsed["communication"]["slacked"] == "true" and parsed["battery"]["slacked"] == "false"
    assert any(record["intervening"])


# ----------------------------------------------------------------------------- bad and partial input


def test_truncated_bag_is_analysed_up_to_where_it_stops(runs: dict[bool, Run], bags: dict[str, Path],
                                                        cfg: Any) -> None:
    run = analysis.load_run(bags["truncated"], cfg)
    traj = runs[True].traj
    n = run.steps
    assert run.truncated and 10 < n < traj.steps
    assert run.data_end_s == float(traj.t_s[n])
    np.testing.assert_array_equal(run.x, traj.x[: n + 1])
    np.testing.assert_array_equal(run.h_substep_min, traj.h_substep_min[:n])
    summary = bag_summary.summarize_run(run, cfg)
    assert summary["bag"]["truncated"] and summary["steps"] == n
    assert f"bag truncated: data ends at t = {run.data_end_s:.1f} s" in bag_summary.format_bag_lines(summary)
    # the verdict says how far it goes (data_end_s is a whole number of seconds here)
    assert summary["bag"]["verdict"] == {"data_ends_s": run.data_end_s, "caveats": []}
    assert f"SAFE up to t = {run.data_end_s:,.0f} s (bag truncated): no non-slacked constraint violated" in \
        format_summary(summary).splitlines()


def test_verdict_of_a_run_whose_commands_were_rejected_says_so(runs: dict[bool, Run], tmp_path: Path,
                                                                cfg: Any) -> None:
    """A bag whose filter_status counts rejected torque_des (here in frame `base_link`): the summary carries
    the counts and the reason, and the verdict is not a plain SAFE; a clean bag's verdict is."""
    rejected = 90
    bag = _write(runs[True], tmp_path / "rejected.mcap", rejected=rejected)
    summary = bag_summary.summarize_run(analysis.load_run(bag, cfg), cfg)
    n = runs[True].traj.steps + 1  # the chain answers the final state too
    commands = summary["bag"]["commands"]  # `answered`: the filter's calls (here the re-used in-process filter's)
    assert {k: v for k, v in commands.items() if k != "answered"} == {
        "received": n, "rejected": rejected, "reason": "frame 'base_link'", "missing": 0}
    line = f"SAFE, but {rejected} of {n} commands were rejected (frame 'base_link'): no non-slacked constraint violated"
    assert line in format_summary(summary).splitlines()
    code, out, err = (lambda p: (p.wait(timeout=120), *p.communicate()))(
        _cli("analyze", str(bag), "--out", str(tmp_path / "out"), "--no-plot"))
    assert code == 0 and line in out.splitlines(), err
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["bag"]["verdict"]["caveats"] == [
        f"{rejected} of {n} commands were rejected (frame 'base_link')"]
    clean = bag_summary.summarize_run(analysis.load_run(_write(runs[True], tmp_path / "clean.mcap"), cfg), cfg)
    assert clean["bag"]["verdict"] == {"data_ends_s": None, "caveats": []}
    assert "SAFE: no non-slacked constraint violated" in format_summary(clean).splitlines()


def test_verdict_qualifiers_count_with_thousands_separators() -> None:
    bag = {"commands": {"received": 2000, "rejected": 900, "reason": "frame 'base_link'", "missing": 1200,
                        "answered": 2001}, "run": {"deadline_misses": 3}, "truncated": True, "data_ends_s": 1004.0}
    verdict = bag_summary.verdict_qualifiers(bag, 2000)
    assert verdict == {"data_ends_s": 1004.0, "caveats": [
        "900 of 2,000 commands were rejected (frame 'base_link')",
        "1,200 of 2,001 states were answered without a command (u_des = 0)",
        "3 of 2,000 steps missed their command deadline (the plant's fallback was applied)"]}


def _cli(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "rta_attitude.cli", *args], cwd=REPO, env=ENV, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def test_cli_bad_and_truncated_bags(bags: dict[str, Path], tmp_path: Path) -> None:
    """One clear line naming the file and the problem, exit 1, no traceback; truncated: exit 0 and
    the report says where the data stops. The subprocesses run in parallel."""
    expected = {
        "foreign": "not an rta_attitude run: no sensor_msgs/msg/JointState 'state' topic "
                   "(topics: /chatter (std_msgs/msg/String))",
        "empty": "empty file (0 bytes)",
        "text": "not an MCAP file (bad magic bytes)",
        "missing": "no such file",
    }
    procs = {case: _cli("analyze", str(bags[case]), "--out", str(tmp_path / case), "--no-plot")
             for case in [*expected, "truncated"]}
    procs["ros_free"] = subprocess.Popen(
        [sys.executable, "-c", "import sys, rta_attitude.recording.analysis; "
                               "ros = sorted(m for m in sys.modules if m.startswith(('rclpy', 'rosidl'))); "
                               "print(ros); sys.exit(1 if ros else 0)"],
        cwd=REPO, env=ENV, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    results = {case: (p.wait(timeout=120), *p.communicate()) for case, p in procs.items()}
    for case, message in expected.items():
        code, out, err = results[case]
        assert code == 1, (case, out, err)
        assert err == f"ERROR: {bags[case]}: {message}\n", case
        assert "Traceback" not in out + err
    code, out, err = results["truncated"]
    assert code == 0, err
    summary = json.loads((tmp_path / "truncated" / "summary.json").read_text())
    assert summary["bag"]["truncated"]
    assert f"bag truncated: data ends at t = {summary['bag']['data_ends_s']:.1f} s" in out
    assert f"SAFE up to t = {summary['bag']['data_ends_s']:,.0f} s (bag truncated): no non-slacked constraint " \
        "violated" in out.splitlines() and "Traceback" not in err
    assert results["ros_free"][0] == 0, results["ros_free"]


def test_load_run_errors(bags: dict[str, Path], tmp_path: Path, cfg: Any) -> None:
    with pytest.raises(BagError, match="no /other/state topic"):
        analysis.load_run(bags["rta"], cfg, namespace="/other")
    (tmp_path / "dir").mkdir()
    with pytest.raises(BagError, match=r"bag directory with no \.mcap file"):
        analysis.load_run(tmp_path / "dir", cfg)
    with BagWriter(tmp_path / "states_only.mcap") as bag:
        bag.add_topic("/rta/state", "sensor_msgs/msg/JointState")
        bag.add_topic("/rta/torque_cmd", "geometry_msgs/msg/Vector3Stamped")
        bag.write_message("/rta/state", {"header": {"stamp": {"sec": 0}}, "name": ["q1"], "position": [1.0]}, 0)
    with pytest.raises(BagError, match="does not name the 19 state entries"):
        analysis.load_run(tmp_path / "states_only.mcap", cfg)


# ----------------------------------------------------------------------------- CLI, compare, figure


def test_analyze_compare_writes_summaries_table_and_figure(bags: dict[str, Path], runs: dict[bool, Run],
                                                           tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert cli_main(["analyze", str(bags["rta"]), "--compare", str(bags["no_rta"]), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    a = json.loads((out / "summary.json").read_text())
    b = json.loads((out / "summary_compare.json").read_text())
    assert _without_bag(a) == json.loads(json.dumps(runs[True].summary))
    assert _without_bag(b) == json.loads(json.dumps(runs[False].summary))
    rows = {r["quantity"]: r for r in json.loads((out / "comparison.json").read_text())["rows"]}
    assert rows["safe"]["a"] is True and rows["safe"]["b"] is False
    om = rows["omega_x min h [rad^2/s^2]"]
    assert om["b_minus_a"] == pytest.approx(om["b"] - om["a"]) and om["b"] < 0 < om["a"]
    assert "A: RTA on (robust)" in text and "B: RTA off" in text and "UNSAFE: " in text
    assert (out / "figure.png").stat().st_size > 50_000
    assert (out / "skymap.png").stat().st_size > 50_000  # both runs, one panel each (recording.skymap)
    with np.load(out / "timeseries.npz") as z:
        np.testing.assert_array_equal(z["x"], runs[True].traj.x)


def test_analyze_animates_the_scene_of_the_first_bag(bags: dict[str, Path], tmp_path: Path) -> None:
    """`--animate`: scene.gif in --out with the frames asked (read back by Pillow); a name that is no
    animation format is one line and exit 1, before anything is written."""
    from PIL import Image

    out = tmp_path / "out"
    assert cli_main(["analyze", str(bags["rta"]), "--out", str(out), "--no-plot", "--animate", "--frames", "3"]) == 0
    with Image.open(out / "scene.gif") as im:
        assert im.n_frames == 3
    proc = _cli("analyze", str(bags["rta"]), "--out", str(tmp_path / "bad"), "--no-plot", "--animate", "scene.txt")
    code, (_stdout, err) = proc.wait(timeout=120), proc.communicate()
    assert code == 1 and err.startswith("ERROR: animation format must be one of gif, mp4") and err.count("\n") == 1
    assert not (tmp_path / "bad" / "scene.txt").exists()


def test_fast_cdr_reader_matches_the_generic_decoder(bags: dict[str, Path]) -> None:
    """analysis reads raw CDR itself (6x faster on filter_status); mcap_ros2's decoder must agree."""
    from rta_attitude.recording.bag import read_bag

    raw = analysis._collect(read_bag(bags["rta"], decode=False), NS, bags["rta"])
    decoded = analysis._collect(read_bag(bags["rta"], decode=True), NS, bags["rta"])
    for name in ("torque_des", "torque_cmd", "torque_applied", "states"):
        a, b = getattr(raw, name), getattr(decoded, name)
        assert a.keys() == b.keys() and len(a) > 100
        assert all(np.array_equal(a[k], b[k]) for k in a)
    assert raw.status == decoded.status and raw.run_status == decoded.run_status and len(raw.status) > 100
    with pytest.raises(analysis.CdrError):
        analysis._raw("state", b"\x00\x02\x00\x00" + bytes(40))  # encapsulation the fast reader does not take
