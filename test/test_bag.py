"""rta_attitude.recording.bag: rosbag2-convention MCAP files, checked against independent readers.

Real files in tmp_path, no mocks. rclpy is imported only for its generated message classes and
rclpy.serialization (no context, no node, so no DDS traffic); discovery is still limited to the
host in case another test in the session creates nodes.
"""

from __future__ import annotations

import array
import dataclasses
import importlib
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rta_attitude.errors import BagError
from rta_attitude.recording.bag import (
    BagWriter,
    Qos,
    message_counts,
    message_definition,
    offered_qos_yaml,
    read_bag,
    topics,
    type_hash,
    write_metadata_yaml,
)

# Set before rclpy is first imported (importlib below, so imports above stay at the top).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
deserialize_message = importlib.import_module("rclpy.serialization").deserialize_message
Time = importlib.import_module("builtin_interfaces.msg").Time
_diagnostic = importlib.import_module("diagnostic_msgs.msg")
DiagnosticArray, DiagnosticStatus, KeyValue = (
    _diagnostic.DiagnosticArray,
    _diagnostic.DiagnosticStatus,
    _diagnostic.KeyValue,
)
Vector3Stamped = importlib.import_module("geometry_msgs.msg").Vector3Stamped
Odometry = importlib.import_module("nav_msgs.msg").Odometry
Clock = importlib.import_module("rosgraph_msgs.msg").Clock
JointState = importlib.import_module("sensor_msgs.msg").JointState

TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/rta/state": "sensor_msgs/msg/JointState",
    "/rta/torque_cmd": "geometry_msgs/msg/Vector3Stamped",
    "/rta/filter_status": "diagnostic_msgs/msg/DiagnosticArray",
    "/rta/odom": "nav_msgs/msg/Odometry",
}
CLASSES = {
    "/clock": Clock,
    "/rta/state": JointState,
    "/rta/torque_cmd": Vector3Stamped,
    "/rta/filter_status": DiagnosticArray,
    "/rta/odom": Odometry,
}
STEPS = 20
DT_NS = 10_000_000  # 10 ms control step


def _stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def _messages(steps: int = STEPS) -> list[tuple[str, Any, int]]:
    """(topic, rclpy message, log time [ns]) for `steps` control steps, odd values included."""
    out: list[tuple[str, Any, int]] = []
    for k in range(steps):
        t = 1_700_000_000_000_000_000 + k * DT_NS
        out.append(("/clock", Clock(clock=_stamp(t)), t))
        state = JointState(name=["q1", "q2", "omega_x"], position=[0.1 * k, -2.5, 1e-9 * k])
        state.velocity = [float(k)]  # arrays of different lengths
        state.header.stamp, state.header.frame_id = _stamp(t), "hill"
        out.append(("/rta/state", state, t))
        torque = Vector3Stamped()
        torque.header.stamp, torque.header.frame_id = _stamp(t), "body"
        torque.vector.x, torque.vector.y, torque.vector.z = 1e-3 * k, -0.5, float("inf")
        out.append(("/rta/torque_cmd", torque, t))
        status = DiagnosticStatus(level=bytes([k % 3]), name="keep_out", message="ok" * (k % 2))
        status.values = [KeyValue(key="h", value=f"{0.25 * k:.6g}"), KeyValue(key="é", value="")]
        diag = DiagnosticArray(status=[status, DiagnosticStatus(name="sun")])
        diag.header.stamp = _stamp(t)
        out.append(("/rta/filter_status", diag, t))
        odom = Odometry(child_frame_id="body")
        odom.header.stamp, odom.header.frame_id = _stamp(t), "hill"
        odom.pose.pose.orientation.w = 1.0
        odom.pose.covariance[::7] = 1e-4 * (k + 1)  # numpy float64[36]
        odom.twist.twist.angular.z = -0.01 * k
        out.append(("/rta/odom", odom, t))
    return out


def _write(path: Path, msgs: list[tuple[str, Any, int]], **kwargs: Any) -> None:
    with BagWriter(path, **kwargs) as bag:
        for topic, type_name in TYPES.items():
            bag.add_topic(topic, type_name, qos=Qos(depth=1) if topic == "/clock" else Qos())
        for topic, msg, t in msgs:
            bag.write_message(topic, msg, t)


def _plain(value: Any) -> Any:
    """Comparable form of a message from rclpy, rosbags or mcap_ros2: nested dicts and lists."""
    if isinstance(value, bytes) and len(value) == 1:
        return value[0]  # rclpy `byte` field; the decoders give an int
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (np.ndarray, array.array, list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "get_fields_and_field_types"):  # rclpy
        names = list(value.get_fields_and_field_types())
    elif dataclasses.is_dataclass(value):  # rosbags
        names = [f.name for f in dataclasses.fields(value)]
    else:  # mcap_ros2
        names = list(value.__slots__)
    # ROS field names are lower case; rosbags adds UPPER_CASE constants and __msgtype__
    return {n: _plain(getattr(value, n)) for n in names if n.islower() and n[0] != "_"}


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bag") / "run_0.mcap"
    _write(path, _messages())
    return path


def test_definition_follows_rosbag2() -> None:
    text = message_definition("nav_msgs/msg/Odometry")
    sections = text.split("\n" + "=" * 80 + "\n")
    names = [s.splitlines()[0] for s in sections[1:]]
    assert names == [
        "MSG: geometry_msgs/PoseWithCovariance",
        "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion",
        "MSG: geometry_msgs/TwistWithCovariance",
        "MSG: geometry_msgs/Twist",
        "MSG: geometry_msgs/Vector3",
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
    ]
    assert sections[0] == (Path(sys.prefix) / "share/nav_msgs/msg/Odometry.msg").read_text()
    assert message_definition("sensor_msgs/JointState") == message_definition("sensor_msgs/msg/JointState")
    with pytest.raises(BagError, match=r"no \.msg file"):
        message_definition("no_such_msgs/msg/Thing")
    with pytest.raises(BagError, match="not a message type name"):
        message_definition("JointState")


def test_type_hash_matches_rosbags_hash_of_our_definition() -> None:
    for type_name in TYPES.values():
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(message_definition(type_name), type_name))
        assert type_hash(type_name).startswith("RIHS01_")
        assert type_hash(type_name) == store.hash_rihs01(type_name)
    assert type_hash("no_such_msgs/msg/Thing") == ""


def test_qos_yaml_is_rosbag2_v9() -> None:
    text = offered_qos_yaml([Qos(depth=1, reliability="best_effort")])
    assert text.startswith("- history: keep_last\n  depth: 1\n  reliability: best_effort\n")
    assert text.endswith("  avoid_ros_namespace_conventions: false")
    assert offered_qos_yaml([]) == "[]"
    with pytest.raises(BagError, match="reliability"):
        Qos(reliability="sometimes")


def test_mcap_records_follow_rosbag2(bag: Path) -> None:
    with bag.open("rb") as f:
        reader = make_reader(f)
        header, summary = reader.get_header(), reader.get_summary()
        records = list(reader.iter_metadata())
    assert header.profile == "ros2"
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 5 * STEPS
    by_topic = {c.topic: c for c in summary.channels.values()}
    assert set(by_topic) == set(TYPES)
    for topic, channel in by_topic.items():
        schema = summary.schemas[channel.schema_id]
        assert (schema.name, schema.encoding) == (TYPES[topic], "ros2msg")
        assert schema.data.decode() == message_definition(TYPES[topic])
        assert channel.message_encoding == "cdr"
        assert channel.metadata["topic_type_hash"] == type_hash(TYPES[topic])
        assert channel.metadata["offered_qos_profiles"].startswith("- history: keep_last\n")
        assert summary.statistics.channel_message_counts[channel.id] == STEPS
    assert all(c.compression in ("zstd", "lz4", "") for c in summary.chunk_indexes)
    assert [r.name for r in records] == ["rosbag2"]
    assert "version: 9\n" in records[0].metadata["serialized_metadata"]
    with bag.open("rb") as f:  # every chunk CRC verifies
        assert sum(1 for _ in StreamReader(f, validate_crcs=True).records) > 0


def test_rosbags_reads_lone_mcap(bag: Path) -> None:
    originals = _messages()
    with Reader(bag) as reader:
        assert reader.message_count == 5 * STEPS
        assert {c.topic: c.msgcount for c in reader.connections} == dict.fromkeys(TYPES, STEPS)
        assert {c.topic: c.msgtype for c in reader.connections} == TYPES
        clock = next(c for c in reader.connections if c.topic == "/clock")
        assert clock.ext.offered_qos_profiles[0].depth == 1
    with AnyReader([bag]) as reader:
        got = [(c.topic, t, _plain(reader.deserialize(raw, c.msgtype))) for c, t, raw in reader.messages()]
    assert got == [(topic, t, _plain(msg)) for topic, msg, t in originals]


def test_rosbags_reads_bag_directory_and_checks_hashes(bag: Path, tmp_path: Path) -> None:
    """rosbag2 directory layout: <dir>/metadata.yaml + <dir>/run_0.mcap."""
    directory = tmp_path / "run"
    directory.mkdir()
    shutil.copy(bag, directory / bag.name)
    assert write_metadata_yaml(directory / bag.name) == directory / "metadata.yaml"
    with AnyReader([directory]) as reader:  # AnyReader compares RIHS01 hashes with definitions
        assert reader.message_count == 5 * STEPS
        assert {c.topic: c.digest for c in reader.connections} == {t: type_hash(n) for t, n in TYPES.items()}
        assert sum(1 for _ in reader.messages()) == 5 * STEPS


def test_read_bag_decodes_everything(bag: Path) -> None:
    originals = _messages()
    contents = read_bag(bag)
    assert not contents.truncated
    assert contents.topics == TYPES
    assert contents.counts == dict.fromkeys(TYPES, STEPS)
    assert contents.last_time_ns == originals[-1][2]
    assert [(m.topic, m.log_time_ns, m.publish_time_ns) for m in contents.messages] == [
        (topic, t, t) for topic, _, t in originals
    ]
    assert [_plain(m.message) for m in contents.messages] == [_plain(m) for _, m, _ in originals]
    assert contents.messages[1].message.header.stamp.sec == 1_700_000_000
    assert contents.messages[1].type_name == "sensor_msgs/msg/JointState"
    assert topics(bag) == TYPES
    assert message_counts(bag) == dict.fromkeys(TYPES, STEPS)
    assert read_bag(bag, topics=["/clock"]).counts == {"/clock": STEPS}
    assert read_bag(bag, decode=False).messages[0].message is None


def test_mcap_generic_reader_decodes(bag: Path) -> None:
    """What Foxglove-style tools do: a seeking reader with the ros2msg/cdr decoder."""
    with bag.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [(ch.topic, msg) for _, ch, _, msg in reader.iter_decoded_messages()]
    assert len(decoded) == 5 * STEPS
    assert decoded[-1][1].pose.covariance[7] == pytest.approx(1e-4 * STEPS)


def test_byte_identical_files(tmp_path: Path) -> None:
    """Same messages and same file name (the rosbag2 record names the file) -> same bytes."""
    first, second = tmp_path / "1" / "run_0.mcap", tmp_path / "2" / "run_0.mcap"
    for path in (first, second):
        path.parent.mkdir()
        _write(path, _messages())
    assert first.read_bytes() == second.read_bytes()


def test_rclpy_deserializes_our_cdr(bag: Path) -> None:
    originals = _messages()
    for got, (topic, msg, _) in zip(read_bag(bag, decode=False).messages, originals, strict=True):
        assert deserialize_message(got.data, CLASSES[topic]) == msg


def test_dict_and_raw_writes(tmp_path: Path) -> None:
    state = JointState(name=["a"], position=[1.5])
    state.header.stamp = _stamp(5)
    with BagWriter(tmp_path / "ref.mcap") as ref:
        ref.add_topic("/s", "sensor_msgs/msg/JointState")
        ref.write_message("/s", state, 5)
    raw = read_bag(tmp_path / "ref.mcap").messages[0].data
    path = tmp_path / "d.mcap"
    with BagWriter(path) as bag:
        bag.add_topic("/s", "sensor_msgs/msg/JointState")
        bag.add_topic("/s", "sensor_msgs/JointState")  # same again: no-op
        as_dict = {"header": {"stamp": {"sec": 0, "nanosec": 5}}, "name": ["a"], "position": [1.5]}
        bag.write_message("/s", as_dict, 5)  # missing fields take their defaults
        bag.write("/s", raw, 6, publish_time_ns=4)
        with pytest.raises(BagError, match="already has type"):
            bag.add_topic("/s", "geometry_msgs/msg/Vector3Stamped")
        with pytest.raises(BagError, match="not added"):
            bag.write("/nope", b"", 7)
        with pytest.raises(BagError, match="Vector3Stamped written to /s"):
            bag.write_message("/s", Vector3Stamped(), 7)
        with pytest.raises(BagError, match="not an integer ns"):
            bag.write("/s", b"", -1)
    bag.close()  # idempotent
    with pytest.raises(BagError, match="closed"):
        bag.write("/s", b"", 8)
    messages = read_bag(path).messages
    assert messages[0].data == raw
    assert (messages[1].log_time_ns, messages[1].publish_time_ns) == (6, 4)
    with pytest.raises(BagError, match="file exists"):
        BagWriter(path)
    BagWriter(path, overwrite=True).close()
    assert read_bag(path).messages == []


def test_missing_empty_and_foreign_files(tmp_path: Path) -> None:
    empty, foreign = tmp_path / "empty.mcap", tmp_path / "notes.mcap"
    empty.write_bytes(b"")
    foreign.write_text("time,value\n0,1\n")
    cases = {
        tmp_path / "missing.mcap": "no such file",
        empty: "empty file",
        foreign: "not an MCAP file",
        tmp_path: "is a directory",
    }
    for path, problem in cases.items():
        for call in (read_bag, topics, message_counts):
            with pytest.raises(BagError, match=problem) as info:
                call(path)
            message = str(info.value)
            assert "\n" not in message and str(path) in message


def test_truncated_file_reads_complete_chunks(tmp_path: Path) -> None:
    originals = _messages(200)
    whole, cut = tmp_path / "whole.mcap", tmp_path / "cut.mcap"
    _write(whole, originals, chunk_size=8 * 1024)
    data = whole.read_bytes()
    cut.write_bytes(data[: int(0.6 * len(data))])
    contents = read_bag(cut)
    n = len(contents.messages)
    assert contents.truncated
    assert 0.3 * len(originals) < n < len(originals)
    assert [_plain(m.message) for m in contents.messages] == [_plain(m) for _, m, _ in originals[:n]]
    assert contents.last_time_ns == originals[n - 1][2]
    assert sum(message_counts(cut).values()) == n
    assert topics(cut) == TYPES
    with pytest.raises(BagError, match="no rosbag2 metadata record"):
        write_metadata_yaml(cut)


def test_killed_writer_loses_at_most_the_last_chunk(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    script = textwrap.dedent(
        f"""
        import os, signal
        from rta_attitude.recording.bag import BagWriter
        bag = BagWriter({str(path)!r}, chunk_size=4096)
        bag.add_topic("/v", "geometry_msgs/msg/Vector3Stamped")
        for k in range(1000):
            bag.write_message("/v", {{"vector": {{"x": float(k)}}}}, k)
        os.kill(os.getpid(), signal.SIGKILL)
        """
    )
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, "-c", script], env=env, check=False, timeout=120)
    assert result.returncode == -9
    contents = read_bag(path)
    assert contents.truncated
    xs = [m.message.vector.x for m in contents.messages]
    assert xs == [float(k) for k in range(len(xs))]
    assert 1000 - len(xs) <= 4096 // 60  # at most one 4 KiB chunk of ~60-byte records lost
    assert contents.last_time_ns == len(xs) - 1
