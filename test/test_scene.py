"""rta_attitude.recording.scene: the attitude scene against closed forms written here, and its animation.

The oracles do not call the package's attitude code: A(q) by Rodrigues' formula from the quaternion's
axis and angle (scalar last, A maps Hill to body, so body axis i in Hill is row i), the sun
r_S = [cos theta_S, sin theta_S, 0], the Earth -x_H, angles atan2(|a x b|, a . b). The animation is
read back with Pillow (frame count, size).
"""

from __future__ import annotations

import itertools
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from helpers import random_states

from rta_attitude import config
from rta_attitude.errors import RtaError
from rta_attitude.recording import scene as scene_module

TOL = 1e-9


@pytest.fixture(scope="module")
def cfg() -> Any:
    return config.load()


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


def _run(x: np.ndarray, rta: bool = True) -> Any:
    n = len(x) - 1
    return SimpleNamespace(t_s=np.arange(n + 1, dtype=float), x=x, u_des=np.zeros((n, 3)), u=np.zeros((n, 3)),
                           rta=rta)


def test_scene_vectors_and_angles_against_rodrigues(cfg: Any) -> None:
    x = random_states(np.random.default_rng(17), 300, cfg)
    sc = scene_module.scene(_run(x), cfg)
    earth = np.array([-1.0, 0.0, 0.0])
    for k in range(len(x)):
        A = _rodrigues(x[k, 0:4] / np.linalg.norm(x[k, 0:4]))
        sun = np.array([np.cos(x[k, 12]), np.sin(x[k, 12]), 0.0])
        np.testing.assert_allclose(sc.body_axes[k], A, atol=TOL)
        np.testing.assert_allclose(sc.sensor[k], A[0], atol=TOL)  # +i_B
        np.testing.assert_allclose(sc.antenna[k], A[1], atol=TOL)  # +j_B
        np.testing.assert_allclose(sc.panel[k], A[2], atol=TOL)  # +k_B
        np.testing.assert_allclose(sc.sun[k], sun, atol=TOL)
        assert abs(sc.sensor_sun_rad[k] - _angle(A[0], sun)) < TOL
        assert abs(sc.antenna_earth_rad[k] - _angle(A[1], earth)) < TOL
    np.testing.assert_allclose(sc.earth, earth, atol=0.0)
    assert sc.keep_out_rad == pytest.approx(np.radians(60.0 / 2 + 10.0), abs=1e-15)  # FOV/2 + beta
    assert sc.comm_rad == pytest.approx(np.radians(180.0 / 2), abs=1e-15)


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
    levels = scene_module.margin_level(np.array([-1e-9, 0.0, warn - 1e-9, warn, 1.0]), warn)
    assert levels.tolist() == [2, 1, 1, 0, 0]
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
    path = scene_module.animate_scene(_run(x), cfg, tmp_path / "scene.gif", "random", frames=4, progress=False)
    with Image.open(path) as im:
        assert im.n_frames == 4 and im.size == (round(6.4 * scene_module.DPI), round(6.8 * scene_module.DPI))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.gif"]  # no temporary file left
    with pytest.raises(RtaError, match="animation format"):
        scene_module.animate_scene(_run(x), cfg, tmp_path / "scene.txt", frames=4, progress=False)
    with pytest.raises(RtaError, match="at least 2 frames"):
        scene_module.animate_scene(_run(x), cfg, tmp_path / "scene.gif", frames=1, progress=False)
