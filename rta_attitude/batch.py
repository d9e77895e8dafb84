"""Lockstep batch simulation of many runs: the single-run loop of `simulation.ClosedLoop`, vectorised.

One step of N runs (states held column-wise, "structure of arrays", shape (19, N)):

    filter    `AsifFilter.filter_batch`: every state through the same compiled per-state code as a
              single `filter` call (`filter_kernel`; rows, fast path, exact active-set QP, fallback)
    plant     u -> tau -> u, saturation, RK4 with `cfg.substeps` substeps (`simulation.integrate`)
    checks    h of every constraint at every sample and every substep

The plant and the checks perform every array operation the single-run code performs, in the same
order, so a run inside the batch reproduces `ClosedLoop.run` bit for bit (the tests check it
against the core functions and against whole runs). `solver="proxsuite"` filters each state with
proxsuite instead (as `simulate` with `filter.solver: proxsuite`; several times slower).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import model
from .asif import CODE_FALLBACK, AsifFilter
from .params import CONSTRAINT_NAMES, Config
from .state import ENERGY, OMEGA, PSI, STATE_SIZE, TEMP, THETA_S

Array = NDArray[np.float64]

SOLVERS: tuple[str, ...] = ("active-set", "proxsuite")
"""QP solvers of the batch: the compiled exact active-set method, or proxsuite state by state."""

SCREEN_MARGIN = 1e-6
"""Angle constraints between samples: cosines this far inside the safe side skip the exact arccos."""

_EZ, _COMM, _TEMP, _BATT = 0, 1, 2, 3
"""Row indices in CONSTRAINT_NAMES order (omega_x/y/z 4..6, psi_x/y/z 7..9)."""


# ----------------------------------------------------------------------------- angles of many states (SoA)
_Vec = tuple["Array | None", "Array | None", "Array | None"]
"""A 3-vector of (N,) arrays; None is an exact zero (skipped in sums, as x + 0 == x)."""


def _sum(*terms: Array | None) -> Array | None:
    out = None
    for t in terms:
        if t is not None:
            out = t if out is None else out + t
    return out


def _mul(a: Array | float | None, b: Array | None) -> Array | None:
    return None if a is None or b is None else a * b


def _dot(a: _Vec, b: _Vec) -> Array | None:
    return _sum(_mul(a[0], b[0]), _mul(a[1], b[1]), _mul(a[2], b[2]))


def _sub(a: Array | None, b: Array | None) -> Array | None:
    if b is None:
        return a
    return -b if a is None else a - b


def _cross(a: _Vec, b: _Vec) -> _Vec:
    return (_sub(_mul(a[1], b[2]), _mul(a[2], b[1])), _sub(_mul(a[2], b[0]), _mul(a[0], b[2])),
            _sub(_mul(a[0], b[1]), _mul(a[1], b[0])))


def _axis(v: tuple[float, float, float]) -> _Vec:
    """A unit body axis as a _Vec of scalars (1.0, -1.0) and exact zeros (None)."""
    return tuple(None if c == 0.0 else float(c) for c in v)  # type: ignore[return-value]


def _theta(axis: tuple[float, float, float], r_B: _Vec) -> Array:
    """Angle between a unit body axis and r_B, as `constraints.pointing.pointing` computes it."""
    e = _axis(axis)
    m = _cross(e, r_B)
    like = next(v for v in r_B if v is not None)
    return np.arctan2(np.sqrt(_z(_dot(m, m), like)), _z(_dot(e, r_B), like))


def _z(a: Array | None, like: Array) -> Array:
    return np.zeros_like(like) if a is None else a


# ----------------------------------------------------------------------------- plant (SoA RK4)
class _Plant:
    """`simulation.integrate` on states held column-wise, same operations in the same order."""

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.J1, self.J2, self.J3 = cfg.spacecraft.inertia_kgm2
        self.cg = cfg.spacecraft.control_gain
        self.n = cfg.environment.mean_motion_rad_s
        self.heat_capacity = cfg.thermal.mass_kg * cfg.thermal.specific_heat_J_kgK

    def derivative(self, Y: Array, cs: Array, sn: Array, cgu: Array) -> Array:
        """d/dt of Y = [q1 q2 q3 q4 w1 w2 w3 T E] (9, N) as model.state_derivative."""
        q1, q2, q3, q4, w1, w2, w3, T, _E = Y
        K = np.empty_like(Y)
        mul, add = np.multiply, np.add
        mul(0.5, q4 * w1 - q3 * w2 + q2 * w3, out=K[0])
        mul(0.5, q3 * w1 + q4 * w2 - q1 * w3, out=K[1])
        mul(0.5, -q2 * w1 + q1 * w2 + q4 * w3, out=K[2])
        mul(-0.5, q1 * w1 + q2 * w2 + q3 * w3, out=K[3])
        J1, J2, J3 = self.J1, self.J2, self.J3
        add((J2 - J3) * w2 * w3 / J1, cgu[0], out=K[4])
        add((J3 - J1) * w3 * w1 / J2, cgu[1], out=K[5])
        add((J1 - J2) * w1 * w2 / J3, cgu[2], out=K[6])
        a10, a11 = 2.0 * (q1 * q2 - q3 * q4), -q1 * q1 + q2 * q2 - q3 * q3 + q4 * q4
        a20, a21 = 2.0 * (q1 * q3 + q2 * q4), 2.0 * (q2 * q3 - q1 * q4)
        cos_sun = -(a10 * cs + a11 * sn)
        np.divide(model.thermal_fluxes(cos_sun, a10, T, self.cfg), self.heat_capacity, out=K[7])
        K[8] = model.net_power(a20 * cs + a21 * sn, self.cfg)
        return K

    def integrate(self, Y: Array, psi: Array, th: Array, u: Array, dt_s: float, substeps: int,
                  on_substep: Callable[[int, Array, Array, Array, Array, Array], None] | None = None
                  ) -> tuple[Array, Array, Array]:
        """Hold u (3, N) over dt_s; returns (Y, psi, theta_S) at t + dt. After each substep j,
        on_substep(j, Y, psi, theta_S, cos theta_S, sin theta_S) sees the state."""
        h_s = dt_s / substeps
        cgu = np.stack([self.cg[a] * u[a] for a in range(3)])
        kp = 0.0 + u
        psi_inc = (h_s / 6.0) * (kp + 2.0 * kp + 2.0 * kp + kp)
        kth = -self.n
        half, full = 0.5 * h_s, h_s
        th_inc = (h_s / 6.0) * (kth + 2.0 * kth + 2.0 * kth + kth)
        c1, s1 = np.cos(th), np.sin(th)
        for j in range(substeps):
            th2 = th + half * kth
            th4 = th + full * kth
            c2, s2 = np.cos(th2), np.sin(th2)
            c4, s4 = np.cos(th4), np.sin(th4)
            k1 = self.derivative(Y, c1, s1, cgu)
            k2 = self.derivative(Y + half * k1, c2, s2, cgu)
            k3 = self.derivative(Y + half * k2, c2, s2, cgu)
            k4 = self.derivative(Y + full * k3, c4, s4, cgu)
            Y = Y + (h_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            q = Y[0:4]
            Y[0:4] = q / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
            psi = psi + psi_inc
            th = th + th_inc
            if j < substeps - 1 or on_substep is not None:
                c1, s1 = np.cos(th), np.sin(th)
            if on_substep is not None:
                on_substep(j, Y, psi, th, c1, s1)
        return Y, psi, th


# ----------------------------------------------------------------------------- the batch simulator
@dataclass
class BatchOutcome:
    """Per-run results of a batch (N runs, m = 10 constraints in CONSTRAINT_NAMES order).

    Attributes:
        violated_samples: (N, m) h < 0 at some sample t_k (the paper's criterion).
        violated_substeps: (N, m) h < 0 at some sample or RK4 substep.
        first_violation_s: (N, m) earliest sample or substep time with h < 0, NaN if none.
        min_h_samples: (N, m) smallest h over the samples.
        qp_steps, fallback_steps, qp_failures: (N,) steps that needed the QP, that ended in the
            fallback, and whose first QP failed.
        max_comm_slack: (N,) largest |delta| of the slacked constraints (rad for communication).
        x_final: (N, 19) state at the end.
        trajectory: (N, steps + 1, 19) states at the samples if recorded, else None.
    """

    violated_samples: NDArray[np.bool_]
    violated_substeps: NDArray[np.bool_]
    first_violation_s: Array
    min_h_samples: Array
    qp_steps: NDArray[np.int64]
    fallback_steps: NDArray[np.int64]
    qp_failures: NDArray[np.int64]
    max_comm_slack: Array
    x_final: Array
    trajectory: Array | None = None


class BatchSimulator:
    """N runs of the closed loop with RTA and u_des = 0 (no primary controller), in lockstep.

    Args:
        cfg: configuration (preset, gains, substeps).
        solver: 'active-set' (the compiled exact active-set QP) or 'proxsuite' (state by state;
            slow). Either way a run equals `simulate` with the same `filter.solver` bit for bit.
    """

    def __init__(self, cfg: Config, solver: str = "active-set") -> None:
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        self.cfg = cfg
        self.solver = solver
        self.filter = AsifFilter(cfg.with_solver("active_set" if solver == "active-set" else "proxsuite"))
        self.plant = _Plant(cfg)
        self.slack_rows = np.flatnonzero(self.filter.slacked)

    # ------------------------------------------------------------------ filter
    def _filter(self, X: Array) -> tuple[Array, NDArray[np.int8], NDArray[np.bool_], Array]:
        """`AsifFilter.filter_batch` for u_des = 0: u (N, 3), status codes, first-QP-failed flags,
        slack (N, m)."""
        N = X.shape[1]
        res = self.filter.filter_batch(np.ascontiguousarray(X.T), np.zeros((N, 3)))
        return res.u, res.status, res.qp_failed, res.slack

    # ------------------------------------------------------------------ checks between samples
    def _substep_h(self, Y: Array, psi: Array, th: Array, cs: Array, sn: Array,
                   flagged: NDArray[np.bool_]) -> tuple[NDArray[np.int64], Array]:
        """Runs that may newly violate a constraint at a substep state, and their h (k, m), the rows
        of `ConstraintSet.safety_values` computed the same way. A cheap screen (cosines and plain
        comparisons, SCREEN_MARGIN on the safe side) picks the candidates; constraints already
        flagged in a run (flagged (N, m)) need no second look."""
        cfg = self.cfg
        L = cfg.limits
        q1, q2, q3, q4 = Y[0], Y[1], Y[2], Y[3]
        c_ez = (q1 * q1 - q2 * q2 - q3 * q3 + q4 * q4) * cs + 2.0 * (q1 * q2 + q3 * q4) * sn  # +i_B . r_S
        c_gs = 2.0 * (q3 * q4 - q1 * q2)  # +j_B . r_E
        near = (c_ez > math.cos(L.exclusion_angle_rad) - SCREEN_MARGIN) & ~flagged[:, _EZ]
        near |= (c_gs < math.cos(L.comm_angle_rad) + SCREEN_MARGIN) & ~flagged[:, _COMM]
        near |= (Y[7] > L.temperature_max_K - SCREEN_MARGIN) & ~flagged[:, _TEMP]
        near |= (Y[8] < L.energy_min_J + SCREEN_MARGIN) & ~flagged[:, _BATT]
        near |= np.any((np.abs(Y[4:7]) > L.omega_max_rad_s * (1.0 - SCREEN_MARGIN)) & ~flagged[:, 4:7].T, axis=0)
        near |= np.any((np.abs(psi) > L.psi_max_rad_s * (1.0 - SCREEN_MARGIN)) & ~flagged[:, 7:10].T, axis=0)
        sel = np.flatnonzero(near)
        if sel.size == 0:
            return sel, np.zeros((0, 10))
        X = np.zeros((STATE_SIZE, sel.size))
        X[0:7] = Y[0:7, sel]
        X[PSI] = psi[:, sel]
        X[TEMP], X[ENERGY], X[THETA_S] = Y[7, sel], Y[8, sel], th[sel]
        return sel, self.safety_values(X)

    def _sample_h(self, X: Array) -> Array:
        """h (N, m) at the samples as ClosedLoop records them (safety_values of the plant state)."""
        if self.solver == "proxsuite":
            return self.filter.constraints.safety_values(np.ascontiguousarray(X.T))
        return self.safety_values(X)

    def safety_values(self, X: Array) -> Array:
        """Physical h (N, m) of states X (19, N), as `ConstraintSet.safety_values` (the angles by
        the same operations as `constraints.pointing`, without the derivatives)."""
        L = self.cfg.limits
        h = np.empty((X.shape[1], 10))
        q1, q2, q3, q4 = X[0], X[1], X[2], X[3]
        s11, s22, s33, s44 = q1 * q1, q2 * q2, q3 * q3, q4 * q4
        A0 = (s11 - s22 - s33 + s44, 2.0 * (q1 * q2 - q3 * q4), 2.0 * (q1 * q3 + q2 * q4))  # column 0
        A1 = (2.0 * (q1 * q2 + q3 * q4), -s11 + s22 - s33 + s44, 2.0 * (q2 * q3 - q1 * q4))  # column 1
        th = X[THETA_S]
        cs, sn = np.cos(th), np.sin(th)
        r_S: _Vec = tuple(A0[i] * cs + A1[i] * sn for i in range(3))  # type: ignore[assignment]
        r_E: _Vec = (-A0[0], -A0[1], -A0[2])
        h[:, _EZ] = _theta(tuple(model.SENSOR_AXIS_BODY), r_S) - L.exclusion_angle_rad  # type: ignore[arg-type]
        h[:, _COMM] = L.comm_angle_rad - _theta(tuple(model.ANTENNA_AXIS_BODY), r_E)  # type: ignore[arg-type]
        h[:, _TEMP] = L.temperature_max_K - X[TEMP]
        h[:, _BATT] = X[ENERGY] - L.energy_min_J
        for a in range(3):
            h[:, 4 + a] = L.omega_max_rad_s**2 - X[OMEGA.start + a] ** 2
            h[:, 7 + a] = L.psi_max_rad_s**2 - X[PSI.start + a] ** 2
        return h

    # ------------------------------------------------------------------ run
    def run(self, x0: Array, duration_s: float, record: bool = False,
            progress: Callable[[int], None] | None = None) -> BatchOutcome:
        """Simulate every run for duration_s.

        Args:
            x0: initial states (N, 19); the Clohessy-Wiltshire entries must be zero (they are
                unforced, constrain nothing and stay zero).
            duration_s: run length, s (steps of filter.sample_time_s).
            record: keep the states at every sample (N, steps + 1, 19) for comparisons.
            progress: called with the number of steps done after each step.
        """
        cfg = self.cfg
        x0 = np.asarray(x0, dtype=float)
        if x0.ndim != 2 or x0.shape[1] != STATE_SIZE:
            raise ValueError(f"x0 must be (N, {STATE_SIZE}), got {x0.shape}")
        if np.any(x0[:, 13:] != 0.0):
            raise ValueError("x0: the Clohessy-Wiltshire entries must be zero in a batch run")
        dt = cfg.filter.sample_time_s
        steps = round(duration_s / dt)
        N = x0.shape[0]
        X = np.ascontiguousarray(x0.T)
        Y = X[[0, 1, 2, 3, 4, 5, 6, TEMP, ENERGY]].copy()
        psi, th = X[PSI].copy(), X[THETA_S].copy()
        viol_s = np.zeros((N, 10), dtype=bool)
        viol_sub = np.zeros((N, 10), dtype=bool)
        first = np.full((N, 10), np.nan)
        min_h = np.full((N, 10), np.inf)
        qp_steps = np.zeros(N, dtype=np.int64)
        fb_steps = np.zeros(N, dtype=np.int64)
        qp_fail = np.zeros(N, dtype=np.int64)
        max_slack = np.zeros(N)
        traj = np.zeros((N, steps + 1, STATE_SIZE)) if record else None
        if traj is not None:
            traj[:, 0] = x0
        sub_t = dt * np.arange(1, cfg.substeps + 1) / cfg.substeps

        def mark(h: Array, t: float, sample: bool, rows: NDArray[np.int64] | None = None) -> None:
            bad = h < 0
            if rows is None:
                if sample:
                    viol_s[:] |= bad
                new = bad & np.isnan(first)
                first[new] = t
                viol_sub[:] |= bad
            elif bad.any():
                new = bad & np.isnan(first[rows])
                first[rows] = np.where(new, t, first[rows])
                viol_sub[rows] |= bad

        def state(Y: Array, psi: Array, th: Array) -> Array:
            Xs = np.zeros((STATE_SIZE, N))
            Xs[0:7], Xs[PSI], Xs[TEMP], Xs[ENERGY], Xs[THETA_S] = Y[0:7], psi, Y[7], Y[8], th
            return Xs

        for k in range(steps):
            t = k * dt
            Xk = state(Y, psi, th)
            u, status, failed, slack = self._filter(Xk)
            h = self._sample_h(Xk)
            np.minimum(min_h, h, out=min_h)
            mark(h, t, True)
            qp_steps += status > 0
            fb_steps += status == CODE_FALLBACK
            qp_fail += failed
            if self.slack_rows.size:
                np.maximum(max_slack, np.abs(slack[:, self.slack_rows]).max(axis=1), out=max_slack)
            u = model.through_torque_interface(u, cfg)
            lim = cfg.limits.wheel_accel_max_rad_s2
            u = np.clip(np.clip(u, -lim, lim), -lim, lim)  # ClosedLoop saturates, integrate saturates again

            def on_sub(j: int, Ys: Array, ps: Array, ts: Array, cs: Array, sn: Array, t: float = t) -> None:
                if j < cfg.substeps - 1:
                    sel, hs = self._substep_h(Ys, ps, ts, cs, sn, viol_sub)
                    if sel.size:
                        mark(hs, t + sub_t[j], False, sel)

            Y, psi, th = self.plant.integrate(Y, psi, th, np.ascontiguousarray(u.T), dt, cfg.substeps, on_sub)
            if traj is not None:
                traj[:, k + 1] = state(Y, psi, th).T
            if progress is not None:
                progress(k + 1)
        Xn = state(Y, psi, th)
        h_end = self._sample_h(Xn)
        np.minimum(min_h, h_end, out=min_h)
        mark(h_end, steps * dt, True)
        return BatchOutcome(viol_s, viol_sub, first, min_h, qp_steps, fb_steps, qp_fail, max_slack,
                            np.ascontiguousarray(Xn.T), traj)


__all__ = ["SOLVERS", "BatchOutcome", "BatchSimulator"]
assert len(CONSTRAINT_NAMES) == 10  # the row indices above follow CONSTRAINT_NAMES
