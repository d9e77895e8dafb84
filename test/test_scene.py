"""rta_attitude.recording.scene: the attitude scene against closed forms written here, and its animation.

The oracles do not call the package's attitude code: A(q) by Rodrigues' formula from the quaternion's
axis and angle (scalar last, A maps Hill to body, so a body vector b reads A^T b in Hill and body axis i is
row i), the sun r_S = [cos beta cos theta_S, cos beta sin theta_S, sin beta], the Earth -x_H, a vector fixed
in the inertial frame R_z(theta_S) v, angles atan2(|a x b|, a . b), margins theta - alpha (keep_out) and
alpha - theta (keep_in). The animation is read back with Pillow (frame count, size).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from helpers import random_states

from rta_attitude import config
from rta_attitude.config.schema import PointingConstraint
from rta_attitude.errors import RtaError
from rta_attitude.recording import scene as scene_module

TOL = 1e-9
EARTH = np.array([-1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def cfg() -> Any:
    return config.load()


def with_cones(cfg: Any, *cones: PointingConstraint, beta_deg: float = 0.0) -> Any:
    """cfg with more pointing constraints (each a group of the first priority level) and the sun's beta angle."""
    levels = cfg.filter.priorities
    levels = (levels[0] + tuple(c.name for c in cones), *levels[1:]) if levels else levels
    return dataclasses.replace(cfg, pointing=cfg.pointing + cones,
                               filter=dataclasses.replace(cfg.filter, priorities=levels),
                               environment=dataclasses.replace(cfg.environment, sun_beta_rad=math.radians(beta_deg)))


def star_tracker(cfg: Any, **kw: Any) -> PointingConstraint:
    """A third cone: -k_B kept 30 deg off the Earth."""
    return PointingConstraint(**{"name": "star_tracker", "kind": "keep_out", "boresight_body": (0.0, 0.0, -1.0),
                                 "target": "earth", "half_angle_rad": math.radians(30), "gains": cfg.pointing[0].gains,
                                 **kw})


def _rodrigues(q: np.ndarray) -> np.ndarray:
    """A(q), Hill -> body: the rotation of the frame by angle phi = 2 atan2(|v|, q4) about e = v / |v|:
    A = cos(phi) I + (1 - cos(phi)) e e^T - sin(phi) [e x]."""
    v, q4 = q[:3], q[3]
    s = np.linalg.norm(v)
    if s == 0.0:
        return np.eye(3)
    e, phi = v / s, 2.0 * np.arctan2(s, q4)
    cross = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
    return np.cos(phi) * np.eye(3) + (1.0 - np.cos(phi)) * np.outer(e, e) - np.sin(phi) * cross


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def _sun(theta: float, beta: float = 0.0) -> np.ndarray:
    return np.array([np.cos(beta) * np.cos(theta), np.cos(beta) * np.sin(theta), np.sin(beta)])


def _run(x: np.ndarray, rta: bool = True) -> Any:
    n = len(x) - 1
    return SimpleNamespace(t_s=np.arange(n + 1, dtype=float), x=x, u_des=np.zeros((n, 3)), u=np.zeros((n, 3)),
                           rta=rta)


def test_scene_vectors_angles_and_margins_against_rodrigues(cfg: Any) -> None:
    x = random_states(np.random.default_rng(17), 300, cfg)
    sc = scene_module.scene(_run(x), cfg)
    assert [(c.name, c.kind, c.target) for c in sc.cones] == [("exclusion_zone", "keep_out", "sun"),
                                                              ("communication", "keep_in", "earth")]
    assert sc.cones[0].half_angle_rad == pytest.approx(np.radians(60.0 / 2 + 10.0), abs=1e-15)  # FOV/2 + buffer
    assert sc.cones[1].half_angle_rad == pytest.approx(np.radians(180.0 / 2), abs=1e-15)
    for k in range(len(x)):
        A = _rodrigues(x[k, 0:4] / np.linalg.norm(x[k, 0:4]))
        sun = _sun(x[k, 12])
        np.testing.assert_allclose(sc.body_axes[k], A, atol=TOL)
        np.testing.assert_allclose(sc.panel[k], A[2], atol=TOL)  # +k_B
        np.testing.assert_allclose(sc.sun[k], sun, atol=TOL)
        for cone, b, target, sign, half in ((sc.cones[0], A[0], sun, 1.0, np.radians(40.0)),  # +i_B off the sun
                                            (sc.cones[1], A[1], EARTH, -1.0, np.radians(90.0))):  # +j_B to the Earth
            np.testing.assert_allclose(cone.boresight[k], b, atol=TOL)
            np.testing.assert_allclose(cone.target_hill[k], target, atol=TOL)
            theta = _angle(b, target)
            assert abs(cone.angle_rad[k] - theta) < TOL
            assert abs(cone.margin_rad[k] - sign * (theta - half)) < TOL
    np.testing.assert_allclose(sc.earth, EARTH, atol=0.0)
    assert all(c.applies.all() for c in sc.cones)
    assert not sc.intervened.any()


def test_a_third_cone_has_its_own_boresight_target_and_windowed_margin(cfg: Any) -> None:
    other = with_cones(cfg, star_tracker(cfg, windows_s=((3.0, 6.0),)))
    x = random_states(np.random.default_rng(4), 10, cfg)
    sc = scene_module.scene(_run(x), other)
    assert [c.name for c in sc.cones] == ["exclusion_zone", "communication", "star_tracker"]
    cone = sc.cones[2]
    inside = (np.arange(10) >= 3) & (np.arange(10) <= 6)
    np.testing.assert_array_equal(cone.applies, inside)
    assert np.all(np.isposinf(cone.margin_rad[~inside]))  # nothing to keep outside its windows
    for k in range(len(x)):
        A = _rodrigues(x[k, 0:4] / np.linalg.norm(x[k, 0:4]))
        np.testing.assert_allclose(cone.boresight[k], -A[2], atol=TOL)  # -k_B in Hill
        np.testing.assert_allclose(cone.target_hill[k], EARTH, atol=TOL)
        theta = _angle(-A[2], EARTH)
        assert abs(cone.angle_rad[k] - theta) < TOL
        if inside[k]:
            assert abs(cone.margin_rad[k] - (theta - np.radians(30.0))) < TOL
    assert scene_module.target_owners(sc.cones) == [0, 1, 1]  # the Earth is drawn once, with communication
    assert scene_module.cone_text(cone, 0).endswith("(outside its windows)")
    assert scene_module.cone_text(cone, 4).endswith("(>= 30.0 deg)")


def test_targets_of_every_kind_with_the_sun_out_of_the_orbit_plane(cfg: Any) -> None:
    v_inertial = np.array([0.6, 0.0, 0.8])
    cones = (PointingConstraint(name="radiator", kind="keep_out", boresight_body=(0.0, -1.0, 0.0), target="sun",
                                half_angle_rad=0.5, gains=cfg.pointing[0].gains),
             PointingConstraint(name="solar_array", kind="keep_in", boresight_body=(0.6, 0.0, 0.8),
                                target="inertial", target_vector=tuple(v_inertial), half_angle_rad=1.0,
                                gains=cfg.pointing[0].gains),
             PointingConstraint(name="gps", kind="keep_in", boresight_body=(0.0, 0.0, 1.0), target="orbit_normal",
                                half_angle_rad=1.2, gains=cfg.pointing[0].gains),
             PointingConstraint(name="ram", kind="keep_out", boresight_body=(1.0, 0.0, 0.0), target="velocity",
                                half_angle_rad=0.3, gains=cfg.pointing[0].gains),
             PointingConstraint(name="fixed", kind="keep_out", boresight_body=(0.0, 1.0, 0.0), target="hill",
                                target_vector=(0.0, 0.6, -0.8), half_angle_rad=0.2, gains=cfg.pointing[0].gains))
    other = with_cones(cfg, *cones, beta_deg=23.0)
    beta = np.radians(23.0)
    x = random_states(np.random.default_rng(8), 20, cfg)
    sc = scene_module.scene_of_states(np.arange(20.0), x, other)
    assert scene_module.target_owners(sc.cones) == [0, 1, 0, 3, 4, 5, 6]  # the second sun cone shares the arrow
    for k in range(len(x)):
        th = x[k, 12]
        c, s = np.cos(th), np.sin(th)
        want = {"sun": _sun(th, beta), "earth": EARTH, "inertial": np.array([c * 0.6, s * 0.6, 0.8]),
                "orbit_normal": np.array([0.0, 0.0, 1.0]), "velocity": np.array([0.0, 1.0, 0.0]),
                "hill": np.array([0.0, 0.6, -0.8])}
        A = _rodrigues(x[k, 0:4] / np.linalg.norm(x[k, 0:4]))
        np.testing.assert_allclose(sc.sun[k], want["sun"], atol=TOL)
        for cone in sc.cones:
            np.testing.assert_allclose(cone.target_hill[k], want[cone.target], atol=TOL)
            b = A.T @ np.asarray(cone.boresight_body)
            np.testing.assert_allclose(cone.boresight[k], b, atol=TOL)
            sign = -1.0 if cone.keep_in else 1.0
            assert abs(cone.margin_rad[k] - sign * (_angle(b, want[cone.target]) - cone.half_angle_rad)) < TOL


def test_cone_generators_and_rim_are_at_the_half_angle() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        half = rng.uniform(0.05, 1.5)
        lines = scene_module.cone_lines(axis, half, length=0.7, lines=12)
        assert lines.shape == (13, 65, 3)
        for seg in lines[:-1]:
            assert np.allclose(seg[0], 0.0) and abs(np.linalg.norm(seg[-1]) - 0.7) < 1e-12
            assert abs(_angle(seg[-1], axis) - half) < 1e-12
        assert all(abs(_angle(p, axis) - half) < 1e-12 for p in lines[-1])


def test_margin_colours_and_frame_picks() -> None:
    warn = np.radians(5.0)
    levels = scene_module.margin_level(np.array([-1e-9, 0.0, warn - 1e-9, warn, 1.0, np.inf]), warn)
    assert levels.tolist() == [2, 1, 1, 0, 0, 0]
    for samples, frames in ((2001, 200), (11, 200), (2, 2), (101, 7), (5, 4)):
        picks = scene_module.frame_samples(samples, frames)
        assert picks[0] == 0 and picks[-1] == samples - 1 and len(picks) <= frames
        assert all(b > a for a, b in itertools.pairwise(picks))
        assert len(picks) == min(samples, frames)
        steps = np.diff(picks)
        assert steps.max() - steps.min() <= 1  # evenly spread


def test_animation_is_a_gif_with_the_frames_asked_and_bad_names_are_one_error(cfg: Any, tmp_path: Path) -> None:
    from PIL import Image

    x = random_states(np.random.default_rng(5), 9, cfg)
    other = with_cones(cfg, star_tracker(cfg, windows_s=((2.0, 5.0),)))
    path = scene_module.animate_scene(_run(x), other, tmp_path / "scene.gif", "random", frames=4, progress=False)
    with Image.open(path) as im:
        assert im.n_frames == 4 and im.size == (round(6.4 * scene_module.DPI), round(6.8 * scene_module.DPI))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.gif"]  # no temporary file left
    with pytest.raises(RtaError, match="animation format"):
        scene_module.animate_scene(_run(x), cfg, tmp_path / "scene.txt", frames=4, progress=False)
    with pytest.raises(RtaError, match="at least 2 frames"):
        scene_module.animate_scene(_run(x), cfg, tmp_path / "scene.gif", frames=1, progress=False)
