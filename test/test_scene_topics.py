"""The attitude scene as ROS topics (scene_node: scene/transform, scene/markers), checked from a real
recorded bag decoded by rosbags against closed forms written here (not the package's geometry):

- the transform's rotation (scipy's quaternion convention) maps each body axis to the Hill direction
  that the paper's attitude matrix A(q) of the recorded state gives;
- each pointing constraint's boresight arrow makes with its target's arrow the angle of the state (q and
  theta_S): the exclusion zone's +i_B to the sun, the communication's +j_B to the Earth, to 1e-9;
- every point of each cone lies at its configured half-angle (read from the YAML) from its target's arrow;
- the boresights are coloured by their margins, and the text names the filter status of its own step and
  each cone's angle, in lines of at most 60 characters;
- every topic the Foxglove layout names is in the bag (except /diagnostics, a live-only topic).
And, without ROS, the marker builder's cones and poses against scipy, and its bytes for a configuration with a
third, windowed cone decoded by rosbags and by rclpy.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

from rta_attitude import topics
from rta_attitude.dynamics.state import STATE_NAMES

ROOT = Path(__file__).resolve().parents[1]
NS = topics.DEFAULT_NAMESPACE
POINTING = yaml.safe_load((ROOT / "config" / "rta_attitude.yaml").read_text())["/**"]["ros__parameters"][
    "constraints"]["pointing"]
KEEP_OUT_RAD = math.radians(POINTING["exclusion_zone"]["half_angle_deg"])
COMM_RAD = math.radians(POINTING["communication"]["half_angle_deg"])
WARN_RAD = math.radians(5.0)  # the scene_warn_deg default
IDS = {"body": 0, "axis_x": 1, "axis_y": 2, "axis_z": 3, "panel": 4, "text": 5,
       "exclusion_zone/boresight": 10, "exclusion_zone/cone": 11, "exclusion_zone/target": 12,
       "communication/boresight": 13, "communication/cone": 14, "communication/target": 15}
"""The default configuration's marker ids: fixed parts, then 10 + 3 i for cone i (boresight, cone, and the arrow
of a target no earlier cone aims at)."""
ORDER = [0, 1, 2, 3, 4, 10, 11, 12, 13, 14, 15, 5]
"""The markers in the array: by id, the text last (its length varies)."""
GREEN, ORANGE, RED, GREY = (0.2, 0.8, 0.2), (1.0, 0.6, 0.0), (0.9, 0.1, 0.1), (0.6, 0.6, 0.6)
LINE_CHARS = 60


def attitude_matrix(q: np.ndarray) -> np.ndarray:
    """The paper's A(q) (Hill -> body), q = (q1, q2, q3, q4) scalar last:
    (q4^2 - |qv|^2) I + 2 qv qv^T - 2 q4 [qv x]."""
    qv, q4 = q[:3], q[3]
    cross = np.array([[0.0, -qv[2], qv[1]], [qv[2], 0.0, -qv[0]], [-qv[1], qv[0], 0.0]])
    return (q4 * q4 - qv @ qv) * np.eye(3) + 2.0 * np.outer(qv, qv) - 2.0 * q4 * cross


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b))


def vec(p: Any) -> np.ndarray:
    return np.array([p.x, p.y, p.z])


def arrow(marker: Any) -> np.ndarray:
    return vec(marker.points[1]) - vec(marker.points[0])


def pose_points(marker: Any) -> np.ndarray:
    """A marker's points in its header frame (its pose applied; scipy's quaternion convention x y z w)."""
    o = marker.pose.orientation
    return Rotation.from_quat([o.x, o.y, o.z, o.w]).apply(np.array([vec(p) for p in marker.points]))


@pytest.fixture(scope="module", params=[topics.SCENE_RECORDER, topics.SCENE_NODE])
def scene_bag(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A 300 s paper-example over DDS, read by rosbags: the scene hosted by the recorder (the default), and
    the scene node as a process of its own (best-effort readers)."""
    tmp = tmp_path_factory.mktemp("scene")
    bag = tmp / "run.mcap"
    proc = subprocess.run([sys.executable, "-m", "rta_attitude.cli.launch", "--scenario", "paper-example",
                           "--duration", "300", "--bag", str(bag), "--out", str(tmp / "out"), "--scene", request.param],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out: dict[str, Any] = {"mode": request.param, "counts": {}, "state": {}, "status": {}, "transform": {},
                           "markers": {}}
    with AnyReader([bag]) as reader:
        out["counts"] = {c.topic: c.msgcount for c in reader.connections}
        wanted = {f"{NS}/state": "state", f"{NS}/filter_status": "status", f"{NS}/scene/transform": "transform",
                  f"{NS}/scene/markers": "markers"}
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            key = wanted[conn.topic]
            head = msg.markers[0].header if key == "markers" else msg.header
            t_ns = head.stamp.sec * 1_000_000_000 + head.stamp.nanosec
            out[key][t_ns] = msg
    return out


DDS = pytest.mark.dds


def by_id(m: Any) -> dict[int, Any]:
    return {mk.id: mk for mk in m.markers}


def check_text(text: str) -> None:
    """The scene text fits a panel: no line longer than LINE_CHARS, none padded with spaces."""
    for line in text.split("\n"):
        assert len(line) <= LINE_CHARS and line == line.rstrip(), repr(line)


@DDS
def test_every_drawn_state_has_its_transform_and_markers_at_its_stamp(scene_bag: dict[str, Any]) -> None:
    from rta_attitude import config
    from rta_attitude.ros import convert

    assert convert.scene_marker_ids(config.load().pointing) == IDS
    states, tfs, markers = scene_bag["state"], scene_bag["transform"], scene_bag["markers"]
    assert len(states) == 301  # the loop's topics are complete in the bag (the recorder waits for their counts)
    if scene_bag["mode"] == topics.SCENE_RECORDER:  # hosted: drawn from what the recorder holds, all of it
        assert set(markers) == set(tfs) == set(states)
    else:  # a process of its own skips states it cannot keep up with; the recorder closes on the loop's counts
        assert markers and tfs and set(markers) <= set(states) and set(tfs) <= set(states)
    for m in markers.values():
        assert [mk.id for mk in m.markers] == ORDER
        assert {mk.header.frame_id for mk in m.markers} == {topics.HILL_FRAME}
    for tf in tfs.values():
        assert (tf.header.frame_id, tf.child_frame_id) == (topics.HILL_FRAME, topics.BODY_FRAME)


@DDS
def test_transform_maps_body_axes_to_the_hill_directions_of_a_q(scene_bag: dict[str, Any]) -> None:
    q_i = STATE_NAMES.index("q1")
    worst = 0.0
    for t_ns, tf in scene_bag["transform"].items():
        x = np.array(scene_bag["state"][t_ns].position)
        A = attitude_matrix(x[q_i:q_i + 4])
        r = tf.transform.rotation
        R = Rotation.from_quat([r.x, r.y, r.z, r.w])
        for e in np.eye(3):
            worst = max(worst, float(np.abs(R.apply(e) - A.T @ e).max()))
    assert worst < 1e-12


@DDS
def test_boresight_arrows_make_the_constraint_angles_of_the_state(scene_bag: dict[str, Any]) -> None:
    q_i, th_i = STATE_NAMES.index("q1"), STATE_NAMES.index("theta_S")
    colours, with_status = set(), 0
    for t_ns, m in scene_bag["markers"].items():
        x = np.array(scene_bag["state"][t_ns].position)
        A = attitude_matrix(x[q_i:q_i + 4])
        sun = np.array([math.cos(x[th_i]), math.sin(x[th_i]), 0.0])
        theta_ez = angle(A.T @ np.array([1.0, 0.0, 0.0]), sun)  # exclusion_zone: +i_B to the sun
        theta_gs = angle(A.T @ np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0]))  # communication: +j_B, -x_H
        mk = by_id(m)
        assert angle(arrow(mk[IDS["exclusion_zone/target"]]), sun) < 1e-9
        assert angle(arrow(mk[IDS["communication/target"]]), np.array([-1.0, 0.0, 0.0])) < 1e-9
        assert angle(arrow(mk[IDS["exclusion_zone/boresight"]]), arrow(mk[IDS["exclusion_zone/target"]])) == \
            pytest.approx(theta_ez, abs=1e-9)
        assert angle(arrow(mk[IDS["communication/boresight"]]), arrow(mk[IDS["communication/target"]])) == \
            pytest.approx(theta_gs, abs=1e-9)
        assert angle(arrow(mk[IDS["panel"]]), A.T @ np.array([0.0, 0.0, 1.0])) < 1e-9
        for name, margin in (("exclusion_zone", theta_ez - KEEP_OUT_RAD), ("communication", COMM_RAD - theta_gs)):
            want = RED if margin < 0 else ORANGE if margin < WARN_RAD else GREEN
            c = mk[IDS[f"{name}/boresight"]].color
            assert (c.r, c.g, c.b) == pytest.approx(want, abs=1e-6)
            if name == "exclusion_zone":
                colours.add(want)
        status = scene_bag["status"][t_ns]
        qp = next(s for s in status.status if s.name == topics.QP_STATUS_NAME)
        word = next(kv.value for kv in qp.values if kv.key == topics.KEY_STATUS)
        # the status of its own step, or (a best-effort sample lost, e.g. while the reader was still matching
        # the writer at start-up: found by the flake hunt at t = 0) says that it is missing
        text = mk[IDS["text"]].text
        check_text(text)
        assert f"filter {word}" in text or "filter status missing" in text, text
        assert f"exclusion_zone {math.degrees(theta_ez):.1f} deg (>= 40.0 deg)" in text, text
        assert f"communication {math.degrees(theta_gs):.1f} deg (<= 90.0 deg)" in text, text
        with_status += f"filter {word}" in text
    assert GREEN in colours and with_status > 0
    if scene_bag["mode"] == topics.SCENE_RECORDER:  # the recorder holds every status: never missing
        assert with_status == len(scene_bag["markers"])


@DDS
def test_cones_have_the_configured_half_angles_about_their_targets(scene_bag: dict[str, Any]) -> None:
    for m in list(scene_bag["markers"].values())[::25]:
        mk = by_id(m)
        for name, half in (("exclusion_zone", KEEP_OUT_RAD), ("communication", COMM_RAD)):
            pts = pose_points(mk[IDS[f"{name}/cone"]])
            far = pts[np.linalg.norm(pts, axis=1) > 1e-9]  # all but the apex
            assert len(far) > 40
            axis = arrow(mk[IDS[f"{name}/target"]])
            assert max(abs(angle(p, axis) - half) for p in far) < 1e-9


@DDS
def test_every_topic_the_layout_names_is_in_the_bag(scene_bag: dict[str, Any]) -> None:
    layout = json.loads((ROOT / "config" / "foxglove_layout.json").read_text())
    named = set()
    for cfg in layout["configById"].values():
        named |= {cfg[k] for k in ("topicToRender", "topicPath") if k in cfg}
        named |= {t for t, v in cfg.get("topics", {}).items() if v.get("visible", True)}
        named |= {p["value"].split(".")[0] for p in cfg.get("paths", []) if p["value"].startswith("/")}
    assert {f"{NS}/scene/markers", f"{NS}/scene/transform", topics.DIAGNOSTICS} <= named
    counts = scene_bag["counts"]
    missing = sorted(t for t in named - {topics.DIAGNOSTICS} if counts.get(t, 0) == 0)
    assert missing == []


# ----------------------------------------------------------------------------- the builder, without ROS


def test_cone_points_and_poses_against_scipy() -> None:
    from rta_attitude.ros import convert

    rng = np.random.default_rng(5)
    pts = convert.cone_points(0.3, 2.0)
    far = pts[np.linalg.norm(pts, axis=1) > 0]
    assert np.allclose(np.linalg.norm(far, axis=1), 2.0)
    assert max(abs(angle(p, np.array([1.0, 0.0, 0.0])) - 0.3) for p in far) < 1e-12
    for d in [np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), *rng.normal(size=(20, 3))]:
        d = d / np.linalg.norm(d)
        q = convert.x_to(d)
        assert np.linalg.norm(Rotation.from_quat(q).apply([1.0, 0.0, 0.0]) - d) < 1e-12


def three_cones() -> Any:
    """The default configuration with a third cone, -k_B kept 30 deg off the Earth within t in [2, 3] s."""
    from rta_attitude import config
    from rta_attitude.config.schema import PointingConstraint

    cfg = config.load()
    cone = PointingConstraint(name="star_tracker", kind="keep_out", boresight_body=(0.0, 0.0, -1.0), target="earth",
                              half_angle_rad=math.radians(30), gains=cfg.pointing[0].gains, windows_s=((2.0, 3.0),))
    levels = cfg.filter.priorities
    return dataclasses.replace(cfg, pointing=(*cfg.pointing, cone), filter=dataclasses.replace(
        cfg.filter, priorities=levels[:1] and (levels[0] + ("star_tracker",), *levels[1:])))


def test_builder_bytes_decode_with_rosbags_to_the_scene_of_the_state() -> None:
    """The builder writes into serialized templates: decoded by rosbags' own CDR reader (and by rclpy), every
    field it writes holds the scene of the state (closed forms here), the rest is a valid MarkerArray; a third,
    windowed cone has its own boresight and cone (the Earth's arrow is drawn once), grey outside its window."""
    from rclpy.serialization import deserialize_message
    from rosbags.typesys import Stores, get_typestore
    from visualization_msgs.msg import MarkerArray

    from rta_attitude.constraints import ConstraintSet
    from rta_attitude.recording.scene import scene_of_states
    from rta_attitude.ros import convert

    store = get_typestore(Stores.ROS2_JAZZY)
    cfg = three_cones()
    ids = convert.scene_marker_ids(cfg.pointing)
    assert ids == {**IDS, "star_tracker/boresight": 16, "star_tracker/cone": 17}  # the Earth: communication's arrow
    builder = convert.SceneBuilder(cfg.pointing, WARN_RAD)
    cs = ConstraintSet(cfg)
    rng = np.random.default_rng(11)
    x = np.asarray(cfg.scenario("paper-example").x0, dtype=float)
    cut = convert.SceneBuilder.TEXT_BYTES
    texts = ["", "a", "ab", "abc", "t = 3 s   filter solved\nexclusion_zone 52.3 deg (>= 40.0 deg)", "x" * (cut + 9)]
    for k, text in enumerate(texts):
        q = rng.normal(size=4)
        x[:4] = q / np.linalg.norm(q)
        x[STATE_NAMES.index("theta_S")] = rng.uniform(0, 2 * np.pi)
        t_ns = 1_709_337_600_000_000_000 + k * 1_000_000_000 + 7
        tf_raw, mk_raw = builder.build(x[:4], scene_of_states([float(k)], x, cfg, cs), 0, t_ns, text, k % 3)
        tf = store.deserialize_cdr(tf_raw, "geometry_msgs/msg/TransformStamped")
        m = store.deserialize_cdr(mk_raw, "visualization_msgs/msg/MarkerArray")
        assert [mk.id for mk in m.markers] == [*ORDER[:-1], 16, 17, 5]
        mk = by_id(m)
        A = attitude_matrix(x[:4])
        sun = np.array([math.cos(x[12]), math.sin(x[12]), 0.0])
        earth = np.array([-1.0, 0.0, 0.0])
        assert (tf.header.stamp.sec, tf.header.stamp.nanosec) == divmod(t_ns, 1_000_000_000)
        assert all((mm.header.stamp.sec, mm.header.stamp.nanosec) == divmod(t_ns, 1_000_000_000) for mm in m.markers)
        r = tf.transform.rotation
        assert np.abs(Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix() - A.T).max() < 1e-12
        for name, axis in (("axis_x", A[0]), ("axis_y", A[1]), ("panel", A[2]), ("exclusion_zone/boresight", A[0]),
                           ("communication/boresight", A[1]), ("star_tracker/boresight", -A[2]),
                           ("exclusion_zone/target", sun), ("communication/target", earth)):
            assert angle(arrow(mk[ids[name]]), axis) < 1e-12, name
        for name, axis, half in (("exclusion_zone", sun, 40.0), ("communication", earth, 90.0),
                                 ("star_tracker", earth, 30.0)):
            cone = mk[ids[f"{name}/cone"]]
            o = cone.pose.orientation
            assert np.linalg.norm(Rotation.from_quat([o.x, o.y, o.z, o.w]).apply([1.0, 0.0, 0.0]) - axis) < 1e-12
            far = [p for p in pose_points(cone) if np.linalg.norm(p) > 1e-9]
            assert max(abs(angle(p, axis) - math.radians(half)) for p in far) < 1e-9
        shown = mk[IDS["text"]].text
        assert shown == text[:cut]  # at its own length: no padding
        assert deserialize_message(mk_raw, MarkerArray).markers[-1].text == shown  # rclpy reads the same
        for name, margin in (("exclusion_zone", angle(A[0], sun) - math.radians(40.0)),
                             ("communication", math.radians(90.0) - angle(A[1], earth)),
                             ("star_tracker", angle(-A[2], earth) - math.radians(30.0))):
            inside = name != "star_tracker" or 2 <= k <= 3
            want = (RED if margin < 0 else ORANGE if margin < WARN_RAD else GREEN) if inside else GREY
            c = mk[ids[f"{name}/boresight"]].color
            assert (c.r, c.g, c.b) == pytest.approx(want, abs=1e-6), (name, k)
        alpha = mk[ids["star_tracker/cone"]].color.a
        assert alpha == pytest.approx(0.8 if 2 <= k <= 3 else 0.2, abs=1e-6)  # faint outside its window


def test_scene_text_lines_fit_a_panel() -> None:
    from rta_attitude.constraints import ConstraintSet
    from rta_attitude.recording.scene import scene_of_states
    from rta_attitude.ros.scene_node import filter_text, scene_text

    cfg = three_cones()
    x = np.asarray(cfg.scenario("paper-example").x0, dtype=float)
    line, level = filter_text("fallback (prioritize)", "exclusion_zone, communication, star_tracker",
                              ["exclusion_zone", "communication", "star_tracker", "temperature", "battery"])
    assert level == 2
    for t in (0.0, 2.0):
        text = scene_text(t, line, scene_of_states([t], x, cfg, ConstraintSet(cfg)))
        check_text(text)
        words = " ".join(text.split())
        assert "gave way: exclusion_zone, communication, star_tracker" in words
        assert "intervening: exclusion_zone, communication, star_tracker, temperature, battery" in words
        assert ("star_tracker" in text.split("\n")[-1]) and (("outside its windows" in text) == (t == 0.0))


def test_filter_summary_reads_what_the_full_reader_reads() -> None:
    from rclpy.serialization import serialize_message

    from rta_attitude.filter.asif import AsifFilter
    from rta_attitude.recording.cdr import Cdr, read_diagnostics
    from rta_attitude.ros import convert
    from rta_attitude.ros.scene_node import filter_summary, summary_from_values

    cfg = three_cones()
    names = cfg.constraint_names
    f = AsifFilter(cfg)
    rng = np.random.default_rng(3)
    x0 = np.asarray(cfg.scenario("paper-example").x0, dtype=float)
    seen = set()
    for u_des in (np.zeros(3), np.full(3, 50.0), *rng.normal(scale=100.0, size=(30, 3))):
        res = f.filter(x0, u_des)
        raw = serialize_message(convert.filter_status_msg(res, 5, f.counters, "robust", ["communication"]))
        t_ns, *fast = filter_summary(raw, names)
        assert t_ns == 5 and tuple(fast) == summary_from_values(read_diagnostics(Cdr(raw))[1], names)
        seen.add(fast[0].split(" ")[0])
        if fast[2]:
            seen.add("intervening")
    assert {"pass", "solved", "intervening"} <= seen
