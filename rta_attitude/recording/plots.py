"""Paper-style 3x3 figure of one run (or several overlaid): Figs. 11-14 of McQuinn et al.

Panels: (a) sensor boresight and sun direction in Hill, (b) sensor-sun angle, (c) antenna-Earth
angle, (d) temperature, (e) omega, (f) omega_dot, (g) psi, (h) psi_dot, (i) energy. Limits are
dashed black lines, the unsafe side is shaded red, the safe side green, as in the paper.
matplotlib is imported here only (Agg backend), so the core never needs it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics import quaternion as quat
from rta_attitude.dynamics.spacecraft import sun_hill
from rta_attitude.dynamics.state import ENERGY, OMEGA, PSI, TEMP, THETA_S, Q
from rta_attitude.errors import RtaError
from rta_attitude.files import atomic

Array = NDArray[np.float64]
CELSIUS_OFFSET_K = 273.15
AXIS_COLORS = ("tab:blue", "tab:orange", "tab:green")


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


def plot_runs(runs: Sequence[tuple[str, RunSeries]], cfg: Config, path: str | Path, title: str = "") -> Path:
    """Draw the 3x3 figure of one or more runs (overlaid, labelled) and save it as PNG.

    Args:
        runs: (label, series) pairs; the first is drawn solid, others dashed.
        cfg: configuration (limits).
        path: output PNG path.
        title: figure title.

    Returns:
        The path written.
    """
    plt = _pyplot()
    L = cfg.limits
    u_max = cfg.u_max_rad_s2
    fig, axes = plt.subplots(3, 3, figsize=(15, 11))
    ax = axes.ravel()
    w_lim = np.degrees(L.omega_max_rad_s)
    wd_lim = np.degrees(L.omega_dot_max_rad_s2)
    for k, (label, run) in enumerate(runs):
        ls = "-" if k == 0 else "--"
        t, x = np.asarray(run.t_s), np.asarray(run.x)
        tu = t[:-1]
        sun = np.array([sun_hill(float(th)) for th in x[:, THETA_S]])  # (cos, sin): the sun in the Hill x-y plane
        boresight = quat.attitude_matrices(x[:, Q])[:, 0, :]  # row 0 of A(q): +i_B in Hill
        angles = ConstraintSet(cfg).angles(x)
        if k == 0:
            ax[0].plot(sun[:, 0], sun[:, 1], color="gold", lw=2, label="sun r_S")
        ax[0].plot(boresight[:, 0], boresight[:, 1], ls=ls, lw=1, label=f"+i_B {label}")
        ax[1].plot(t, np.degrees(angles["sensor_sun"]), ls=ls, label=label)
        ax[2].plot(t, np.degrees(angles["antenna_earth"]), ls=ls, label=label)
        ax[3].plot(t, x[:, TEMP] - CELSIUS_OFFSET_K, ls=ls, label=label)
        for i in range(3):
            lab = f"{'xyz'[i]} {label}" if len(runs) > 1 else "xyz"[i]
            ax[4].plot(t, np.degrees(x[:, OMEGA.start + i]), ls=ls, color=AXIS_COLORS[i], label=lab)
            ax[5].plot(tu, np.degrees(np.asarray(run.omega_dot)[:, i]), ls=ls, color=AXIS_COLORS[i], label=lab)
            ax[6].plot(t, x[:, PSI.start + i], ls=ls, color=AXIS_COLORS[i], label=lab)
            ax[7].plot(tu, np.asarray(run.u)[:, i], ls=ls, color=AXIS_COLORS[i], label=lab)
        ax[8].plot(t, x[:, ENERGY] / 1000.0, ls=ls, label=label)
    ax[0].add_patch(plt.Circle((0, 0), 1.0, fill=False, color="0.7", lw=0.8))
    ax[0].set_aspect("equal")
    ax[0].set(title="(a) sensor boresight and sun, Hill x-y", xlabel="x_H", ylabel="y_H")
    ax[1].set(title="(b) sensor-to-sun angle", ylabel="theta_EZ [deg]")
    _shade(ax[1], np.degrees(L.exclusion_angle_rad), None, np.degrees(L.exclusion_angle_rad), np.inf)
    ax[2].set(title="(c) antenna-to-Earth angle", ylabel="theta_GS [deg]")
    _shade(ax[2], None, np.degrees(L.comm_angle_rad), -np.inf, np.degrees(L.comm_angle_rad))
    T_max = L.temperature_max_K - CELSIUS_OFFSET_K
    ax[3].set(title="(d) temperature, -j_B face", ylabel="T [degC]")
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
    for a in ax[1:]:
        a.set_xlabel("t [s]")
        a.grid(alpha=0.3)
    for a in (ax[0], ax[4], ax[5], ax[6], ax[7]):
        a.legend(fontsize=7, loc="best")
    if len(runs) > 1:
        for a in (ax[1], ax[2], ax[3], ax[8]):
            a.legend(fontsize=7, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(plt, fig, path)


__all__ = ["RunSeries", "plot_runs"]
