"""Paper-style figure of one run (or several overlaid): Figs. 11-14 of McQuinn et al., for any configured
pointing constraints.

Panels: (a) the first pointing constraint's boresight and its target in Hill x-y; one panel per pointing
constraint (`constraints.pointing`, in order): its boresight's angle to its target against the half-angle;
the temperature of the thermal face; omega; omega_dot; psi; psi_dot; the energy. The first two cones take
the paper's places (b) and (c) of the 3x3 grid, so the default configuration draws the paper's figure; a
third and later cones add rows below it, (j), (k), ... (one panel each: a cone's margin is read off its own
limit line, which a shared panel would lose). Limits are dashed black lines, the unsafe side is shaded red,
the safe side green, as in the paper; a windowed cone's times outside its windows are shaded grey.

Also the labels every picture of a run uses for what it draws (`body_label`, `target_label`, `limit_text`).
matplotlib is imported here only (Agg backend), so the core never needs it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rta_attitude.config.schema import Config, PointingConstraint, wheel_constraint_name
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics.environment import sun_direction, target_direction, target_kind
from rta_attitude.dynamics.state import ENERGY, OMEGA, STATE_SIZE, TEMP, THETA_S, Q, wheel_columns
from rta_attitude.errors import RtaError
from rta_attitude.files import atomic

Array = NDArray[np.float64]
CELSIUS_OFFSET_K = 273.15
AXIS_COLORS = ("tab:blue", "tab:orange", "tab:green")
PANEL_COLUMNS = 3
PAPER_CONE_SLOTS = (1, 2)
"""The grid slots (row-major) of the first two cones: the paper's (b) and (c)."""
FIXED_SLOTS = 9
"""Slots of the paper's 3x3 grid; cones after the first two take the slots after it."""
TARGET_LABELS = {"sun": "sun", "earth": "Earth", "orbit_normal": "orbit normal", "velocity": "velocity"}
"""How a named target is written in figures and texts; fixed vectors are written out (`target_label`)."""


class RunSeries(Protocol):
    """What the figure needs of a run (simulation.Trajectory and bag analysis both provide it)."""

    t_s: Array
    """Sample times (N + 1,), s."""
    x: Array
    """States (N + 1, 19), model units."""
    u: Array
    """Applied wheel accelerations (N, 3), rad/s^2."""
    omega_dot: Array
    """Body angular accelerations (N, 3), rad/s^2."""


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise RtaError("figures need matplotlib: pip install matplotlib") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(plt: Any, fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Write the figure as PNG through `files.atomic` (never a half-written file) and close it."""
    out = Path(path)
    try:
        with atomic(out) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return out


def _shade(ax: Any, lo: float | None, hi: float | None, safe_lo: float, safe_hi: float) -> None:
    """Dashed limits; red outside [safe_lo, safe_hi], green inside (within the current y range)."""
    y0, y1 = ax.get_ylim()
    y0, y1 = min(y0, safe_lo if np.isfinite(safe_lo) else y0), max(y1, safe_hi if np.isfinite(safe_hi) else y1)
    for lim in (lo, hi):
        if lim is not None:
            ax.axhline(lim, color="k", ls="--", lw=1)
    ax.axhspan(max(y0, safe_lo), min(y1, safe_hi), color="tab:green", alpha=0.08, lw=0)
    if np.isfinite(safe_lo) and safe_lo > y0:
        ax.axhspan(y0, safe_lo, color="tab:red", alpha=0.12, lw=0)
    if np.isfinite(safe_hi) and safe_hi < y1:
        ax.axhspan(safe_hi, y1, color="tab:red", alpha=0.12, lw=0)
    ax.set_ylim(y0, y1)


def body_label(v: ArrayLike) -> str:
    """A body direction as written in figures: '+i_B', '-k_B' for a body axis, else its components
    ('[0.58, 0.58, 0.58]_B')."""
    v = np.asarray(v, dtype=float)
    for i, letter in enumerate("ijk"):
        for sign, text in ((1.0, "+"), (-1.0, "-")):
            if np.allclose(v, sign * np.eye(3)[i], rtol=0.0, atol=1e-12):
                return f"{text}{letter}_B"
    return "[" + ", ".join(f"{c:.2f}" for c in v) + "]_B"


def target_label(target: str, vector: ArrayLike | None = None) -> str:
    """A target as written in figures: 'sun', 'Earth', 'orbit normal', 'velocity'; a fixed vector with its
    frame ('[0.00, 0.00, 1.00]_H' in Hill, '..._I' inertial)."""
    if target in TARGET_LABELS:
        return TARGET_LABELS[target]
    frame = "H" if target == "hill" else "I"
    return "[" + ", ".join(f"{c:.2f}" for c in np.asarray(vector, dtype=float)) + f"]_{frame}"


def limit_text(kind: str, half_angle_rad: float) -> str:
    """A cone's limit on the angle: '>= 40.0 deg' (keep_out: outside the cone) or '<= 90.0 deg' (keep_in)."""
    return f"{'<=' if kind == 'keep_in' else '>='} {math.degrees(half_angle_rad):.1f} deg"


def cone_targets(cone: PointingConstraint, theta_S_rad: ArrayLike, beta_rad: float) -> Array:
    """A cone's target direction in Hill (N, 3) at sun angles theta_S (N,) (`environment.target_direction`)."""
    code, vector = target_kind(cone.target)
    if cone.target_vector is not None:
        vector = cone.target_vector
    return target_direction(code, np.asarray(vector, dtype=float), np.asarray(theta_S_rad, dtype=float), beta_rad)


def outside_windows_s(windows_s: Sequence[tuple[float, float]], t0_s: float, t1_s: float) -> list[tuple[float, float]]:
    """The spans of [t0, t1] (s) outside a cone's windows; none for a cone without windows (always on)."""
    if not windows_s:
        return []
    spans, start = [], t0_s
    for a, b in windows_s:
        if a > start:
            spans.append((start, min(a, t1_s)))
        start = max(start, b)
    if start < t1_s:
        spans.append((start, t1_s))
    return [(a, b) for a, b in spans if b > a]


def cone_slots(n_cones: int) -> list[int]:
    """The grid slots (row-major, PANEL_COLUMNS wide) of n cone panels: the paper's (b) and (c), then the
    slots after the 3x3 grid."""
    return [*PAPER_CONE_SLOTS, *range(FIXED_SLOTS, FIXED_SLOTS + max(0, n_cones - len(PAPER_CONE_SLOTS)))][:n_cones]


def _first_cone_panel(ax: Any, plt: Any, runs: Sequence[tuple[str, RunSeries]], cfg: Config) -> None:
    """(a): the first cone's boresight and its target in Hill x-y (without cones, +i_B and the sun)."""
    cone = cfg.pointing[0] if cfg.pointing else None
    axis = np.array(cone.boresight_body if cone else (1.0, 0.0, 0.0))
    name = body_label(axis) + (f" ({cone.name})" if cone else "")
    where = target_label(cone.target, cone.target_vector) if cone else "sun"
    beta = cfg.environment.sun_beta_rad
    for k, (label, run) in enumerate(runs):
        x = np.asarray(run.x)
        target = cone_targets(cone, x[:, THETA_S], beta) if cone else sun_direction(x[:, THETA_S], beta)
        boresight = np.einsum("kij,i->kj", quat.attitude_matrices(x[:, Q]), axis)  # A(q)^T b: b in Hill
        if k == 0:
            ax.plot(target[:, 0], target[:, 1], color="gold", lw=2, marker="o" if np.ptp(target[:, :2]) == 0 else None,
                    label=f"{where}")
        ax.plot(boresight[:, 0], boresight[:, 1], ls="-" if k == 0 else "--", lw=1, label=f"{body_label(axis)} {label}")
    ax.add_patch(plt.Circle((0, 0), 1.0, fill=False, color="0.7", lw=0.8))
    ax.set_aspect("equal")
    ax.set(title=f"(a) {name} and {where}, Hill x-y", xlabel="x_H", ylabel="y_H")


def _cone_panel(ax: Any, letter: str, cone: PointingConstraint, runs: Sequence[tuple[str, RunSeries]],
                angles_rad: Sequence[Array]) -> None:
    """One cone's panel: its boresight's angle to its target over time against its half-angle."""
    for k, ((label, run), theta) in enumerate(zip(runs, angles_rad, strict=True)):
        ax.plot(np.asarray(run.t_s), np.degrees(theta), ls="-" if k == 0 else "--", label=label)
    t0 = min(float(np.asarray(run.t_s)[0]) for _, run in runs)
    t1 = max(float(np.asarray(run.t_s)[-1]) for _, run in runs)
    for i, (a, b) in enumerate(outside_windows_s(cone.windows_s, t0, t1)):
        ax.axvspan(a, b, color="0.5", alpha=0.15, lw=0, label="outside its windows" if i == 0 else None)
    half = math.degrees(cone.half_angle_rad)
    if cone.keep_in:
        _shade(ax, None, half, -np.inf, half)
    else:
        _shade(ax, half, None, half, np.inf)
    ax.set(title=f"({letter}) {cone.name}: {body_label(cone.boresight_body)} to "
                 f"{target_label(cone.target, cone.target_vector)}",
           ylabel=f"angle [deg] ({cone.kind.replace('_', ' ')} {limit_text(cone.kind, cone.half_angle_rad)})")


def plot_runs(runs: Sequence[tuple[str, RunSeries]], cfg: Config, path: str | Path, title: str = "") -> Path:
    """Draw the figure of one or more runs (overlaid, labelled) and save it as PNG: the paper's 3x3 grid, and a
    row more for every three cones after the second (module docstring).

    Args:
        runs: (label, series) pairs; the first is drawn solid, others dashed.
        cfg: configuration (limits, the pointing constraints).
        path: output PNG path.
        title: figure title.

    Returns:
        The path written.
    """
    plt = _pyplot()
    L = cfg.limits
    u_max = cfg.u_max_rad_s2
    slots = cone_slots(len(cfg.pointing))
    rows = max(FIXED_SLOTS, (max(slots) + 1) if slots else 0)
    rows = -(-rows // PANEL_COLUMNS)
    fig, axes = plt.subplots(rows, PANEL_COLUMNS, figsize=(15, 11 / 3 * rows), squeeze=False)
    ax = axes.ravel()
    w_lim = np.degrees(L.omega_max_rad_s)
    wd_lim = np.degrees(L.omega_dot_max_rad_s2)
    constraints = ConstraintSet(cfg.body_model)
    n_wheels = cfg.spacecraft.n_wheels
    wheels = [wheel_constraint_name(w).removeprefix("psi_") for w in cfg.spacecraft.wheel_names]  # the paper's x y z
    angles = [constraints.angles(np.asarray(run.x)[:, :STATE_SIZE]) for _, run in runs]  # (q and t alone)
    _first_cone_panel(ax[0], plt, runs, cfg)
    for slot, cone in zip(slots, cfg.pointing, strict=True):
        _cone_panel(ax[slot], chr(ord("a") + slot), cone, runs, [a[cone.name] for a in angles])
    for slot in range(len(ax)):
        if slot not in slots and (slot in PAPER_CONE_SLOTS or slot >= FIXED_SLOTS):
            ax[slot].set_axis_off()
    for k, (label, run) in enumerate(runs):
        ls = "-" if k == 0 else "--"
        t, x = np.asarray(run.t_s), np.asarray(run.x)
        tu = t[:-1]
        ax[3].plot(t, x[:, TEMP] - CELSIUS_OFFSET_K, ls=ls, label=label)
        for i in range(3):
            lab = f"{'xyz'[i]} {label}" if len(runs) > 1 else "xyz"[i]
            ax[4].plot(t, np.degrees(x[:, OMEGA.start + i]), ls=ls, color=AXIS_COLORS[i], label=lab)
            ax[5].plot(tu, np.degrees(np.asarray(run.omega_dot)[:, i]), ls=ls, color=AXIS_COLORS[i], label=lab)
        for i, (col, wheel) in enumerate(zip(wheel_columns(n_wheels), wheels, strict=True)):
            lab = f"{wheel} {label}" if len(runs) > 1 else wheel
            color = AXIS_COLORS[i] if n_wheels == 3 else None
            ax[6].plot(t, x[:, col], ls=ls, color=color, label=lab)
            ax[7].plot(tu, np.asarray(run.u)[:, i], ls=ls, color=color, label=lab)
        ax[8].plot(t, x[:, ENERGY] / 1000.0, ls=ls, label=label)
    T_max = L.temperature_max_K - CELSIUS_OFFSET_K
    ax[3].set(title=f"(d) temperature, {body_label(cfg.thermal.face_normal_body)} face", ylabel="T [degC]")
    _shade(ax[3], None, T_max, -np.inf, T_max)
    ax[4].set(title="(e) angular rate", ylabel="omega [deg/s]")
    _shade(ax[4], -w_lim, w_lim, -w_lim, w_lim)
    ax[5].set(title="(f) angular acceleration", ylabel="omega_dot [deg/s^2]")
    _shade(ax[5], -wd_lim, wd_lim, -wd_lim, wd_lim)
    ax[6].set(title="(g) wheel speed", ylabel="psi [rad/s]")
    _shade(ax[6], -L.psi_max_rad_s, L.psi_max_rad_s, -L.psi_max_rad_s, L.psi_max_rad_s)
    ax[7].set(title="(h) wheel acceleration (applied)", ylabel="psi_dot [rad/s^2]")
    for i in range(3):
        for sgn in (-1, 1):
            ax[7].axhline(sgn * u_max[i], color=AXIS_COLORS[i], ls=":", lw=0.8)
    _shade(ax[7], -L.wheel_accel_max_rad_s2, L.wheel_accel_max_rad_s2, -L.wheel_accel_max_rad_s2,
           L.wheel_accel_max_rad_s2)
    E_min = L.energy_min_J / 1000.0
    ax[8].set(title="(i) battery energy", ylabel="E [kJ]")
    _shade(ax[8], E_min, None, E_min, np.inf)
    for slot in (*slots, *range(3, FIXED_SLOTS)):
        ax[slot].set_xlabel("t [s]")
        ax[slot].grid(alpha=0.3)
    for a in (ax[0], ax[4], ax[5], ax[6], ax[7]):
        a.legend(fontsize=7, loc="best")
    for slot, cone in zip(slots, cfg.pointing, strict=True):
        if len(runs) > 1 or cone.windows_s:
            ax[slot].legend(fontsize=7, loc="best")
    if len(runs) > 1:
        for a in (ax[3], ax[8]):
            a.legend(fontsize=7, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(plt, fig, path)


__all__ = ["RunSeries", "body_label", "cone_slots", "cone_targets", "limit_text", "outside_windows_s", "plot_runs",
           "target_label"]
