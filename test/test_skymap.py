"""rta_attitude.recording.skymap: the sun-centred boresight map, against closed forms written here.

The oracles do not call the module under test nor the package's attitude code: A(q) is Markley's
closed form, the sun r_S = [cos theta_S, sin theta_S, 0], the Earth -x_H, angles atan2(|a x b|, a . b),
and the map is inverted by the rule the module states (pole r_S, up z_H, right r_S x z_H, azimuthal
equidistant: a point at rho [deg] (cos phi, sin phi) is the direction at angle rho from the sun,
azimuth phi from `right` towards `up`). Runs are the paper example simulated in process (no DDS).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from helpers import random_states

from rta_attitude import config
from rta_attitude.cli.main import main as cli_main
from rta_attitude.recording import skymap

TOL = 1e-9


@pytest.fixture(scope="module")
def cfg() -> Any:
    return config.load()


# ----------------------------------------------------------------------------- oracles


def _attitude(q: np.ndarray) -> np.ndarray:
    """A(q) (3, 3), Hill -> body, scalar-last: (q4^2 - |v|^2) I + 2 v v^T - 2 q4 [v x] (Markley)."""
    v, q4 = q[:3], q[3]
    cross = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return (q4 * q4 - v @ v) * np.eye(3) + 2.0 * np.outer(v, v) - 2.0 * q4 * cross


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def _sun(theta: float) -> np.ndarray:
    return np.array([np.cos(theta), np.sin(theta), 0.0])


def _frame(theta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, pole) of the stated rule: pole r_S, up z_H, right r_S x z_H = [sin, -cos, 0]."""
    return np.array([np.sin(theta), -np.cos(theta), 0.0]), np.array([0.0, 0.0, 1.0]), _sun(theta)


def _direction(rho: float, phi: float, theta: float) -> np.ndarray:
    """The unit Hill direction at angle rho from the sun and azimuth phi (from right towards up)."""
    right, up, pole = _frame(theta)
    return np.sin(rho) * (np.cos(phi) * right + np.sin(phi) * up) + np.cos(rho) * pole


def _inverse(xy: np.ndarray, theta: float) -> np.ndarray:
    """The Hill direction drawn at map point xy (deg) in the frame of sun angle theta."""
    return _direction(np.radians(np.hypot(*xy)), float(np.arctan2(xy[1], xy[0])), theta)


def _run(x: np.ndarray, u_des: np.ndarray | None = None, u: np.ndarray | None = None, rta: bool = True) -> Any:
    n = len(x) - 1
    u_des = np.zeros((n, 3)) if u_des is None else u_des
    return SimpleNamespace(t_s=np.arange(n + 1, dtype=float), x=x, u_des=u_des, u=u_des.copy() if u is None else u,
                           rta=rta)


@pytest.fixture(scope="module")
def random_run(cfg: Any) -> Any:
    """300 random states (any attitude, any sun angle) plus the poles and anti-poles of both boresights."""
    x = random_states(np.random.default_rng(17), 300, cfg)
    # q = rotation about z_H by a puts +i_B at [cos a, sin a, 0] and +j_B at azimuth a + 90 deg: +i_B at and
    # opposite the sun, +j_B at and opposite the Earth (azimuth 180 deg)
    for k, a in enumerate((x[0, 12], x[1, 12] + np.pi, np.pi / 2, -np.pi / 2)):
        x[k, 0:4] = [0.0, 0.0, np.sin(a / 2), np.cos(a / 2)]
    return _run(x)


# ----------------------------------------------------------------------------- the map against the oracles


def test_sensor_point_is_the_exclusion_angle_from_the_centre_and_maps_back_to_i_B(random_run: Any, cfg: Any) -> None:
    track = skymap.sky_track(random_run, cfg)
    for k, x in enumerate(random_run.x):
        A = _attitude(x[0:4])
        i_B = A[0]  # row 0 of A(q): body axis +i_B in Hill
        theta_EZ = _angle(i_B, _sun(x[12]))
        assert np.radians(np.hypot(*track.sensor[k])) == pytest.approx(theta_EZ, abs=TOL)
        np.testing.assert_allclose(_inverse(track.sensor[k], x[12]), i_B, atol=TOL)
    assert np.degrees(track.sensor_sun_rad).min() < 1e-6 and np.degrees(track.sensor_sun_rad).max() > 180 - 1e-6


def test_antenna_point_is_the_communication_angle_from_the_earth_point(random_run: Any, cfg: Any) -> None:
    track = skymap.sky_track(random_run, cfg)
    earth = np.array([-1.0, 0.0, 0.0])
    for k, x in enumerate(random_run.x):
        j_B = _attitude(x[0:4])[1]
        theta_GS = _angle(j_B, earth)
        e_map, a_map = _inverse(track.earth[k], x[12]), _inverse(track.antenna[k], x[12])
        np.testing.assert_allclose(e_map, earth, atol=TOL)
        assert _angle(a_map, e_map) == pytest.approx(theta_GS, abs=TOL)
        # the Earth is in the orbit plane: on the map's horizontal axis, angle(r_S, -x_H) from the centre
        assert track.earth[k, 1] == pytest.approx(0.0, abs=TOL)
        assert np.radians(abs(track.earth[k, 0])) == pytest.approx(_angle(_sun(x[12]), earth), abs=TOL)


def test_keep_out_circle_and_antenna_limit_are_drawn_at_their_angles(cfg: Any) -> None:
    limits = dataclasses.replace(cfg.limits, exclusion_fov_rad=np.radians(50.0), exclusion_buffer_rad=np.radians(7.5),
                                 comm_fov_rad=np.radians(130.0))
    other = dataclasses.replace(cfg, limits=limits)
    x = random_states(np.random.default_rng(3), 41, cfg)
    track = skymap.sky_track(_run(x), other)
    np.testing.assert_allclose(np.hypot(*track.keep_out.T), 50.0 / 2 + 7.5, atol=TOL)
    assert len(track.comm_limits) == skymap.COMM_SNAPSHOTS
    assert [t for t, _ in track.comm_limits] == [0.0, 10.0, 20.0, 30.0, 40.0]  # first and last included
    for t, curve in track.comm_limits:
        theta = x[int(t), 12]
        drawn = curve[np.isfinite(curve[:, 0])]
        assert len(drawn) > 0.9 * len(curve)
        for xy in drawn[::20]:
            assert _angle(_inverse(xy, theta), np.array([-1.0, 0.0, 0.0])) == pytest.approx(np.radians(65.0), abs=TOL)


def test_projection_is_azimuthal_equidistant() -> None:
    """The polar property, by closed form: the direction at angle rho from the sun and azimuth phi is drawn at
    rho [deg] (cos phi, sin phi), so distances from the centre and along meridians are true angles, and the
    ring at rho has the map circumference 2 pi rho (not the sphere's 2 pi sin rho)."""
    rng = np.random.default_rng(5)
    for theta in rng.uniform(0, 2 * np.pi, 20):
        frame = skymap.sun_frames([theta])[0]
        for rho, phi in zip(rng.uniform(1e-6, np.pi - 1e-6, 50), rng.uniform(-np.pi, np.pi, 50)):
            xy = skymap.project(_direction(rho, phi, theta), frame)
            np.testing.assert_allclose(xy, np.degrees(rho) * np.array([np.cos(phi), np.sin(phi)]), atol=1e-9)
        meridian = np.array([_direction(r, 0.7, theta) for r in np.linspace(0, np.pi * 0.99, 100)])
        steps = np.hypot(*np.diff(skymap.project(meridian, frame), axis=0).T)
        np.testing.assert_allclose(steps, np.degrees(np.pi * 0.99 / 99), rtol=1e-9)
        ring = np.array([_direction(1.0, p, theta) for p in np.linspace(0, 2 * np.pi, 4001)])
        length = np.hypot(*np.diff(skymap.project(ring, frame), axis=0).T).sum()
        assert length == pytest.approx(2 * np.pi * np.degrees(1.0), rel=1e-6)
        # the frame rule: up = orbit normal, right = r_S x z_H, the sun at the centre, the anti-sun on the rim
        np.testing.assert_allclose(skymap.project([0.0, 0.0, 1.0], frame), [0.0, 90.0], atol=1e-9)
        np.testing.assert_allclose(skymap.project(_frame(theta)[0], frame), [90.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(skymap.project(_sun(theta), frame), [0.0, 0.0], atol=1e-9)
        assert np.hypot(*skymap.project(-_sun(theta), frame)) == pytest.approx(180.0, abs=1e-9)


def test_intervened_samples_are_the_steps_whose_command_the_filter_changed(cfg: Any) -> None:
    x = random_states(np.random.default_rng(9), 6, cfg)
    u_des = np.arange(15, dtype=float).reshape(5, 3)
    u = u_des.copy()
    u[1, 2] += 1e-3
    u[3, 0] -= 2.0
    u[4, 1] += 1e-12  # a torque round trip's rounding is no intervention
    track = skymap.sky_track(_run(x, u_des, u), cfg)
    assert track.intervened.tolist() == [False, True, False, True, False, False]  # the last sample starts no step
    assert not skymap.sky_track(_run(x, u_des, u, rta=False), cfg).intervened.any()  # saturation without RTA


# ----------------------------------------------------------------------------- the paper example


def test_paper_example_map_and_figure(paper_reference: dict[bool, Any], cfg: Any, tmp_path: Path) -> None:
    on, off = paper_reference[True], paper_reference[False]
    track = skymap.sky_track(on, cfg)
    keep = np.degrees(cfg.limits.exclusion_fov_rad / 2 + cfg.limits.exclusion_buffer_rad)
    sensor_deg = np.hypot(*track.sensor.T)
    assert sensor_deg.min() > keep  # the filter keeps +i_B out of the keep-out circle at every sample
    oracle = [_angle(_attitude(x[0:4])[0], _sun(x[12])) for x in on.x]
    np.testing.assert_allclose(np.radians(sensor_deg), oracle, atol=TOL)
    # the filter's own record of intervention (rows active or box clipping: FilterResult.intervened)
    np.testing.assert_array_equal(track.intervened[:-1], on.intervening.any(axis=1) | on.box_active.any(axis=1))
    assert not skymap.sky_track(off, cfg).intervened.any()
    png = skymap.plot_skymap([("RTA on", on), ("RTA off", off)], cfg, tmp_path / "skymap.png", "paper-example")
    assert png == tmp_path / "skymap.png" and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 50_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["skymap.png"]  # atomic: no temporary left


def test_simulate_writes_the_sky_map_unless_no_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim"
    assert cli_main(["simulate", "--scenario", "paper-example", "--duration", "60", "--out", str(out)]) == 0
    assert (out / "skymap.png").stat().st_size > 20_000 and (out / "figure.png").exists()
    assert f"sky map: {out / 'skymap.png'}" in capsys.readouterr().out
    bare = tmp_path / "bare"
    assert cli_main(["simulate", "--scenario", "paper-example", "--duration", "5", "--no-plot", "--out",
                     str(bare)]) == 0
    assert not (bare / "skymap.png").exists() and not (bare / "figure.png").exists()
