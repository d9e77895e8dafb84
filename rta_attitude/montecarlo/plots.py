"""Fig. 10 of the paper: the Monte Carlo initial conditions per variable, safe runs green, failed red.

matplotlib is imported when a figure is drawn (Agg backend), so the core never needs it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rta_attitude.config.schema import Config
from rta_attitude.dynamics.state import ENERGY, OMEGA, PSI, TEMP, THETA_S
from rta_attitude.errors import RtaError
from rta_attitude.files import atomic

Array = NDArray[np.float64]
CELSIUS_OFFSET_K = 273.15


def _panels(x0: Array, cfg: Config) -> list[tuple[str, Array, tuple[float, float] | None, str]]:
    """(label, values, (lower, upper) limits or None, unit) of each panel, in display units."""
    L = cfg.limits
    w_max = math.degrees(L.omega_max_rad_s)
    out: list[tuple[str, Array, tuple[float, float] | None, str]] = []
    for a, axis in enumerate("xyz"):
        out.append((f"omega_{axis}", np.degrees(x0[:, OMEGA.start + a]), (-w_max, w_max), "deg/s"))
    for a, axis in enumerate("xyz"):
        out.append((f"psi_{axis}", x0[:, PSI.start + a], (-L.psi_max_rad_s, L.psi_max_rad_s), "rad/s"))
    out.append(("theta_S", np.degrees(np.mod(x0[:, THETA_S], 2 * np.pi)), None, "deg"))
    out.append(("T", x0[:, TEMP] - CELSIUS_OFFSET_K, (-math.inf, L.temperature_max_K - CELSIUS_OFFSET_K), "degC"))
    out.append(("E", x0[:, ENERGY] / 1000.0, (L.energy_min_J / 1000.0, math.inf), "kJ"))
    return out


def plot_initial_conditions(x0: Array, failed: NDArray[np.bool_], cfg: Config, path: Path,
                            title: str = "") -> Path:
    """Draw the 3x3 grid of Fig. 10 (run index against each initial value) and save it as PNG.

    Args:
        x0: initial states (n, 19), model units.
        failed: (n,) True for failed runs (red), False for safe runs (green).
        cfg: limits (black dashed lines; the unsafe side shaded red, the safe side green).
        path: PNG file to write.
        title: figure title.

    Returns:
        path.

    Raises:
        RtaError: matplotlib is not installed.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RtaError("the Monte Carlo figure needs matplotlib (pip install matplotlib)") from None
    failed = np.asarray(failed, dtype=bool)
    idx = np.arange(len(x0))
    fig, axes = plt.subplots(3, 3, figsize=(13, 10), constrained_layout=True)
    for ax, (label, vals, lim, unit) in zip(axes.ravel(), _panels(x0, cfg)):
        ax.scatter(idx[~failed], vals[~failed], marker="x", s=6, lw=0.6, color="tab:green", label="safe")
        ax.scatter(idx[failed], vals[failed], marker="x", s=14, lw=0.9, color="tab:red", label="failed")
        lo_v, hi_v = float(np.min(vals)), float(np.max(vals))
        pad = 0.15 * (hi_v - lo_v or 1.0)
        y0, y1 = lo_v - pad, hi_v + pad
        if lim is not None:
            lo, hi = lim
            y0 = min(y0, lo - pad) if math.isfinite(lo) else y0
            y1 = max(y1, hi + pad) if math.isfinite(hi) else y1
            safe_lo = lo if math.isfinite(lo) else y0
            safe_hi = hi if math.isfinite(hi) else y1
            ax.axhspan(safe_lo, safe_hi, color="tab:green", alpha=0.08, lw=0)
            for b in (lo, hi):
                if math.isfinite(b):
                    ax.axhline(b, color="k", ls="--", lw=1.0)
            if math.isfinite(lo):
                ax.axhspan(y0, lo, color="tab:red", alpha=0.08, lw=0)
            if math.isfinite(hi):
                ax.axhspan(hi, y1, color="tab:red", alpha=0.08, lw=0)
        ax.set_ylim(y0, y1)
        ax.set_xlim(-0.5, max(len(x0) - 0.5, 0.5))
        ax.set_title(f"{label}(0)  [{unit}]")
        ax.set_xlabel("run")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    n_fail = int(failed.sum())
    fig.suptitle(f"{title}  -  {len(x0) - n_fail} safe (green), {n_fail} failed (red)".strip(" -"))
    path = Path(path)
    try:
        with atomic(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path


__all__ = ["plot_initial_conditions"]
