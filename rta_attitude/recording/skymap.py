"""Boresight sky map: the sensor (+i_B) and the antenna (+j_B) over time on the celestial sphere seen
from the spacecraft, centred on the sun, with the keep-out cone, the Earth and the antenna's limit.

Map frame. The sun turns in Hill (theta_S_dot = -n), so the frame is taken afresh at every sample k
from that sample's sun direction (`dynamics.spacecraft.sun_hill`):

    pole   p_k = r_S = [cos theta_S, sin theta_S, 0]       (Hill)   the map centre
    up       u = z_H = [0, 0, 1]                                    +Y on the map (orbit normal)
    right  r_k = p_k x z_H = [sin theta_S, -cos theta_S, 0]         +X on the map

Rule for the reference azimuth: the orbit normal z_H points up. The sun is always in the orbit plane,
so z_H is always perpendicular to it: the rule needs no projection and is never undefined. (right,
up) is the sky as seen from the spacecraft looking at the sun with the orbit normal up (right x up
= -p: a view from inside the sphere, not a globe seen from outside). The Earth (-x_H,
`spacecraft.EARTH_HILL`, the ground station) is in the orbit plane too, so it always lies on the
map's horizontal axis, angle(r_S, -x_H) from the centre, and moves along it as the sun turns.

Projection: azimuthal equidistant (a polar plot of the sphere about the sun). A direction d at
angle rho = atan2(|d x p|, d . p) from the sun and azimuth phi = atan2(d . u, d . r) is drawn at

    (X, Y) = rho[deg] (cos phi, sin phi)

Why this one and not Lambert's equal-area projection: the constraint the map is about is an angle
from its centre. Here the distance of a sensor point from the centre *is* the exclusion-zone angle
theta_EZ (read it off the 30 deg rings), and the keep-out cone theta_EZ < FOV/2 + beta is exactly
the disc of that radius; every ring is a true angle from the sun. Lambert's r = 2 sin(rho/2) would
keep areas (the density of points over time) but squeeze the radial scale away from the sun, so a
margin could not be read off the map. The price: shapes far from the sun stretch (the anti-sun
point is the whole rim rho = 180 deg), so the antenna's limit, a circle of comm_fov/2 about the
Earth, is drawn as a distorted curve; it moves with the Earth and is drawn at a few times.

Points are coloured by time; samples whose command the filter changed (|u - u_des| > 1e-9 rad/s^2 on
some axis at the step that starts there; never without RTA) have a black core. The angles named
in each panel's title are `constraints.ConstraintSet.angles`, the geometry the barriers act on.

`sky_track` returns the map coordinates without matplotlib (NumPy and the package's compiled
geometry: `quaternion.attitude_matrices`, `sun_hill`, `ConstraintSet.angles`), so it is testable
alone; `plot_skymap` draws one run or several side by side (`analyze --compare`) and writes
`skymap.png`. matplotlib is imported only through `plots._pyplot` (Agg backend).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet, communication, exclusion_zone
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics.spacecraft import EARTH_HILL, sun_hill
from rta_attitude.dynamics.state import THETA_S, Q
from rta_attitude.recording.plots import _pyplot, _save

Array = NDArray[np.float64]

UP_HILL = (0.0, 0.0, 1.0)
"""The map's +Y: the orbit normal z_H (the reference azimuth)."""
INTERVENTION_TOLERANCE_RAD_S2 = 1e-9
"""|u - u_des| above which a step counts as one where the filter changed the command (far above the
rounding of a bag's torque round trip, ~1e-14 rad/s^2)."""
COMM_SNAPSHOTS = 5
"""Number of times (evenly spaced, first and last included) at which the antenna's limit is drawn."""
CIRCLE_POINTS = 721
RIM_JUMP_DEG = 90.0
"""A drawn curve is cut where two neighbouring points are farther apart on the map (it crossed the
anti-sun point, which is the whole rim)."""
RINGS_DEG = (30, 60, 90, 120, 150, 180)
RING_LABEL_AZIMUTH_DEG = 112.0
TIME_CMAP = "viridis"


class SkyRun(Protocol):
    """What the sky map needs of a run (simulation.Trajectory and recording.analysis.BagRun have it)."""

    t_s: Array
    """Sample times (N + 1,), s."""
    x: Array
    """States (N + 1, 19), model units."""
    u_des: Array
    """Desired wheel accelerations (N, 3), rad/s^2."""
    u: Array
    """Applied wheel accelerations (N, 3), rad/s^2."""
    rta: bool
    """A filter ran."""


@dataclass(frozen=True)
class SkyTrack:
    """One run on the sky map; map coordinates (X, Y) in degrees, |(X, Y)| = angle from the sun.

    Attributes:
        t_s: sample times (N + 1,), s.
        sensor, antenna, earth: +i_B, +j_B and the Earth direction at each sample (N + 1, 2).
        intervened: the filter changed the command of the step starting at the sample (N + 1,); the
            last sample starts no step (False).
        keep_out: the keep-out circle, angle FOV/2 + beta from the sun (CIRCLE_POINTS, 2).
        comm_limits: (t, curve) pairs: the antenna's limit comm_fov/2 about the Earth in the map
            frame of time t (CIRCLE_POINTS, 2), NaN where the curve is cut at the rim.
        sensor_sun_rad, antenna_earth_rad: theta_EZ and theta_GS at the samples (N + 1,)
            (`ConstraintSet.angles`).
        keep_out_rad, comm_rad: FOV/2 + beta and comm_fov/2 (`Limits.exclusion_angle_rad`, `comm_angle_rad`).
    """

    t_s: Array
    sensor: Array
    antenna: Array
    earth: Array
    intervened: NDArray[np.bool_]
    keep_out: Array
    comm_limits: tuple[tuple[float, Array], ...]
    sensor_sun_rad: Array
    antenna_earth_rad: Array
    keep_out_rad: float
    comm_rad: float


def sun_frames(theta_S_rad: ArrayLike) -> Array:
    """Map frames of sun angles theta_S (N,): (N, 3, 3), rows right, up, pole (the sun) in Hill."""
    th = np.asarray(theta_S_rad, dtype=float).reshape(-1)
    sun = np.zeros((th.size, 3))
    for k, theta in enumerate(th):
        sun[k, 0], sun[k, 1] = sun_hill(float(theta))
    up = np.broadcast_to(np.array(UP_HILL), sun.shape)
    return np.stack([np.cross(sun, up), up, sun], axis=1)


def project(d_hill: ArrayLike, frames: ArrayLike) -> Array:
    """Azimuthal equidistant map coordinates (..., 2), deg, of unit directions d (..., 3) in Hill in
    map frames (..., 3, 3) (`sun_frames`; broadcast against d). The anti-sun point goes to (180, 0)."""
    c = np.einsum("...ij,...j->...i", np.asarray(frames, dtype=float), np.asarray(d_hill, dtype=float))
    s = np.hypot(c[..., 0], c[..., 1])
    rho = np.degrees(np.arctan2(s, c[..., 2]))
    safe = np.where(s > 0.0, s, 1.0)
    X = np.where(s > 0.0, rho * c[..., 0] / safe, rho)
    Y = np.where(s > 0.0, rho * c[..., 1] / safe, 0.0)
    return np.stack([X, Y], axis=-1)


def ring(center: ArrayLike, radius_rad: float, points: int = CIRCLE_POINTS) -> Array:
    """The unit directions (points, 3) at angle radius_rad about a unit direction `center`, once round
    (first and last point equal)."""
    c = np.asarray(center, dtype=float)
    helper = np.eye(3)[int(np.argmin(np.abs(c)))]
    a = np.cross(c, helper)
    a /= np.linalg.norm(a)
    b = np.cross(c, a)
    phi = np.linspace(0.0, 2.0 * np.pi, points)[:, None]
    return np.cos(radius_rad) * c + np.sin(radius_rad) * (np.cos(phi) * a + np.sin(phi) * b)


def small_circle(center_hill: ArrayLike, radius_rad: float, frame: ArrayLike, points: int = CIRCLE_POINTS) -> Array:
    """Map coordinates (points, 2), deg, of the circle of angle radius_rad about a unit Hill direction,
    in one map frame (3, 3); NaN rows where it jumps across the rim (an open curve for matplotlib)."""
    xy = project(ring(center_hill, radius_rad, points), frame)
    jump = np.hypot(*np.diff(xy, axis=0).T) > RIM_JUMP_DEG
    xy[1:][jump] = np.nan
    return xy


def intervened_steps(run: SkyRun) -> NDArray[np.bool_]:
    """(N,) steps at which the filter changed the command: |u - u_des| > INTERVENTION_TOLERANCE_RAD_S2
    on some axis (none without RTA, where u differs from u_des only by the actuator's saturation)."""
    u, u_des = np.asarray(run.u, dtype=float), np.asarray(run.u_des, dtype=float)
    if not run.rta:
        return np.zeros(len(u), dtype=bool)
    return np.asarray(np.any(np.abs(u - u_des) > INTERVENTION_TOLERANCE_RAD_S2, axis=1))


def body_axis_in_hill(A: Array, axis_body: tuple[float, float, float]) -> Array:
    """A(q)^T e for attitude matrices (N, 3, 3) (Hill -> body): body axis e in Hill (N, 3)."""
    return np.einsum("kij,i->kj", A, np.asarray(axis_body))


def sky_track(run: SkyRun, cfg: Config) -> SkyTrack:
    """The run on the sun-centred map (no matplotlib).

    Args:
        run: the run's samples and commands.
        cfg: configuration (the exclusion and communication limits).
    """
    t = np.asarray(run.t_s, dtype=float)
    x = np.asarray(run.x, dtype=float)
    frames = sun_frames(x[:, THETA_S])
    A = quat.attitude_matrices(x[:, Q])
    earth = np.array(EARTH_HILL)
    inter = np.zeros(len(t), dtype=bool)
    inter[: len(run.u)] = intervened_steps(run)
    angles = ConstraintSet(cfg).angles(x)
    L = cfg.limits
    snaps = np.unique(np.linspace(0, len(t) - 1, COMM_SNAPSHOTS).round().astype(int))
    return SkyTrack(
        t_s=t,
        sensor=project(body_axis_in_hill(A, exclusion_zone.AXIS_BODY), frames),
        antenna=project(body_axis_in_hill(A, communication.AXIS_BODY), frames),
        earth=project(np.broadcast_to(earth, (len(t), 3)), frames),
        intervened=inter,
        keep_out=small_circle(frames[0, 2], L.exclusion_angle_rad, frames[0]),
        comm_limits=tuple((float(t[k]), small_circle(earth, L.comm_angle_rad, frames[k])) for k in snaps),
        sensor_sun_rad=angles["sensor_sun"],
        antenna_earth_rad=angles["antenna_earth"],
        keep_out_rad=L.exclusion_angle_rad,
        comm_rad=L.comm_angle_rad,
    )


def _draw(ax: Any, plt: Any, label: str, tr: SkyTrack, norm: Any, cmap: Any) -> None:
    """One run's panel."""
    for r in RINGS_DEG:
        ax.add_patch(plt.Circle((0, 0), r, fill=False, color="0.8" if r < 180 else "0.4", lw=0.6 if r < 180 else 1.0))
        ax.text(r * np.cos(np.radians(RING_LABEL_AZIMUTH_DEG)), r * np.sin(np.radians(RING_LABEL_AZIMUTH_DEG)),
                f"{r}°", fontsize=7, color="0.45", ha="center", va="bottom")
    ax.axhline(0.0, color="0.85", lw=0.6, zorder=0)
    ax.axvline(0.0, color="0.85", lw=0.6, zorder=0)
    ax.text(2, 92, "+z_H", fontsize=7, color="0.45")
    ax.text(2, -98, "-z_H", fontsize=7, color="0.45")
    keep_deg = np.degrees(tr.keep_out_rad)
    ax.fill(tr.keep_out[:, 0], tr.keep_out[:, 1], color="tab:red", alpha=0.15, lw=0)
    ax.plot(tr.keep_out[:, 0], tr.keep_out[:, 1], color="tab:red", lw=1.5,
            label=f"sensor keep-out: {keep_deg:.0f}° (FOV/2 + beta) from the sun")
    comm_deg = np.degrees(tr.comm_rad)
    for k, (t, curve) in enumerate(tr.comm_limits):
        ax.plot(curve[:, 0], curve[:, 1], ls="--", lw=1.0, color=cmap(norm(t)),
                label=f"antenna limit: {comm_deg:.0f}° (comm_fov/2) from Earth, at {len(tr.comm_limits)} times"
                if k == 0 else None)
    ax.scatter(tr.earth[:, 0], tr.earth[:, 1], c=tr.t_s, cmap=cmap, norm=norm, marker="D", s=14, lw=0,
               label="Earth (-x_H, ground station)")
    for name, pts, marker in (("antenna +j_B", tr.antenna, "s"), ("sensor +i_B", tr.sensor, "o")):
        ax.scatter(pts[:, 0], pts[:, 1], c=tr.t_s, cmap=cmap, norm=norm, marker=marker, s=16, lw=0, label=name)
        hit = tr.intervened
        ax.scatter(pts[hit, 0], pts[hit, 1], color="k", marker=".", s=1.5, lw=0)
    for name, pts in (("+j_B", tr.antenna), ("+i_B", tr.sensor), ("Earth", tr.earth)):
        ax.annotate(name, pts[0], xytext=(8, 8), textcoords="offset points", fontsize=8, zorder=6,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.75, "lw": 0})
        ax.scatter(*pts[0], marker="o", s=70, facecolors="none", edgecolors="k", lw=1.0, zorder=4)
        ax.scatter(*pts[-1], marker="X", s=50, color="k", lw=0, zorder=4)
    ax.scatter([0.0], [0.0], marker="*", s=260, color="gold", edgecolors="k", linewidths=0.6, zorder=5, label="sun")
    handles, labels = ax.get_legend_handles_labels()
    handles += [ax.scatter([], [], marker="o", s=70, facecolors="none", edgecolors="k", lw=1.0),
                ax.scatter([], [], marker="X", s=50, color="k", lw=0)]
    labels += ["start of a track", "end of a track"]
    core = (ax.scatter([], [], marker="o", s=16, color="0.75", lw=0), ax.scatter([], [], marker=".", s=4, color="k"))
    handles.append(core)
    labels.append(f"black core: the filter changed the command ({int(tr.intervened.sum())} of {len(tr.t_s) - 1} "
                  "steps)")
    ez, gs = np.degrees(tr.sensor_sun_rad), np.degrees(tr.antenna_earth_rad)
    ax.set_title(f"{label}\nsensor-sun min {ez.min():.1f}° (limit >= {keep_deg:.0f}°), "
                 f"antenna-Earth max {gs.max():.1f}° (limit <= {comm_deg:.0f}°)", fontsize=9)
    ax.set_xlim(-190, 190)
    ax.set_ylim(-190, 190)
    ax.set_aspect("equal")
    ax.set_xlabel("centre: the sun; radius: angle from the sun [deg]; up: orbit normal z_H; right: r_S x z_H",
                  fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_visible(False)
    ax.legend(handles, labels, fontsize=7, loc="lower left", framealpha=0.85)


def plot_skymap(runs: Sequence[tuple[str, SkyRun]], cfg: Config, path: str | Path, title: str = "") -> Path:
    """Draw the sky map of one or more runs (one panel each, side by side, one time scale) and save it as PNG.

    Args:
        runs: (label, run) pairs.
        cfg: configuration (limits).
        path: output PNG path.
        title: figure title.

    Returns:
        The path written.
    """
    plt = _pyplot()
    tracks = [(label, sky_track(run, cfg)) for label, run in runs]
    cmap = plt.get_cmap(TIME_CMAP)
    norm = plt.Normalize(min(float(tr.t_s[0]) for _, tr in tracks), max(float(tr.t_s[-1]) for _, tr in tracks))
    fig, axes = plt.subplots(1, len(tracks), figsize=(7.4 * len(tracks) + 1.0, 7.8), squeeze=False,
                             layout="constrained")
    for ax, (label, tr) in zip(axes[0], tracks):
        _draw(ax, plt, label, tr, norm, cmap)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=list(axes[0]), shrink=0.7, label="t [s]")
    fig.suptitle(title or "boresights on the sky, sun-centred")
    return _save(plt, fig, path)


__all__ = ["SkyRun", "SkyTrack", "body_axis_in_hill", "intervened_steps", "plot_skymap", "project", "ring",
           "sky_track", "small_circle", "sun_frames"]
