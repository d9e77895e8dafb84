"""The attitude scene of a run in the Hill frame, and its animation (`analyze --animate`).

`scene` returns, per sample, what a GNC engineer wants to see turn (no matplotlib): the body axes in Hill,
and for every configured pointing constraint (`constraints.pointing`, in order) its boresight in Hill, its
target's direction in Hill, its half-angle and kind, the boresight's angle to the target and the margin h;
besides, the panel normal, the sun and the Earth, and the steps the filter changed. No constraint is named
here: the cones are whatever the configuration lists. Everything comes from the package's one definition of
the geometry: `quaternion.attitude_matrices` (A(q), Hill -> body: a body vector b reads A(q)^T b in Hill),
`environment.target_direction` and `sun_direction`, `ConstraintSet.angles` (the angles the barriers act on)
and `ConstraintSet.safety_values` (h, with the cones' time windows).

A cone's margin is its physical h in rad: theta - alpha (keep_out) or alpha - theta (keep_in), and +inf at
the samples outside its time windows (nothing to keep there; `ConeView.applies` says where it holds).

`animate_scene` draws it as a GIF (Pillow, which matplotlib ships with) or an MP4 (needs ffmpeg on the
PATH), at most `frames` frames spread evenly over the run, with a progress bar while it renders. Each cone
is drawn about its target (keep_out red, keep_in blue); each boresight is coloured by its margin: green
(ok), orange (within `warn_rad` of its limit), red (violated), grey outside the cone's windows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.config.schema import Config, PointingConstraint
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics.environment import EARTH_HILL, sun_direction
from rta_attitude.dynamics.state import STATE_SIZE, THETA_S, Q
from rta_attitude.errors import RtaError
from rta_attitude.files import atomic
from rta_attitude.recording.plots import _pyplot, body_label, cone_targets, limit_text, target_label
from rta_attitude.recording.skymap import SkyRun, body_axis_in_hill, intervened_steps, ring

Array = NDArray[np.float64]

WARN_RAD = np.radians(5.0)
"""Default warning band: a margin below this is drawn orange."""
MARGIN_COLORS = ("tab:green", "tab:orange", "tab:red")
INACTIVE_COLOR = "0.6"
"""A boresight outside its cone's windows (the constraint does not apply)."""
KIND_COLORS = {"keep_out": "tab:red", "keep_in": "tab:blue"}
"""A cone's colour by kind."""
TARGET_COLORS = {"sun": "gold", "earth": "tab:blue"}
OTHER_TARGET_COLOR = "tab:purple"
BORESIGHT_STYLES = ("-", "--", ":", "-.")
"""Line styles that tell the cones' boresight arrows apart, in order."""
CONE_LINES = 16
"""Generator lines drawn on each cone."""
FORMATS = ("gif", "mp4")
DPI = 80
LEGEND = ("boresights (one line style per cone): green ok, orange within {warn:.0f}° of the limit, red violated, "
          "grey outside the cone's windows\nred cones: keep out, about their target; blue cones: keep in; grey: "
          "the panel normal")


@dataclass(frozen=True)
class ConeView:
    """One pointing constraint in a scene, per sample (N samples), directions unit vectors in Hill.

    Attributes:
        name, kind: the constraint's name and kind ('keep_out' or 'keep_in').
        target: its target (`schema.TARGET_NAMES`); target_vector: the fixed vector of 'hill' and 'inertial'.
        half_angle_rad: the cone's half-angle.
        boresight_body: the boresight in body axes (3,).
        boresight: the boresight in Hill (N, 3), A(q)^T b.
        target_hill: the target's direction in Hill (N, 3).
        angle_rad: the angle between them (N,) (`ConstraintSet.angles`).
        margin_rad: h (N,): theta - alpha (keep_out), alpha - theta (keep_in); +inf outside its windows.
    """

    name: str
    kind: str
    target: str
    target_vector: tuple[float, float, float] | None
    half_angle_rad: float
    boresight_body: tuple[float, float, float]
    boresight: Array
    target_hill: Array
    angle_rad: Array
    margin_rad: Array

    @property
    def keep_in(self) -> bool:
        return self.kind == "keep_in"

    @property
    def applies(self) -> NDArray[np.bool_]:
        """(N,) the constraint holds at the sample (inside its windows, or it has none)."""
        return np.asarray(~np.isposinf(self.margin_rad))

    @property
    def label(self) -> str:
        """'+i_B exclusion_zone' (the boresight, then the name)."""
        return f"{body_label(self.boresight_body)} {self.name}"


@dataclass(frozen=True)
class Scene:
    """A run's attitude scene, per sample (N samples), all directions unit vectors in Hill.

    Attributes:
        t_s: sample times (N,), s.
        body_axes: (N, 3, 3), row i = body axis i (+i_B, +j_B, +k_B) in Hill.
        panel: the solar panel's normal (`power.panel_normal_body`) in Hill (N, 3).
        sun: the sun direction r_S (N, 3).
        earth: the Earth (nadir) direction (3,), fixed in Hill.
        cones: the configured pointing constraints, in order (`ConeView`).
        intervened: the filter changed the command of the step starting at the sample (N,).
    """

    t_s: Array
    body_axes: Array
    panel: Array
    sun: Array
    earth: Array
    cones: tuple[ConeView, ...]
    intervened: NDArray[np.bool_]


def target_owners(cones: Sequence[PointingConstraint | ConeView]) -> list[int]:
    """For each cone, the index of the first cone aimed at the same target (the same name and, for 'hill' and
    'inertial', the same vector): the one whose arrow draws that target."""
    keys = [(c.target, c.target_vector) for c in cones]
    return [keys.index(k) for k in keys]


def scene(run: SkyRun, cfg: Config, constraints: ConstraintSet | None = None) -> Scene:
    """The run's attitude scene (no matplotlib); `constraints`: a ConstraintSet of cfg made once by a caller
    that draws many runs or samples."""
    sc = scene_of_states(run.t_s, run.x, cfg, constraints)
    inter = np.zeros(len(sc.t_s), dtype=bool)
    inter[: len(run.u)] = intervened_steps(run)
    return replace(sc, intervened=inter)


def scene_of_states(t_s: ArrayLike, x: ArrayLike, cfg: Config, constraints: ConstraintSet | None = None) -> Scene:
    """The scene of states x (N, 19) at times t_s (N,) (s from the run's t = 0: the cones' windows), without
    commands (`intervened` all False): what the scene node draws at each state it receives."""
    t = np.asarray(t_s, dtype=float).reshape(-1)
    x = np.asarray(x, dtype=float).reshape(-1, STATE_SIZE)
    cs = constraints or ConstraintSet(cfg)
    A = quat.attitude_matrices(x[:, Q])
    beta = cfg.environment.sun_beta_rad
    angles = cs.angles(x)
    h = cs.safety_values(x, t)
    cones = tuple(
        ConeView(name=c.name, kind=c.kind, target=c.target, target_vector=c.target_vector,
                 half_angle_rad=c.half_angle_rad, boresight_body=c.boresight_body,
                 boresight=body_axis_in_hill(A, c.boresight_body), target_hill=cone_targets(c, x[:, THETA_S], beta),
                 angle_rad=angles[c.name], margin_rad=h[:, cs.registry.index(c.name)])
        for c in cfg.pointing)  # fmt: skip
    return Scene(t_s=t, body_axes=A, panel=body_axis_in_hill(A, cfg.power.panel_normal_body),
                 sun=sun_direction(x[:, THETA_S], beta), earth=np.array(EARTH_HILL, dtype=float), cones=cones,
                 intervened=np.zeros(len(t), dtype=bool))


def margin_level(margin_rad: Array | float, warn_rad: float = WARN_RAD) -> NDArray[np.int_]:
    """0 ok, 1 within warn_rad of the limit, 2 violated (index into MARGIN_COLORS); +inf (outside a cone's
    windows) is 0."""
    m = np.asarray(margin_rad, dtype=float)
    return np.where(m < 0.0, 2, np.where(m < warn_rad, 1, 0))


def cone_text(cone: ConeView, k: int) -> str:
    """One line on a cone at sample k, at most about 60 characters for a name of up to 24:
    'exclusion_zone 52.3 deg (>= 40.0 deg)', or '... (outside its windows)'."""
    where = limit_text(cone.kind, cone.half_angle_rad) if cone.applies[k] else "outside its windows"
    return f"{cone.name} {math.degrees(float(cone.angle_rad[k])):.1f} deg ({where})"


def cone_lines(axis: Array, half_angle_rad: float, length: float = 1.0, lines: int = CONE_LINES) -> Array:
    """A cone about a unit direction as `lines` generator segments from the origin and its rim circle:
    (lines + 1, 2 or 65, 3); the segments' far ends lie at half_angle_rad from `axis`."""
    rim = length * ring(axis, half_angle_rad, 65)
    picks = rim[np.linspace(0, 64, lines, endpoint=False).astype(int)]
    segments = [np.stack([np.zeros(3), p]) for p in picks]
    return np.array([*[np.pad(s, ((0, 63), (0, 0)), mode="edge") for s in segments], rim])


def frame_samples(samples: int, frames: int) -> list[int]:
    """min(samples, frames) sample indices, evenly spread from the first to the last."""
    return [int(k) for k in np.round(np.linspace(0, samples - 1, min(samples, frames)))]


def check_animation(path: Path, frames: int) -> str:
    """The animation's format ('gif' or 'mp4', by the suffix of `path`).

    Raises:
        RtaError: another suffix, or frames < 2.
    """
    fmt = Path(path).suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise RtaError(f"animation format must be one of {', '.join(FORMATS)} (by the file suffix), "
                       f"got {Path(path).name!r}")
    if frames < 2:
        raise RtaError(f"an animation needs at least 2 frames, got {frames}")
    return fmt


def _draw_body(ax: Any, body_axes: Array) -> None:
    """The body: a 1 x 2 x 3 box (a 6U CubeSat's proportions) in body axes, drawn in Hill."""
    half = np.array([0.1, 0.2, 0.3])
    for i in range(3):
        j, m = (i + 1) % 3, (i + 2) % 3
        for sa in (-1, 1):
            for sb in (-1, 1):
                ends = []
                for si in (-1, 1):
                    p = np.zeros(3)
                    p[i], p[j], p[m] = si * half[i], sa * half[j], sb * half[m]
                    ends.append(p @ body_axes)
                ax.plot(*np.array(ends).T, color="0.2", lw=0.8)


def _draw_frame(ax: Any, sc: Scene, k: int, title: str, warn_rad: float) -> None:
    """Sample k of the scene on a cleared 3D axes."""
    ax.cla()
    for set_lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        set_lim(-1.1, 1.1)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x_H (radial)")
    ax.set_ylabel("y_H (along-track)")
    ax.set_zlabel("z_H (orbit normal)")
    owners = target_owners(sc.cones)
    for i, cone in enumerate(sc.cones):
        active = bool(cone.applies[k])
        for seg in cone_lines(cone.target_hill[k], cone.half_angle_rad, length=0.9, lines=12):
            ax.plot(*seg.T, color=KIND_COLORS[cone.kind], lw=0.6, alpha=0.45 if active else 0.12)
        if owners[i] == i:
            tip = cone.target_hill[k]
            ax.quiver(0, 0, 0, *(1.05 * tip), color=TARGET_COLORS.get(cone.target, OTHER_TARGET_COLOR), lw=2.5,
                      arrow_length_ratio=0.08)
            ax.text(*(1.12 * tip), target_label(cone.target, cone.target_vector), fontsize=8)
        color = MARGIN_COLORS[int(margin_level(cone.margin_rad[k], warn_rad))] if active else INACTIVE_COLOR
        length = 1.0 - 0.1 * (i % 3)
        ax.quiver(0, 0, 0, *(length * cone.boresight[k]), color=color, lw=2.5, arrow_length_ratio=0.1,
                  linestyle=BORESIGHT_STYLES[i % len(BORESIGHT_STYLES)])
        ax.text(*((length + 0.05) * cone.boresight[k]), cone.label, fontsize=7)
    ax.quiver(0, 0, 0, *(0.6 * sc.panel[k]), color="0.3", lw=2.0, arrow_length_ratio=0.12)
    ax.text(*(0.68 * sc.panel[k]), "panel", fontsize=7)
    _draw_body(ax, sc.body_axes[k])
    flag = "filter intervening" if sc.intervened[k] else "primary command passed"
    texts = [cone_text(c, k) for c in sc.cones]
    rows = ["   ".join(texts[i:i + 2]) for i in range(0, len(texts), 2)]
    ax.set_title("\n".join([title, f"t = {sc.t_s[k]:.0f} s   {flag}", *rows]), fontsize=8)


def animate_scene(run: SkyRun, cfg: Config, path: str | Path, title: str = "", frames: int = 200,
                  fps: int = 12, warn_rad: float = WARN_RAD, progress: bool = True) -> Path:
    """Render the run's scene in the Hill frame, at most `frames` frames evenly over the run (the last
    sample always), as a GIF or MP4 (by the suffix of `path`), through `files.atomic` (never a
    half-written file).

    Raises:
        RtaError: unknown suffix, frames < 2, or MP4 without ffmpeg.
    """
    out = Path(path)
    fmt = check_animation(out, frames)
    plt = _pyplot()
    from matplotlib import animation

    if fmt == "mp4" and not animation.FFMpegWriter.isAvailable():
        raise RtaError("an MP4 animation needs ffmpeg on the PATH; use a .gif name instead")
    sc = scene(run, cfg)
    picks = frame_samples(len(sc.t_s), frames)
    fig = plt.figure(figsize=(6.4, 6.8))
    ax = fig.add_subplot(projection="3d")
    fig.text(0.5, 0.02, LEGEND.format(warn=np.degrees(warn_rad)), ha="center", fontsize=6)

    bar: Any = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(picks), desc=f"rendering {out.name}", unit="frame", leave=False)

    def frame(i: int) -> list[Any]:
        _draw_frame(ax, sc, picks[i], title, warn_rad)
        if bar is not None:
            bar.update(1)
        return []

    anim = animation.FuncAnimation(fig, frame, frames=len(picks), init_func=list, blit=False)
    writer = animation.PillowWriter(fps=fps) if fmt == "gif" else animation.FFMpegWriter(fps=fps)
    try:
        with atomic(out) as tmp:  # an OSError: OutputError, one line; nothing left under `out`
            anim.save(str(tmp), writer=writer, dpi=DPI)
    finally:
        if bar is not None:
            bar.close()
        plt.close(fig)
    return out


__all__ = ["ConeView", "Scene", "animate_scene", "check_animation", "cone_lines", "cone_text", "frame_samples",
           "margin_level", "scene", "scene_of_states", "target_owners"]
