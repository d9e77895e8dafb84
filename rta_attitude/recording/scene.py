"""The attitude scene of a run in the Hill frame, and its animation (`analyze --animate`).

`scene` returns, per sample, what a GNC engineer wants to see turn (no matplotlib): the body axes in
Hill (+i_B the sensor boresight, +j_B the antenna, +k_B the solar panel; -j_B is the hot face), the
sun direction with the sensor keep-out cone (half-angle FOV/2 + beta), the Earth direction (the ground
station, -x_H) with the antenna's cone (half-angle comm_fov/2), the exclusion-zone and communication
angles and margins, and the steps the filter changed. Everything comes from the package's one
definition of the geometry: `quaternion.attitude_matrices` (A(q), Hill -> body: row i is body axis i in
Hill), `spacecraft.sun_hill` and the cone rings through the sky map's helpers (`skymap.sun_frames`,
`body_axis_in_hill`, `ring`), `spacecraft.EARTH_HILL`, the constraints' `AXIS_BODY` and
`ConstraintSet.angles`.

`animate_scene` draws it as a GIF (Pillow, which matplotlib ships with) or an MP4 (needs ffmpeg on the
PATH), one frame per `stride` samples, with a progress bar while it renders. Each boresight is coloured
by its margin: green (ok), orange (within `warn_rad` of its limit), red (violated).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet, battery, communication, exclusion_zone
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics.spacecraft import EARTH_HILL
from rta_attitude.dynamics.state import STATE_SIZE, THETA_S, Q
from rta_attitude.errors import RtaError
from rta_attitude.files import atomic
from rta_attitude.recording.plots import _pyplot
from rta_attitude.recording.skymap import SkyRun, body_axis_in_hill, intervened_steps, ring, sun_frames

Array = NDArray[np.float64]

WARN_RAD = np.radians(5.0)
"""Default warning band: a margin below this is drawn orange."""
MARGIN_COLORS = ("tab:green", "tab:orange", "tab:red")
CONE_LINES = 16
"""Generator lines drawn on each cone."""
FORMATS = ("gif", "mp4")
DPI = 80
LEGEND = ("+i_B sensor (solid), +j_B antenna (dashed): green ok, orange within {warn:.0f}° of the limit, red violated\n"
          "red cone: sensor keep-out about the sun; blue cone: antenna limit about the Earth; grey: +k_B panel")


@dataclass(frozen=True)
class Scene:
    """A run's attitude scene, per sample (N + 1 samples), all directions unit vectors in Hill.

    Attributes:
        t_s: sample times (N + 1,), s.
        body_axes: (N + 1, 3, 3), row i = body axis i (+i_B, +j_B, +k_B) in Hill.
        sensor, antenna, panel: +i_B (exclusion_zone.AXIS_BODY), +j_B (communication.AXIS_BODY) and
            +k_B (battery.AXIS_BODY) in Hill (N + 1, 3).
        sun: the sun direction r_S (N + 1, 3).
        earth: the Earth (ground station) direction (3,).
        sensor_sun_rad, antenna_earth_rad: theta_EZ and theta_GS (N + 1,) (`ConstraintSet.angles`).
        keep_out_rad, comm_rad: FOV/2 + beta and comm_fov/2.
        intervened: the filter changed the command of the step starting at the sample (N + 1,).
    """

    t_s: Array
    body_axes: Array
    sensor: Array
    antenna: Array
    panel: Array
    sun: Array
    earth: Array
    sensor_sun_rad: Array
    antenna_earth_rad: Array
    keep_out_rad: float
    comm_rad: float
    intervened: NDArray[np.bool_]

    @property
    def sensor_margin_rad(self) -> Array:
        """theta_EZ - (FOV/2 + beta): >= 0 is safe."""
        return self.sensor_sun_rad - self.keep_out_rad

    @property
    def antenna_margin_rad(self) -> Array:
        """comm_fov/2 - theta_GS: >= 0 is safe."""
        return self.comm_rad - self.antenna_earth_rad


def scene(run: SkyRun, cfg: Config, constraints: ConstraintSet | None = None) -> Scene:
    """The run's attitude scene (no matplotlib); `constraints`: a ConstraintSet of cfg made once by a caller
    that draws many runs or samples."""
    sc = scene_of_states(run.t_s, run.x, cfg, constraints)
    inter = np.zeros(len(sc.t_s), dtype=bool)
    inter[: len(run.u)] = intervened_steps(run)
    return replace(sc, intervened=inter)


def scene_of_states(t_s: ArrayLike, x: ArrayLike, cfg: Config, constraints: ConstraintSet | None = None) -> Scene:
    """The scene of states x (N, 19) at times t_s (N,), without commands (`intervened` all False): what
    the scene node draws at each state it receives."""
    t = np.asarray(t_s, dtype=float).reshape(-1)
    x = np.asarray(x, dtype=float).reshape(-1, STATE_SIZE)
    A = quat.attitude_matrices(x[:, Q])
    sun = sun_frames(x[:, THETA_S])[:, 2]  # the map frames' pole: r_S
    angles = (constraints or ConstraintSet(cfg)).angles(x)
    return Scene(t_s=t, body_axes=A, sensor=body_axis_in_hill(A, exclusion_zone.AXIS_BODY),
                 antenna=body_axis_in_hill(A, communication.AXIS_BODY), panel=body_axis_in_hill(A, battery.AXIS_BODY),
                 sun=sun, earth=np.array(EARTH_HILL, dtype=float), sensor_sun_rad=angles["sensor_sun"],
                 antenna_earth_rad=angles["antenna_earth"], keep_out_rad=cfg.limits.exclusion_angle_rad,
                 comm_rad=cfg.limits.comm_angle_rad, intervened=np.zeros(len(t), dtype=bool))


def margin_level(margin_rad: Array | float, warn_rad: float = WARN_RAD) -> NDArray[np.int_]:
    """0 ok, 1 within warn_rad of the limit, 2 violated (index into MARGIN_COLORS)."""
    m = np.asarray(margin_rad, dtype=float)
    return np.where(m < 0.0, 2, np.where(m < warn_rad, 1, 0))


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
    fig.text(0.5, 0.02, LEGEND.format(warn=np.degrees(warn_rad)), ha="center", fontsize=7)

    def draw(k: int) -> None:
        ax.cla()
        ax.set_xlim(-1.1, 1.1)
        ax.set_ylim(-1.1, 1.1)
        ax.set_zlim(-1.1, 1.1)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("x_H (radial)")
        ax.set_ylabel("y_H (along-track)")
        ax.set_zlabel("z_H (orbit normal)")
        for seg in cone_lines(sc.sun[k], sc.keep_out_rad):
            ax.plot(*seg.T, color="tab:red", lw=0.7, alpha=0.5)
        for seg in cone_lines(sc.earth, sc.comm_rad, length=0.8, lines=8):
            ax.plot(*seg.T, color="tab:blue", lw=0.5, alpha=0.35)
        ax.quiver(0, 0, 0, *(1.05 * sc.sun[k]), color="gold", lw=2.5, arrow_length_ratio=0.08)
        ax.quiver(0, 0, 0, *(0.95 * sc.earth), color="tab:blue", lw=2.0, arrow_length_ratio=0.08)
        s_lvl = int(margin_level(sc.sensor_margin_rad[k], warn_rad))
        a_lvl = int(margin_level(sc.antenna_margin_rad[k], warn_rad))
        ax.quiver(0, 0, 0, *sc.sensor[k], color=MARGIN_COLORS[s_lvl], lw=3.0, arrow_length_ratio=0.1)
        ax.quiver(0, 0, 0, *(0.8 * sc.antenna[k]), color=MARGIN_COLORS[a_lvl], lw=2.5, arrow_length_ratio=0.1,
                  linestyle="--")
        ax.quiver(0, 0, 0, *(0.6 * sc.panel[k]), color="0.3", lw=2.0, arrow_length_ratio=0.12)
        # the body: a 1 x 2 x 3 box (a 6U CubeSat's proportions) in body axes, drawn in Hill
        half = np.array([0.1, 0.2, 0.3])
        for i in range(3):
            for sa in (-1, 1):
                for sb in (-1, 1):
                    j, m = (i + 1) % 3, (i + 2) % 3
                    ends = []
                    for si in (-1, 1):
                        p = np.zeros(3)
                        p[i], p[j], p[m] = si * half[i], sa * half[j], sb * half[m]
                        ends.append(p @ sc.body_axes[k])
                    ax.plot(*np.array(ends).T, color="0.2", lw=0.8)
        for name, v in (("sun", 1.12 * sc.sun[k]), ("Earth", 1.02 * sc.earth), ("+i_B", 1.05 * sc.sensor[k]),
                        ("+j_B", 0.88 * sc.antenna[k]), ("+k_B", 0.68 * sc.panel[k])):
            ax.text(*v, name, fontsize=8)
        flag = "filter intervening" if sc.intervened[k] else "primary command passed"
        ax.set_title(f"{title}\nt = {sc.t_s[k]:.0f} s   sensor-sun {np.degrees(sc.sensor_sun_rad[k]):.1f}° "
                     f"(>= {np.degrees(sc.keep_out_rad):.0f}°)   antenna-Earth "
                     f"{np.degrees(sc.antenna_earth_rad[k]):.1f}° (<= {np.degrees(sc.comm_rad):.0f}°)\n{flag}",
                     fontsize=8)

    bar: Any = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(picks), desc=f"rendering {out.name}", unit="frame", leave=False)

    def frame(i: int) -> list[Any]:
        draw(picks[i])
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


__all__ = ["Scene", "animate_scene", "check_animation", "cone_lines", "frame_samples", "margin_level", "scene"]
