"""proxsuite as the filter's QP solver (`filter.solver: proxsuite`), with quadprog as its backup.

`solve` is the pipeline's solver step for proxsuite (`filter.qp.solve` enters it through
numba's object mode); proxsuite and quadprog are imported on the first call, so choosing the
default active-set solver never imports them.

Measured (docs/decisions.md sec. 4): proxsuite 0.8 alone takes 70-90 us per call on the filter's
4-variable, 12-row QP here, and on ~12 % of feasible problems with the p = 1e12 communication slack
it stops at MAX_ITER or reports SOLVED at a KKT point of the wrong problem. Every answer is therefore
checked against the rows *and* for KKT stationarity; quadprog (Goldfarb-Idnani, exact) re-solves
what fails, then the filter's fallback policy acts.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rta_attitude.filter import active_set
from rta_attitude.filter.outcome import (
    NOT_SOLVED,
    QUADPROG,
    SOLVE_CHECK_FAILED,
    SOLVE_INFEASIBLE,
    SOLVE_MAX_ITER,
    SOLVE_OK,
)

Array = NDArray[np.float64]
BIG = active_set.BIG

_WORKSPACES: dict[tuple[int, int, tuple[float, ...]], Any] = {}
"""proxsuite QP objects by (variables, rows, settings): built once, re-initialised per call."""


def _workspace(n: int, n_in: int, f: Any) -> Any:
    import proxsuite

    settings = (float(f["eps_abs"]), float(f["eps_primal_inf"]), float(f["eps_dual_inf"]), int(f["max_iterations"]),
                int(f["max_inner_iterations"]))
    key = (n, n_in, settings)
    if key not in _WORKSPACES:
        qp = proxsuite.proxqp.dense.QP(n, 0, n_in)
        s = qp.settings
        s.eps_abs, s.eps_rel = settings[0], 0.0
        s.eps_primal_inf, s.eps_dual_inf = settings[1], settings[2]
        s.max_iter, s.max_iter_in = settings[3], settings[4]
        s.verbose = False
        s.initial_guess = proxsuite.proxqp.InitialGuess.NO_INITIAL_GUESS
        _WORKSPACES[key] = qp
    return _WORKSPACES[key]


def is_stationary(C: Array, lower: Array, upper: Array, z: Array, mult: Array, g: Array, tol: float) -> bool:
    """KKT stationarity of an answer to min 1/2 |z|^2 + g.z (H = I): z + g + C' y = 0 on the u part, with
    multipliers of the right signs (measured: proxsuite can report SOLVED at a point 6 % worse than
    the optimum when a p = 1e12 slack is present)."""
    absent_lo = lower <= -BIG / 2
    absent_hi = upper >= BIG / 2
    if np.any(absent_lo & (mult < -tol)) or np.any(absent_hi & (mult > tol)):
        return False
    res = z[:3] + g[:3] + C[:, :3].T @ mult
    return bool(math.sqrt(float(res @ res)) <= tol * (1.0 + math.sqrt(float(g @ g))))


def solve_with_quadprog(C: Array, lower: Array, upper: Array, z0: Array) -> tuple[Array, Array, bool]:
    """Exact dual active-set solution (Goldfarb-Idnani, `quadprog`) of min 1/2 |z - z0|^2, lower <= C z <=
    upper. Returns (z, row multipliers in proxsuite's sign convention, solved?)."""
    import quadprog

    lo_rows = np.flatnonzero(lower > -BIG / 2)
    up_rows = np.flatnonzero(upper < BIG / 2)
    Cq = np.vstack([C[lo_rows], -C[up_rows]]).T
    bq = np.concatenate([lower[lo_rows], -upper[up_rows]])
    try:
        z, _f, _xu, _it, lag, _act = quadprog.solve_qp(np.eye(C.shape[1]), z0, Cq, bq, 0)
    except ValueError:  # infeasible (quadprog detects it in a finite number of steps)
        return np.full(C.shape[1], np.nan), np.zeros(C.shape[0]), False
    mult = np.zeros(C.shape[0])
    mult[lo_rows] -= lag[: len(lo_rows)]
    mult[up_rows] += lag[len(lo_rows):]
    return np.asarray(z, dtype=float), mult, True


def solve(C: Array, lower: Array, upper: Array, z0: Array, f: Any, z_out: Array, mult_out: Array
          ) -> tuple[int, int, int]:
    """Solve with proxsuite, checked; re-solve with quadprog (`backup_solver`) where that fails.

    Args:
        C, lower, upper, z0: the pipeline's QP (`filter.qp.assemble`).
        f: the FILTER_DTYPE record (settings, tolerance, backup solver).
        z_out, mult_out: receive the usable answer (quadprog's when proxsuite's failed and quadprog's
            holds), else proxsuite's.

    Returns:
        (proxsuite's SOLVE_RESULTS code, its iterations, quadprog's code or NOT_SOLVED).
    """
    import proxsuite

    tol = float(f["check_tolerance"])
    qp = _workspace(C.shape[1], C.shape[0], f)
    qp.init(np.eye(C.shape[1]), -z0, None, None, C, lower, upper)
    qp.solve()
    res = qp.results
    status = res.info.status
    z = np.array(res.x, dtype=float)
    mult = np.array(res.z, dtype=float)
    if status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED:
        ok = active_set.rows_hold(C, lower, upper, z, tol) and is_stationary(C, lower, upper, z, mult, -z0, tol)
        code = SOLVE_OK if ok else SOLVE_CHECK_FAILED
    elif status == proxsuite.proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED:
        code = SOLVE_MAX_ITER
    else:
        code = SOLVE_INFEASIBLE
    z_out[:], mult_out[:] = z, mult
    backup = NOT_SOLVED
    if code != SOLVE_OK and int(f["backup_solver"]) == QUADPROG:
        zq, mq, solved = solve_with_quadprog(C, lower, upper, z0)
        if not solved:
            backup = SOLVE_INFEASIBLE
        elif active_set.rows_hold(C, lower, upper, zq, tol):
            backup = SOLVE_OK
            z_out[:], mult_out[:] = zq, mq
        else:
            backup = SOLVE_CHECK_FAILED
    return code, int(res.info.iter), backup


__all__ = ["is_stationary", "solve", "solve_with_quadprog"]
