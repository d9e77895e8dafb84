"""rta_attitude.recording.skymap: the boresight maps (one per pointing constraint, centred on its target), against
closed forms written here; and the figure's panels per cone.

The oracles do not call the module under test nor the package's attitude code: A(q) is Markley's
closed form, the sun r_S = [cos theta_S, sin theta_S, 0], the Earth -x_H, angles atan2(|a x b|, a . b),
and a map is inverted by the rule the module states (pole the target, up z_H made perpendicular to it (y_H
for a pole along z_H), right pole x up, azimuthal equidistant: a point at rho [deg] (cos phi, sin phi) is the
direction at angle rho from the centre, azimuth phi from `right` towards `up`). For the sun's map that is
pole r_S, up z_H, right [sin theta_S, -cos theta_S, 0]; for the Earth's, pole -x_H, up z_H, right +y_H. Runs
are the paper example simulated in process (no DDS).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from helpers import random_states

from rta_attitude import config
from rta_attitude.cli.main import main as cli_main
from rta_attitude.config.schema import PointingConstraint
from rta_attitude.recording import plots, skymap

TOL = 1e-9
EARTH = np.array([-1.0, 0.0, 0.0])
EARTH_FRAME = (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), EARTH)
"""(right, up, pole) of the Earth's map by the stated rule."""


@pytest.fixture(scope="module")
def cfg() -> Any:
    return config.load()


def with_star_tracker(cfg: Any, **kw: Any) -> Any:
    """cfg with a third cone: -k_B kept 30 deg off the Earth (a group of the first priority level)."""
    cone = PointingConstraint(**{"name": "star_tracker", "kind": "keep_out", "boresight_body": (0.0, 0.0, -1.0),
                                 "target": "earth", "half_angle_rad": math.radians(30), "gains": cfg.pointing[0].gains,
                                 **kw})
    levels = cfg.filter.priorities
    return dataclasses.replace(cfg, pointing=(*cfg.pointing, cone), filter=dataclasses.replace(
        cfg.filter, priorities=levels[:1] and (levels[0] + ("star_tracker",), *levels[1:])))


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
    """(right, up, pole) of the sun's map: pole r_S, up z_H, right r_S x z_H = [sin, -cos, 0]."""
    return np.array([np.sin(theta), -np.cos(theta), 0.0]), np.array([0.0, 0.0, 1.0]), _sun(theta)


def _direction(rho: float, phi: float, frame: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """The unit Hill direction at angle rho from the pole and azimuth phi (from right towards up)."""
    right, up, pole = frame
    return np.sin(rho) * (np.cos(phi) * right + np.sin(phi) * up) + np.cos(rho) * pole


def _inverse(xy: np.ndarray, frame: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """The Hill direction drawn at map point xy (deg) in a map frame."""
    return _direction(np.radians(np.hypot(*xy)), float(np.arctan2(xy[1], xy[0])), frame)


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



# ----------------------------------------------------------------------------- the maps against the oracles


def test_sun_map_radius_is_the_exclusion_angle_and_maps_back_to_i_B(random_run: Any, cfg: Any) -> None:
    track = skymap.sky_track(random_run, cfg)
    assert [c.name for c in track.cones] == ["exclusion_zone", "communication"]
    ez = track.cones[0]
    assert (ez.target, ez.boresight_text, ez.up_text) == ("sun", "+i_B", "+z_H")
    for k, x in enumerate(random_run.x):
        i_B = _attitude(x[0:4])[0]  # row 0 of A(q): body axis +i_B in Hill
        theta_EZ = _angle(i_B, _sun(x[12]))
        assert np.radians(np.hypot(*ez.boresight[k])) == pytest.approx(theta_EZ, abs=TOL)
        np.testing.assert_allclose(_inverse(ez.boresight[k], _frame(x[12])), i_B, atol=TOL)
        np.testing.assert_allclose(_inverse(ez.earth[k], _frame(x[12])), EARTH, atol=TOL)
        np.testing.assert_allclose(ez.sun[k], [0.0, 0.0], atol=TOL)  # the centre
    np.testing.assert_allclose(ez.angle_rad, [_angle(_attitude(x[0:4])[0], _sun(x[12])) for x in random_run.x],
                               atol=TOL)
    assert np.degrees(ez.angle_rad).min() < 1e-6 and np.degrees(ez.angle_rad).max() > 180 - 1e-6


def test_earth_map_radius_is_the_communication_angle_and_maps_back_to_j_B(random_run: Any, cfg: Any) -> None:
    comm = skymap.sky_track(random_run, cfg).cones[1]
    assert (comm.target, comm.boresight_text, comm.kind) == ("earth", "+j_B", "keep_in")
    for k, x in enumerate(random_run.x):
        j_B = _attitude(x[0:4])[1]
        theta_GS = _angle(j_B, EARTH)
        assert np.radians(np.hypot(*comm.boresight[k])) == pytest.approx(theta_GS, abs=TOL)
        assert comm.angle_rad[k] == pytest.approx(theta_GS, abs=TOL)
        np.testing.assert_allclose(_inverse(comm.boresight[k], EARTH_FRAME), j_B, atol=TOL)
        # the sun is in the orbit plane: on the Earth map's horizontal axis, angle(r_S, -x_H) from the centre
        np.testing.assert_allclose(_inverse(comm.sun[k], EARTH_FRAME), _sun(x[12]), atol=TOL)
        assert comm.sun[k, 1] == pytest.approx(0.0, abs=TOL)
        np.testing.assert_allclose(comm.earth[k], [0.0, 0.0], atol=TOL)


def test_limits_are_circles_of_the_configured_half_angles_about_the_centre(cfg: Any) -> None:
    ez, comm = cfg.pointing
    other = dataclasses.replace(cfg, pointing=(dataclasses.replace(ez, half_angle_rad=np.radians(32.5)),
                                               dataclasses.replace(comm, half_angle_rad=np.radians(65.0))))
    x = random_states(np.random.default_rng(3), 41, cfg)
    track = skymap.sky_track(_run(x), other)
    for cone, half_deg in zip(track.cones, (32.5, 65.0), strict=True):
        assert cone.half_angle_rad == pytest.approx(np.radians(half_deg), abs=1e-15)
        np.testing.assert_allclose(np.hypot(*cone.limit.T), half_deg, atol=TOL)
        assert np.isfinite(cone.limit).all()  # a circle about the centre never crosses the rim


def test_a_third_cone_gets_its_own_map_with_its_windows(cfg: Any, tmp_path: Path) -> None:
    other = with_star_tracker(cfg, windows_s=((10.0, 20.0),))
    x = random_states(np.random.default_rng(6), 31, cfg)
    track = skymap.sky_track(_run(x), other)
    assert [c.name for c in track.cones] == ["exclusion_zone", "communication", "star_tracker"]
    st = track.cones[2]
    assert (st.target, st.boresight_text, st.kind) == ("earth", "-k_B", "keep_out")
    t = np.arange(31)
    np.testing.assert_array_equal(st.applies, (t >= 10) & (t <= 20))
    np.testing.assert_allclose(np.hypot(*st.limit.T), 30.0, atol=TOL)
    for k, xk in enumerate(x):
        minus_k_B = -_attitude(xk[0:4])[2]
        assert np.radians(np.hypot(*st.boresight[k])) == pytest.approx(_angle(minus_k_B, EARTH), abs=TOL)
        np.testing.assert_allclose(_inverse(st.boresight[k], EARTH_FRAME), minus_k_B, atol=TOL)
    png = skymap.plot_skymap([("random", _run(x))], other, tmp_path / "skymap.png", "three cones")
    from PIL import Image

    with Image.open(png) as im:  # one map per cone, three to a row
        assert im.size[0] > 2.5 * im.size[1]


def test_map_frames_follow_the_stated_rule() -> None:
    """Up is z_H made perpendicular to the pole (a sun out of the orbit plane), y_H for a pole along z_H."""
    for beta in np.radians([0.0, 23.0, -60.0, 89.0]):
        for theta in np.linspace(0, 2 * np.pi, 7):
            pole = np.array([np.cos(beta) * np.cos(theta), np.cos(beta) * np.sin(theta), np.sin(beta)])
            right, up, p = skymap.sun_frames([theta], beta)[0]
            np.testing.assert_allclose(p, pole, atol=1e-12)
            want_up = np.array([0.0, 0.0, 1.0]) - np.sin(beta) * pole
            np.testing.assert_allclose(up, want_up / np.linalg.norm(want_up), atol=1e-12)
            np.testing.assert_allclose(right, np.cross(pole, up), atol=1e-12)
    for pole in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])):
        right, up, p = skymap.map_frames(pole)[0]
        np.testing.assert_allclose(up, [0.0, 1.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(right, np.cross(pole, [0.0, 1.0, 0.0]), atol=1e-12)
    np.testing.assert_allclose(skymap.map_frames(EARTH)[0], np.array(EARTH_FRAME), atol=0.0)


def test_projection_is_azimuthal_equidistant() -> None:
    """The polar property, by closed form: the direction at angle rho from the sun and azimuth phi is drawn at
    rho [deg] (cos phi, sin phi), so distances from the centre and along meridians are true angles, and the
    ring at rho has the map circumference 2 pi rho (not the sphere's 2 pi sin rho)."""
    rng = np.random.default_rng(5)
    for theta in rng.uniform(0, 2 * np.pi, 20):
        frame = skymap.sun_frames([theta])[0]
        for rho, phi in zip(rng.uniform(1e-6, np.pi - 1e-6, 50), rng.uniform(-np.pi, np.pi, 50)):
            xy = skymap.project(_direction(rho, phi, _frame(theta)), frame)
            np.testing.assert_allclose(xy, np.degrees(rho) * np.array([np.cos(phi), np.sin(phi)]), atol=1e-9)
        meridian = np.array([_direction(r, 0.7, _frame(theta)) for r in np.linspace(0, np.pi * 0.99, 100)])
        steps = np.hypot(*np.diff(skymap.project(meridian, frame), axis=0).T)
        np.testing.assert_allclose(steps, np.degrees(np.pi * 0.99 / 99), rtol=1e-9)
        ring = np.array([_direction(1.0, p, _frame(theta)) for p in np.linspace(0, 2 * np.pi, 4001)])
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


# ----------------------------------------------------------------------------- the figure's cone panels


def test_figure_has_the_papers_grid_and_a_row_more_for_a_third_cone(cfg: Any, tmp_path: Path) -> None:
    from PIL import Image

    assert plots.cone_slots(2) == [1, 2] and plots.cone_slots(3) == [1, 2, 9] and plots.cone_slots(0) == []
    assert plots.outside_windows_s(((10.0, 20.0), (30.0, 40.0)), 0.0, 35.0) == [(0.0, 10.0), (20.0, 30.0)]
    assert plots.outside_windows_s((), 0.0, 35.0) == []
    x = random_states(np.random.default_rng(2), 21, cfg)
    run = SimpleNamespace(t_s=np.arange(21.0), x=x, u=np.zeros((20, 3)), omega_dot=np.zeros((20, 3)))
    sizes = {}
    for name, c in (("paper", cfg), ("three", with_star_tracker(cfg, windows_s=((5.0, 9.0),)))):
        png = plots.plot_runs([("random", run)], c, tmp_path / f"{name}.png", name)
        with Image.open(png) as im:
            sizes[name] = im.size
    assert sizes["paper"] == (15 * 110, 11 * 110)  # the paper's 3x3 grid
    assert sizes["three"] == (15 * 110, round(11 / 3 * 4 * 110))  # a fourth row: (j) star_tracker


# ----------------------------------------------------------------------------- the paper example


def test_paper_example_map_and_figure(paper_reference: dict[bool, Any], cfg: Any, tmp_path: Path) -> None:
    on, off = paper_reference[True], paper_reference[False]
    track = skymap.sky_track(on, cfg)
    ez = track.cones[0]
    sensor_deg = np.hypot(*ez.boresight.T)
    assert sensor_deg.min() > np.degrees(cfg.pointing[0].half_angle_rad)  # +i_B out of the keep-out disc throughout
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
