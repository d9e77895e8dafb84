"""Boresight sky maps: each pointing constraint's boresight over time on the celestial sphere seen from the
spacecraft, on a map of its own centred on the constraint's target, with the cone's limit about it.

One map per cone, each centred on its own target, rather than one map with a legend. What a pointing
constraint bounds is an angle from its target; on an azimuthal equidistant map centred on that target the
angle *is* the distance from the centre, so the limit is an exact circle of radius alpha and the margin is
read off with a ruler (the 30 deg rings). One map centred on the sun keeps that only for the cones about the
sun: a cone about the Earth becomes a distorted curve that moves across the map as the sun turns (the
paper's antenna limit of 90 deg about the Earth reached past the anti-sun rim), and with several cones and
boresights on one map their tracks and limits cross and cannot be told apart. The sun and the Earth are
still drawn on every map (coloured by time) so that each can be placed against the others; runs side by
side (`analyze --compare`) give one row of maps each.

Map frame. Taken at every sample k from that sample's target direction p_k (in Hill, `environment`): the
sun turns in Hill (theta_S_dot = -n), a target fixed in the inertial frame turns too, and a target fixed in
Hill (the Earth) gives the same frame at every sample:

    pole   p_k                                                   the map centre
    up     u_k = z_H - (z_H . p_k) p_k, normalised               +Y on the map (orbit normal)
    right  r_k = p_k x u_k                                        +X on the map

Rule for the reference azimuth: the orbit normal z_H points up. For the sun in the paper (beta = 0) and for
the Earth z_H is perpendicular to the pole, so u = z_H and r = p x z_H (the sun's map: [sin theta_S,
-cos theta_S, 0]; the Earth's, -x_H: r = +y_H, the velocity to the right). For a sun out of the orbit plane
(beta != 0) z_H is projected; for a pole within 1e-6 of +-z_H (the orbit normal as a target) the rule
takes the along-track y_H instead (`UP_FALLBACK_HILL`, the map's up is then labelled +y_H). (right, up) is
the sky as seen from the spacecraft looking at the target (right x up = -p: a view from inside the sphere,
not a globe seen from outside).

Projection: azimuthal equidistant (a polar plot of the sphere about the target). A direction d at angle
rho = atan2(|d x p|, d . p) from the centre and azimuth phi = atan2(d . u, d . r) is drawn at

    (X, Y) = rho[deg] (cos phi, sin phi)

Why this one and not Lambert's equal-area projection: Lambert's r = 2 sin(rho/2) would keep areas (the
density of points over time) but squeeze the radial scale away from the centre, so a margin could not be
read off the map. The price: shapes far from the centre stretch (the antipode is the whole rim rho = 180
deg); no limit is drawn there, every limit being a circle about the centre.

A keep_out cone shades its disc (where the boresight must not go), a keep_in cone the ring outside its
circle. Points are coloured by time; samples whose command the filter changed (|u - u_des| > 1e-9
rad/s^2 on some axis at the step that starts there; never without RTA) have a black core; samples
outside a windowed cone's windows are drawn small and faint (the constraint does not apply there). The
angles named in each panel's title are `constraints.ConstraintSet.angles`, the geometry the barriers act on.

`sky_track` returns the map coordinates without matplotlib (NumPy and the package's compiled geometry:
`quaternion.attitude_matrices`, `environment`, `ConstraintSet.angles` and `safety_values`), so it is
testable alone; `plot_skymap` draws one run or several and writes `skymap.png`. matplotlib is imported only
through `plots._pyplot` (Agg backend).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.config.schema import Config, PointingConstraint
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics.environment import EARTH_HILL, sun_direction
from rta_attitude.dynamics.state import STATE_SIZE, THETA_S, Q
from rta_attitude.recording.plots import _pyplot, _save, body_label, cone_targets, limit_text, target_label

Array = NDArray[np.float64]

UP_HILL = (0.0, 0.0, 1.0)
"""The map's +Y: the orbit normal z_H (the reference azimuth), made perpendicular to the pole."""
UP_FALLBACK_HILL = (0.0, 1.0, 0.0)
"""The map's +Y where the pole is along +-z_H: the along-track y_H."""
POLE_GUARD = 1e-6
"""|z_H - (z_H . p) p| below this: the pole counts as along z_H (UP_FALLBACK_HILL)."""
INTERVENTION_TOLERANCE_RAD_S2 = 1e-9
"""|u - u_des| above which a step counts as one where the filter changed the command (far above the
rounding of a bag's torque round trip, ~1e-14 rad/s^2)."""
CIRCLE_POINTS = 721
RIM_JUMP_DEG = 90.0
"""A drawn curve is cut where two neighbouring points are farther apart on the map (it crossed the
antipode, which is the whole rim)."""
RINGS_DEG = (30, 60, 90, 120, 150, 180)
RING_LABEL_AZIMUTH_DEG = 112.0
TIME_CMAP = "viridis"
MAP_COLUMNS = 3
"""Maps per row of the figure at most (one run's cones wrap onto further rows)."""
KIND_COLORS = {"keep_out": "tab:red", "keep_in": "tab:blue"}
CENTRE_MARKERS = {"sun": ("*", "gold", 260), "earth": ("D", "tab:blue", 90)}
"""(marker, colour, size) of the map centre by target; other targets: a black plus."""


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
class ConeTrack:
    """One pointing constraint's map, centred on its target; coordinates (X, Y) in degrees, |(X, Y)| = angle
    from the target.

    Attributes:
        name, kind, target: the constraint's name, kind ('keep_out', 'keep_in') and target (TARGET_NAMES).
        target_text, boresight_text: how the target and the boresight are written (`plots.target_label`,
            `plots.body_label`).
        half_angle_rad: the cone's half-angle.
        boresight: the boresight at each sample (N + 1, 2).
        sun, earth: the sun's and the Earth's direction at each sample, in this map (N + 1, 2).
        angle_rad: the boresight's angle to the target (N + 1,) (`ConstraintSet.angles`).
        applies: the constraint holds at the sample (N + 1,) (inside its windows, or it has none).
        limit: the limit, the circle at half_angle_rad about the centre (CIRCLE_POINTS, 2).
        up_text: what the map's +Y is ('+z_H', or '+y_H' for a pole along z_H).
    """

    name: str
    kind: str
    target: str
    target_text: str
    boresight_text: str
    half_angle_rad: float
    boresight: Array
    sun: Array
    earth: Array
    angle_rad: Array
    applies: NDArray[np.bool_]
    limit: Array
    up_text: str

    @property
    def keep_in(self) -> bool:
        return self.kind == "keep_in"


@dataclass(frozen=True)
class SkyTrack:
    """One run's maps: one per configured pointing constraint, in order.

    Attributes:
        t_s: sample times (N + 1,), s.
        intervened: the filter changed the command of the step starting at the sample (N + 1,); the
            last sample starts no step (False).
        cones: one `ConeTrack` per pointing constraint (`constraints.pointing`, in order).
    """

    t_s: Array
    intervened: NDArray[np.bool_]
    cones: tuple[ConeTrack, ...]


def map_frames(pole_hill: ArrayLike) -> Array:
    """Map frames of unit pole directions (N, 3) in Hill: (N, 3, 3), rows right, up, pole (module docstring:
    up is z_H made perpendicular to the pole, y_H where the pole is along z_H)."""
    p = np.asarray(pole_hill, dtype=float).reshape(-1, 3)
    up = np.array(UP_HILL) - (p @ np.array(UP_HILL))[:, None] * p
    norm = np.linalg.norm(up, axis=1)
    near = norm < POLE_GUARD
    if near.any():
        up[near] = np.array(UP_FALLBACK_HILL) - (p[near] @ np.array(UP_FALLBACK_HILL))[:, None] * p[near]
        norm[near] = np.linalg.norm(up[near], axis=1)
    up = up / norm[:, None]
    return np.stack([np.cross(p, up), up, p], axis=1)


def sun_frames(theta_S_rad: ArrayLike, beta_rad: float = 0.0) -> Array:
    """Map frames centred on the sun at sun angles theta_S (N,): (N, 3, 3), rows right, up, pole (the sun)."""
    return map_frames(sun_direction(np.asarray(theta_S_rad, dtype=float).reshape(-1), beta_rad))


def project(d_hill: ArrayLike, frames: ArrayLike) -> Array:
    """Azimuthal equidistant map coordinates (..., 2), deg, of unit directions d (..., 3) in Hill in
    map frames (..., 3, 3) (`map_frames`; broadcast against d). The antipode goes to (180, 0)."""
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


def body_axis_in_hill(A: Array, axis_body: ArrayLike) -> Array:
    """A(q)^T e for attitude matrices (N, 3, 3) (Hill -> body): body direction e in Hill (N, 3)."""
    return np.einsum("kij,i->kj", A, np.asarray(axis_body, dtype=float))


def cone_track(cone: PointingConstraint, A: Array, x: Array, angle_rad: Array, h: Array, beta_rad: float) -> ConeTrack:
    """One cone's map of states x (N, 19) with attitude matrices A (N, 3, 3), its angles (N,) and h (N,)."""
    frames = map_frames(cone_targets(cone, x[:, THETA_S], beta_rad))
    sun = sun_direction(x[:, THETA_S], beta_rad)
    earth = np.broadcast_to(np.array(EARTH_HILL), sun.shape)
    along_z = float(np.linalg.norm(np.cross(frames[0, 2], UP_HILL))) < POLE_GUARD
    return ConeTrack(
        name=cone.name, kind=cone.kind, target=cone.target, target_text=target_label(cone.target, cone.target_vector),
        boresight_text=body_label(cone.boresight_body), half_angle_rad=cone.half_angle_rad,
        boresight=project(body_axis_in_hill(A, cone.boresight_body), frames), sun=project(sun, frames),
        earth=project(earth, frames), angle_rad=np.asarray(angle_rad, dtype=float),
        applies=np.asarray(~np.isposinf(h)), limit=small_circle(frames[0, 2], cone.half_angle_rad, frames[0]),
        up_text="+y_H" if along_z else "+z_H",
    )  # fmt: skip


def sky_track(run: SkyRun, cfg: Config, constraints: ConstraintSet | None = None) -> SkyTrack:
    """The run's maps, one per pointing constraint (no matplotlib).

    Args:
        run: the run's samples and commands.
        cfg: configuration (the pointing constraints, the sun's beta angle).
        constraints: a ConstraintSet of cfg made once by a caller that maps many runs.
    """
    t = np.asarray(run.t_s, dtype=float)
    x = np.asarray(run.x, dtype=float)
    A = quat.attitude_matrices(x[:, Q])
    inter = np.zeros(len(t), dtype=bool)
    inter[: len(run.u)] = intervened_steps(run)
    cs = constraints or ConstraintSet(cfg.body_model)
    body = x[:, :STATE_SIZE]  # (an array's first three wheels stand in at 7..9: a cone reads q and t alone)
    angles = cs.angles(body)
    h = cs.safety_values(body, t)
    beta = cfg.environment.sun_beta_rad
    return SkyTrack(t_s=t, intervened=inter,
                    cones=tuple(cone_track(c, A, x, angles[c.name], h[:, cs.registry.index(c.name)], beta)
                                for c in cfg.pointing))


def _grid(ax: Any, plt: Any, up_text: str) -> None:
    """The rings of true angle from the centre, the axes and the up/down labels."""
    for r in RINGS_DEG:
        ax.add_patch(plt.Circle((0, 0), r, fill=False, color="0.8" if r < 180 else "0.4", lw=0.6 if r < 180 else 1.0))
        ax.text(r * np.cos(np.radians(RING_LABEL_AZIMUTH_DEG)), r * np.sin(np.radians(RING_LABEL_AZIMUTH_DEG)),
                f"{r}°", fontsize=7, color="0.45", ha="center", va="bottom")
    ax.axhline(0.0, color="0.85", lw=0.6, zorder=0)
    ax.axvline(0.0, color="0.85", lw=0.6, zorder=0)
    ax.text(2, 92, up_text, fontsize=7, color="0.45")
    ax.text(2, -98, up_text.replace("+", "-"), fontsize=7, color="0.45")


def _limit(ax: Any, plt: Any, cone: ConeTrack) -> None:
    """The cone's limit about the centre: a keep_out's disc or a keep_in's outer ring shaded (where the
    boresight must not go), its circle drawn."""
    from matplotlib.patches import Wedge

    half_deg = math.degrees(cone.half_angle_rad)
    if cone.keep_in:
        ax.add_patch(Wedge((0, 0), 180.0, 0.0, 360.0, width=180.0 - half_deg, color="tab:red", alpha=0.12, lw=0))
    else:
        ax.fill(cone.limit[:, 0], cone.limit[:, 1], color="tab:red", alpha=0.15, lw=0)
    word = "keep in" if cone.keep_in else "keep out"
    ax.plot(cone.limit[:, 0], cone.limit[:, 1], color=KIND_COLORS[cone.kind], lw=1.5,
            label=f"{cone.name}: {word}, {half_deg:.0f}° from the {cone.target_text}")


def _tracks(ax: Any, tr: SkyTrack, cone: ConeTrack, norm: Any, cmap: Any) -> None:
    """The boresight, and the sun and the Earth where they are not the centre, coloured by time."""
    for name, pts, target, marker in (("sun", cone.sun, "sun", "*"), ("Earth (-x_H)", cone.earth, "earth", "D")):
        if cone.target != target:
            ax.scatter(pts[:, 0], pts[:, 1], c=tr.t_s, cmap=cmap, norm=norm, marker=marker, s=14, lw=0, label=name)
    on, off = cone.applies, ~cone.applies
    pts = cone.boresight
    ax.scatter(pts[on, 0], pts[on, 1], c=tr.t_s[on], cmap=cmap, norm=norm, marker="o", s=16, lw=0,
               label=f"{cone.boresight_text} boresight")
    if off.any():
        ax.scatter(pts[off, 0], pts[off, 1], c=tr.t_s[off], cmap=cmap, norm=norm, marker="o", s=5, lw=0, alpha=0.3,
                   label="outside its windows")
    hit = tr.intervened
    ax.scatter(pts[hit, 0], pts[hit, 1], color="k", marker=".", s=1.5, lw=0)
    ax.annotate(cone.boresight_text, pts[0], xytext=(8, 8), textcoords="offset points", fontsize=8, zorder=6,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.75, "lw": 0})
    ax.scatter(*pts[0], marker="o", s=70, facecolors="none", edgecolors="k", lw=1.0, zorder=4)
    ax.scatter(*pts[-1], marker="X", s=50, color="k", lw=0, zorder=4)
    marker, color, size = CENTRE_MARKERS.get(cone.target, ("P", "k", 90))
    ax.scatter([0.0], [0.0], marker=marker, s=size, color=color, edgecolors="k", linewidths=0.6, zorder=5,
               label=f"{cone.target_text} (the centre)")


def _title(label: str, cone: ConeTrack) -> str:
    """'<run>: <name>' and the extreme angle that the limit bounds, over the samples where it applies."""
    worst = "max" if cone.keep_in else "min"
    theta = np.degrees(cone.angle_rad[cone.applies])
    where = " in its windows" if not cone.applies.all() else ""
    value = f"{(theta.max() if cone.keep_in else theta.min()):.1f}°" if theta.size else "n/a (never in a window)"
    return (f"{label}: {cone.name}\n{cone.boresight_text} to {cone.target_text}: {worst}{where} {value} "
            f"(limit {limit_text(cone.kind, cone.half_angle_rad).replace(' deg', '°')})")


def _draw(ax: Any, plt: Any, label: str, tr: SkyTrack, cone: ConeTrack, norm: Any, cmap: Any) -> None:
    """One cone's map of one run."""
    _grid(ax, plt, cone.up_text)
    _limit(ax, plt, cone)
    _tracks(ax, tr, cone, norm, cmap)
    handles, labels = ax.get_legend_handles_labels()
    handles += [ax.scatter([], [], marker="o", s=70, facecolors="none", edgecolors="k", lw=1.0),
                ax.scatter([], [], marker="X", s=50, color="k", lw=0),
                (ax.scatter([], [], marker="o", s=16, color="0.75", lw=0), ax.scatter([], [], marker=".", s=4,
                                                                                       color="k"))]
    labels += ["start of the track", "end of the track",
               f"black core: the filter changed the command ({int(tr.intervened.sum())} of {len(tr.t_s) - 1} steps)"]
    ax.set_title(_title(label, cone), fontsize=9)
    ax.set_xlim(-190, 190)
    ax.set_ylim(-190, 190)
    ax.set_aspect("equal")
    ax.set_xlabel(f"centre: the {cone.target_text}; radius: angle from it [deg]; up: {cone.up_text}; "
                  "right: centre x up", fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_visible(False)
    ax.legend(handles, labels, fontsize=7, loc="lower left", framealpha=0.85)


def plot_skymap(runs: Sequence[tuple[str, SkyRun]], cfg: Config, path: str | Path, title: str = "") -> Path:
    """Draw the sky maps of one or more runs (one map per pointing constraint, MAP_COLUMNS to a row; each run's
    maps on rows of their own; one time scale) and save them as PNG.

    Args:
        runs: (label, run) pairs.
        cfg: configuration (the pointing constraints).
        path: output PNG path.
        title: figure title.

    Returns:
        The path written.
    """
    plt = _pyplot()
    constraints = ConstraintSet(cfg.body_model)
    tracks = [(label, sky_track(run, cfg, constraints)) for label, run in runs]
    n_cones = len(cfg.pointing)
    columns = max(1, min(n_cones, MAP_COLUMNS))
    rows_per_run = max(1, -(-n_cones // columns))
    cmap = plt.get_cmap(TIME_CMAP)
    norm = plt.Normalize(min(float(tr.t_s[0]) for _, tr in tracks), max(float(tr.t_s[-1]) for _, tr in tracks))
    fig, axes = plt.subplots(rows_per_run * len(tracks), columns, figsize=(7.4 * columns + 1.0,
                             7.8 * rows_per_run * len(tracks)), squeeze=False, layout="constrained")
    for r, (label, tr) in enumerate(tracks):
        panels = list(axes[r * rows_per_run:(r + 1) * rows_per_run].ravel())
        for ax, cone in zip(panels, tr.cones, strict=False):
            _draw(ax, plt, label, tr, cone, norm, cmap)
        for ax in panels[len(tr.cones):]:
            ax.set_axis_off()
            if not tr.cones:
                ax.text(0.5, 0.5, f"{label}: no pointing constraint configured", ha="center", transform=ax.transAxes)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=list(axes.ravel()), shrink=0.7, label="t [s]")
    fig.suptitle(title or "boresights on the sky, each centred on its constraint's target")
    return _save(plt, fig, path)


__all__ = ["ConeTrack", "SkyRun", "SkyTrack", "body_axis_in_hill", "cone_track", "intervened_steps", "map_frames",
           "plot_skymap", "project", "ring", "sky_track", "small_circle", "sun_frames"]
