"""The floors the benchmarks report their speed against, measured in the same run on the same machine.

Absolute times depend on the machine and on what else it runs; a ratio to a floor does not (much):

- `plant_floor`: the Monte Carlo's unavoidable work, the plant alone in a compiled loop over runs:
  RK4 with the zero-order hold (`dynamics.spacecraft.rk4_hold`) and the safety values at every
  substep (`constraints.rows.safety_values`), u = 0, no filter. The Monte Carlo runs the same two
  functions plus the filter, so Monte Carlo / floor is the filter's cost on top of the physics.
- `StraightforwardFilter`: the filter as one would first write it: the barrier rows of the numpy
  oracle (test/oracles, the project's first implementation), the QP assembled in numpy and solved by
  proxsuite (dense, checked). The compiled filter / this is the speed-up of the compiled pipeline.
- the forward-only node chain is in bench_dds.py (it needs ROS).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numba
import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "test"))

from rta_attitude.config.schema import Config  # noqa: E402
from rta_attitude.constraints.base import MAX_ROWS  # noqa: E402
from rta_attitude.constraints.geometry import CONTEXT_DTYPE  # noqa: E402
from rta_attitude.constraints.rows import safety_values  # noqa: E402
from rta_attitude.dynamics.spacecraft import RK4_WORK_ROWS, rk4_hold  # noqa: E402
from rta_attitude.dynamics.state import STATE_SIZE  # noqa: E402
from rta_attitude.simulation.closed_loop import loop_record  # noqa: E402

Array = NDArray[np.float64]


@numba.njit(cache=True)
def _plant_only(X0: Array, steps: int, loop: NDArray[np.void], min_h: Array) -> None:
    lp = loop[0]
    p, c = lp.plant, lp.filter.constraints
    S = lp.substeps
    ctx = np.zeros(1, CONTEXT_DTYPE)
    u = np.zeros(3)
    subs = np.empty((S, STATE_SIZE))
    work = np.zeros((RK4_WORK_ROWS, STATE_SIZE))
    h = np.empty(MAX_ROWS)
    n = c.n_rows
    for k in range(X0.shape[0]):
        x = X0[k].copy()
        for step in range(steps):
            rk4_hold(x, u, lp.dt_s, S, p, subs, work)
            for j in range(S):
                safety_values(subs[j], lp.dt_s * (step + (j + 1) / S), p, c, ctx[0], h)
                for i in range(n):
                    if h[i] < min_h[k, i]:
                        min_h[k, i] = h[i]
            x[:] = subs[S - 1]


def plant_floor(cfg: Config, x0: Array, duration_s: float) -> Array:
    """Run the plant alone from x0 (N, 19) for duration_s (u = 0, safety values at every substep).
    Returns the smallest h of each run (N, m), so the work cannot be optimised away."""
    steps = round(duration_s / cfg.filter.sample_time_s)
    min_h = np.full((len(x0), len(cfg.constraint_names)), np.inf)
    _plant_only(np.ascontiguousarray(x0, dtype=float), steps, loop_record(cfg, rta=False, pd=False), min_h)
    return min_h


class StraightforwardFilter:
    """The filter written plainly: numpy rows (the oracle), numpy QP assembly, proxsuite, numpy checks.

    Same QP as the compiled pipeline (normalised rows, scaled slack, the robust box); answers agree with
    it to the solver's tolerance on problems proxsuite solves.
    """

    def __init__(self, cfg: Config) -> None:
        import proxsuite
        from oracles.constraints import ConstraintSet

        self.cfg = cfg
        self.cs = ConstraintSet.from_config(cfg)
        self.enabled = self.cs.enabled.astype(bool)
        self.weights = self.cs.slack_weights
        self.proxsuite = proxsuite

    def box(self, x: Array) -> tuple[Array, Array]:
        cfg = self.cfg
        u_max = cfg.u_max_rad_s2
        lo, hi = -u_max.copy(), u_max.copy()
        if cfg.filter.preset == "robust":
            zlo, zhi = self.cs.zoh_bounds(self.cs.context(x), cfg.filter.sample_time_s, cfg.filter.zoh_margin)
            new_lo, new_hi = np.maximum(lo, zlo), np.minimum(hi, zhi)
            bad = new_lo > new_hi
            edge = np.where(zhi < lo, lo, hi)
            lo, hi = np.where(bad, edge, new_lo), np.where(bad, edge, new_hi)
        return lo, hi

    def filter(self, x: Array, u_des: Array) -> Array:
        """u (3,) for state x (19,) and u_des (3,)."""
        t = self.cs.evaluate(x)
        lo, hi = self.box(x)
        u0 = np.clip(u_des, lo, hi)
        gnorm = np.linalg.norm(t.gain, axis=1)
        rows = self.enabled & (gnorm > 1e-12)
        tol = self.cfg.filter.check_tolerance * np.maximum(1.0, gnorm[rows])
        if np.all(t.drift[rows] + t.gain[rows] @ u0 >= -tol):  # the fast path: u_des (clipped) is safe
            return u0
        idx = np.flatnonzero(rows)
        soft = [i for i in idx if self.weights[i] > 0]
        n = 3 + len(soft)
        C = np.zeros((len(idx) + 3, n))
        lower = np.full(len(idx) + 3, -1e20)
        upper = np.full(len(idx) + 3, 1e20)
        for r, i in enumerate(idx):
            C[r, :3] = t.gain[i]
            if i in soft:
                C[r, 3 + soft.index(i)] = 1.0 / np.sqrt(self.weights[i])
            norm = np.linalg.norm(C[r])
            C[r] /= norm
            lower[r] = -t.drift[i] / norm
        C[len(idx):, :3] = np.eye(3)
        lower[len(idx):], upper[len(idx):] = lo, hi
        qp = self.proxsuite.proxqp.dense.QP(n, 0, len(lower))
        qp.settings.eps_abs = 1e-9
        qp.settings.verbose = False
        z0 = np.zeros(n)
        z0[:3] = u_des
        qp.init(np.eye(n), -z0, None, None, C, lower, upper)
        qp.solve()
        z = np.asarray(qp.results.x)
        return np.clip(z[:3], lo, hi)


__all__ = ["StraightforwardFilter", "plant_floor"]
