"""`active_set` (the compiled single-problem QP solver) against quadprog and Clarabel (independent
solvers); infeasible, already feasible, dependent, nearly parallel and degenerate rows; iteration
limits; `rows_hold`. (When it was ported from the vectorised numpy solver of batch.py, commit
bcaa5df, it matched that solver bit for bit on ~25,000 problems; the port replaced it.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from numpy.typing import NDArray

from rta_attitude.filter import active_set
from rta_attitude.filter.active_set import (
    BIG,
    CODE_INFEASIBLE,
    CODE_MAX_ITER,
    CODE_SOLVED,
    DEPENDENCE_TOL,
    FEASIBILITY_TOL,
    MAX_ACTIVE_SET_ITER,
    POLISH_ROUNDS,
    RATIO_TOL,
    REFINEMENT_STEPS,
)

Array = NDArray[np.float64]


def solve_projection_qp(C, lower, upper, z0, max_iter: int = active_set.MAX_ACTIVE_SET_ITER):
    """`solve` over a batch of K problems (the return contract of the former `batch.solve_projection_qp`).

    Args:
        C: constraint rows (K, m, n).
        lower, upper: bounds (K, m), +-BIG where absent.
        z0: unconstrained minimisers (K, n).
        max_iter: iterations per round before giving up.

    Returns:
        (z (K, n), multipliers (K, m) with proxsuite's sign convention, code (K,) int8 0 solved /
        1 infeasible / 2 too many iterations, iterations (K,) int64).
    """
    C = np.ascontiguousarray(C, dtype=np.float64)
    lower = np.ascontiguousarray(lower, dtype=np.float64)
    upper = np.ascontiguousarray(upper, dtype=np.float64)
    z0 = np.ascontiguousarray(z0, dtype=np.float64)
    K, m, n = C.shape
    z = np.empty((K, n))
    mult = np.empty((K, m))
    code = np.empty(K, dtype=np.int8)
    iters = np.empty(K, dtype=np.int64)
    for k in range(K):
        z[k], mult[k], code[k], iters[k] = active_set.solve(C[k], lower[k], upper[k], z0[k], int(max_iter))
    return z, mult, code, iters


def _random_problems(k: int, seed: int) -> tuple[Array, Array, Array, Array]:
    """Projection QPs shaped like the filter's: 10 unit rows (one with a 1e-6 slack column) + box
    (as in test_montecarlo)."""
    rng = np.random.default_rng(seed)
    C = np.zeros((k, 13, 4))
    C[:, :10, :3] = rng.normal(size=(k, 10, 3))
    C[:, 1, 3] = 1e-6
    C[:, :10] /= np.linalg.norm(C[:, :10], axis=-1, keepdims=True)
    C[:, 10:, :3] = np.eye(3)
    lower = np.full((k, 13), -BIG)
    upper = np.full((k, 13), BIG)
    lower[:, :10] = rng.normal(size=(k, 10)) * 0.4 - 0.5
    lower[:, 10:] = -rng.uniform(0.3, 3.0, (k, 3))
    upper[:, 10:] = rng.uniform(0.3, 3.0, (k, 3))
    z0 = np.zeros((k, 4))
    z0[:, :3] = rng.normal(size=(k, 3))
    return C, lower, upper, z0


def _dependent_problems(k: int, seed: int) -> tuple[Array, Array, Array, Array]:
    """Filter-shaped problems with (linearly) dependent rows: row 2 duplicates row 3 (same bound, or
    0.05 tighter), row 4 is -row 5 (a band of width 0, 0.05 or 1), row 0 is row 1 without its 1e-6
    slack column (nearly parallel; bounds equal, 1e-7 or 1e-3 apart); row 6 is an equality
    (lower = upper) in a fifth of them."""
    C, lower, upper, z0 = _random_problems(k, seed)
    rng = np.random.default_rng(seed + 1000)
    C[:, 2] = C[:, 3]
    lower[:, 2] = lower[:, 3] + rng.choice([0.0, 0.05], k)
    C[:, 4] = -C[:, 5]
    lower[:, 4] = -lower[:, 5] - rng.choice([0.0, 0.05, 1.0], k)
    C[:, 0, :3] = C[:, 1, :3]
    C[:, 0] /= np.linalg.norm(C[:, 0], axis=-1, keepdims=True)
    lower[:, 0] = lower[:, 1] + rng.choice([0.0, 1e-7, 1e-3], k)
    eq = rng.random(k) < 0.2
    upper[eq, 6] = lower[eq, 6]
    return C, lower, upper, z0


def _degenerate_problems(k: int, seed: int) -> tuple[Array, Array, Array, Array]:
    """Rows 1, 2 within 1e-6 of row 0; rows 2..5 pass within ~1e-9 of the optimum of rows 0, 1
    (row 5 an equality); scale 1e3. The polished optimum of a few of them violates a row the
    iterations had satisfied, so the solver resumes (seed 4: problems 811 and 1950 of 4000)."""
    rng = np.random.default_rng(seed)
    eps, scale = 1e-6, 1e3
    C = np.zeros((k, 6, 4))
    C[:, 0] = rng.normal(size=(k, 4))
    C[:, 1:3] = C[:, :1] + eps * rng.normal(size=(k, 2, 4))
    C[:, 3:] = rng.normal(size=(k, 3, 4))
    C /= np.linalg.norm(C, axis=-1, keepdims=True)
    lower = np.full((k, 6), -BIG)
    upper = np.full((k, 6), BIG)
    lower[:, :2] = scale * (1.0 + eps * rng.normal(size=(k, 2)))
    z0 = rng.normal(size=(k, 4)) * 0.3 * scale
    zs = solve_projection_qp(C[:, :2], lower[:, :2], upper[:, :2], z0)[0]
    lower[:, 2:] = np.einsum("kij,kj->ki", C[:, 2:], zs) + rng.normal(size=(k, 4)) * 1e-12 * scale
    upper[:, 5] = lower[:, 5]
    return C, lower, upper, z0


def _one_sided(C: Array, lower: Array, upper: Array) -> tuple[Array, Array]:
    """Rows A and b of A z >= b (the bounds that are present)."""
    rows, b = [], []
    for i in range(len(C)):
        if lower[i] > -BIG / 2:
            rows.append(C[i])
            b.append(lower[i])
        if upper[i] < BIG / 2:
            rows.append(-C[i])
            b.append(-upper[i])
    return np.array(rows), np.array(b)


def _clarabel(C: Array, lower: Array, upper: Array, z0: Array) -> Array | None:
    """min 1/2 |z - z0|^2 s.t. lower <= C z <= upper by Clarabel (interior point); None if infeasible."""
    import clarabel

    A, b = _one_sided(C, lower, upper)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    n = len(z0)
    solver = clarabel.DefaultSolver(sp.csc_matrix(np.eye(n)), -z0, sp.csc_matrix(-A), -b,
                                    [clarabel.NonnegativeConeT(len(b))], settings)
    sol = solver.solve()
    if str(sol.status) != "Solved":  # AlmostSolved: on infeasible problems too, far from feasible
        return None
    return np.array(sol.x)


def _bits(a: NDArray) -> NDArray:
    """The bit patterns of a float array (so that 0.0 and -0.0 differ), other arrays unchanged."""
    return a.view(np.int64) if a.dtype == np.float64 else a


def _assert_kkt(C: Array, lower: Array, upper: Array, z0: Array, z: Array, mult: Array, tol: float) -> None:
    """Stationarity z - z0 = -C^T mult, feasibility, proxsuite's signs and complementarity."""
    np.testing.assert_allclose(z - z0, -C.T @ mult, rtol=0, atol=tol * (1 + np.abs(z).max()))
    assert active_set.rows_hold(C, lower, upper, z, tol)
    Cz = C @ z
    assert np.all(np.abs(Cz[mult < 0] - lower[mult < 0]) <= tol * (1 + np.abs(lower[mult < 0])))
    assert np.all(np.abs(Cz[mult > 0] - upper[mult > 0]) <= tol * (1 + np.abs(upper[mult > 0])))


# ----------------------------------------------------------------------------- tests
def test_constants() -> None:
    assert (FEASIBILITY_TOL, DEPENDENCE_TOL, RATIO_TOL) == (1e-12, 1e-16, 1e-12)
    assert (MAX_ACTIVE_SET_ITER, POLISH_ROUNDS, REFINEMENT_STEPS) == (100, 3, 2)
    assert BIG == 1e20
    assert (CODE_SOLVED, CODE_INFEASIBLE, CODE_MAX_ITER) == (0, 1, 2)


def test_matches_quadprog() -> None:
    quadprog = pytest.importorskip("quadprog")
    C, lower, upper, z0 = _random_problems(600, 2)
    checked = infeasible = 0
    for k in range(len(C)):
        z, mult, code, iters = active_set.solve(C[k], lower[k], upper[k], z0[k], MAX_ACTIVE_SET_ITER)
        assert 1 <= iters <= 30
        A, b = _one_sided(C[k], lower[k], upper[k])
        try:
            ref = quadprog.solve_qp(np.eye(4), z0[k], A.T, b)[0]
        except ValueError:  # quadprog: infeasible
            assert code == CODE_INFEASIBLE
            assert not mult.any()
            infeasible += 1
            continue
        assert code == CODE_SOLVED
        np.testing.assert_allclose(z[:3], ref[:3], rtol=1e-9, atol=1e-9)  # in fact within 3e-14
        # the slack variable (coefficient ~1e-6: z[3] = -C[1, 3] mult[1]) is where quadprog loses
        # accuracy: up to 6e-9 off on values ~1e-7 (e.g. problem 581), while the stationarity
        # residual of ours there is ~1e-16; the (1 + |z|) 1e-9 KKT check below is on ours
        np.testing.assert_allclose(z[3], ref[3], rtol=1e-9, atol=1e-8)
        _assert_kkt(C[k], lower[k], upper[k], z0[k], z, mult, 1e-9)
        checked += 1
    assert checked > 500
    assert infeasible > 20


def test_the_batch_wrapper_is_a_loop_of_solve() -> None:
    C, lower, upper, z0 = _dependent_problems(50, 6)
    z, mult, code, iters = solve_projection_qp(C, lower, upper, z0)
    for k in range(50):
        one = active_set.solve(C[k], lower[k], upper[k], z0[k], MAX_ACTIVE_SET_ITER)
        np.testing.assert_array_equal(_bits(one[0]), _bits(z[k]))
        np.testing.assert_array_equal(_bits(one[1]), _bits(mult[k]))
        assert (one[2], one[3]) == (code[k], iters[k])


def test_resumed_problem() -> None:
    """A problem whose polished optimum violates a row the iterations had satisfied (found by
    instrumenting the method): it resumes and still ends optimal, as quadprog and the KKT
    conditions confirm."""
    quadprog = pytest.importorskip("quadprog")
    C, lower, upper, z0 = (a[811] for a in _degenerate_problems(4000, 4))
    z, mult, code, iters = active_set.solve(C, lower, upper, z0, MAX_ACTIVE_SET_ITER)
    assert code == CODE_SOLVED and iters == 5
    A, b = _one_sided(C, lower, upper)
    ref = quadprog.solve_qp(np.eye(len(z0)), z0, A.T, b)[0]
    np.testing.assert_allclose(z, ref, rtol=1e-9, atol=1e-9 * (1 + np.abs(ref).max()))
    _assert_kkt(C, lower, upper, z0, z, mult, 1e-9)


def test_infeasible() -> None:
    C = np.zeros((5, 3))
    C[0] = (1.0, 0.0, 0.0)
    C[1] = (-1.0, 0.0, 0.0)  # x >= 1 and -x >= 1
    C[2:] = np.eye(3)
    lower = np.array([1.0, 1.0, -5, -5, -5])
    upper = np.array([BIG, BIG, 5, 5, 5])
    z, mult, code, iters = active_set.solve(C, lower, upper, np.zeros(3), MAX_ACTIVE_SET_ITER)
    assert code == CODE_INFEASIBLE
    assert iters == 2
    assert not mult.any()
    np.testing.assert_array_equal(z, [1.0, 0.0, 0.0])  # where it stopped: row 0 active
    # an empty two-sided row and a box row that cannot be met
    for lo, up in (((1.0, 1.0, -5, -5, -5), (0.5, BIG, 5, 5, 5)), ((-BIG, -BIG, -5, 6, -5), (BIG, BIG, 5, 5, 5))):
        out = active_set.solve(C, np.array(lo), np.array(up), np.zeros(3), MAX_ACTIVE_SET_ITER)
        assert out[2] == CODE_INFEASIBLE


def test_feasible_z0_is_returned_exactly() -> None:
    C, lower, upper, _ = _random_problems(1, 7)
    C, lower, upper = C[0], lower[0], upper[0]
    z0 = np.array([0.1, -0.2, 0.3, 0.0])
    lower[:10] = C[:10] @ z0 - 0.1  # z0 strictly inside
    z, mult, code, iters = active_set.solve(C, lower, upper, z0, MAX_ACTIVE_SET_ITER)
    assert (code, iters) == (CODE_SOLVED, 1)
    np.testing.assert_array_equal(_bits(z), _bits(z0))
    assert z is not z0
    np.testing.assert_array_equal(_bits(mult), _bits(np.zeros(13)))
    # on the boundary (slack 0, and -FEASIBILITY_TOL / 2) counts as feasible too
    lower[0] = C[0] @ z0
    lower[1] = C[1] @ z0 + FEASIBILITY_TOL / 2
    z, mult, code, iters = active_set.solve(C, lower, upper, z0, MAX_ACTIVE_SET_ITER)
    assert (code, iters) == (CODE_SOLVED, 1)
    np.testing.assert_array_equal(z, z0)
    assert not mult.any()


def test_max_iter() -> None:
    C, lower, upper, z0 = (a[0] for a in _random_problems(1, 2))
    z1, _, code1, _ = active_set.solve(C, lower, upper, z0, MAX_ACTIVE_SET_ITER)
    assert code1 == CODE_SOLVED and not np.array_equal(z1, z0)
    z, mult, code, iters = active_set.solve(C, lower, upper, z0, 1)
    assert (code, iters) == (CODE_MAX_ITER, 1)
    assert not mult.any()
    assert np.all(np.isfinite(z))


def test_dependent_and_nearly_parallel_rows_match_clarabel() -> None:
    """Against Clarabel (interior point); infeasibility also confirmed by an LP (HiGHS). Clarabel
    leaves the slack variable z[3] (coefficient ~1e-6, so the objective is flat to ~1e-12 along it)
    up to ~1e-6 off, slightly outside the nearly parallel row 0; ours is feasible and at least as
    good (objective at most ~1e-11 above Clarabel's slightly infeasible one)."""
    pytest.importorskip("clarabel")
    from scipy.optimize import linprog

    C, lower, upper, z0 = _dependent_problems(600, 8)
    z, mult, code, _ = solve_projection_qp(C, lower, upper, z0)
    both_duplicates = both_parallel = checked = infeasible = 0
    for k in range(len(C)):
        ref = _clarabel(C[k], lower[k], upper[k], z0[k])
        if code[k] == CODE_INFEASIBLE:
            assert ref is None
            A, b = _one_sided(C[k], lower[k], upper[k])
            lp = linprog(np.zeros(4), A_ub=-A, b_ub=-b, bounds=[(None, None)] * 4, method="highs")
            assert lp.status == 2  # infeasible
            infeasible += 1
            continue
        assert code[k] == CODE_SOLVED and ref is not None
        np.testing.assert_allclose(z[k, :3], ref[:3], rtol=0, atol=1e-9)  # in fact within 2e-10
        np.testing.assert_allclose(z[k, 3], ref[3], rtol=0, atol=1e-5)  # in fact within 1e-6
        assert 0.5 * np.sum((z[k] - z0[k]) ** 2) <= 0.5 * np.sum((ref - z0[k]) ** 2) + 1e-10
        _assert_kkt(C[k], lower[k], upper[k], z0[k], z[k], mult[k], 1e-9)
        checked += 1
        Cz = C[k] @ z[k]
        both_duplicates += abs(Cz[2] - lower[k, 2]) < 1e-9 and abs(Cz[3] - lower[k, 3]) < 1e-9
        both_parallel += abs(Cz[0] - lower[k, 0]) < 1e-9 and abs(Cz[1] - lower[k, 1]) < 1e-9
    assert checked > 400 and infeasible > 100
    assert both_duplicates > 30  # (440, 160, 45 and 27 with seed 8)
    assert both_parallel > 15


def test_zero_padding_changes_nothing() -> None:
    """Zero rows with absent bounds are inert: same numbers as the compact problem."""
    C, lower, upper, z0 = _random_problems(200, 9)
    Cp = np.concatenate([C[:, :5], np.zeros((200, 2, 4)), C[:, 5:]], axis=1)
    lp = np.concatenate([lower[:, :5], np.full((200, 2), -BIG), lower[:, 5:]], axis=1)
    up = np.concatenate([upper[:, :5], np.full((200, 2), BIG), upper[:, 5:]], axis=1)
    a = solve_projection_qp(C, lower, upper, z0)
    b = solve_projection_qp(Cp, lp, up, z0)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], np.delete(b[1], [5, 6], axis=1))
    np.testing.assert_array_equal(a[2], b[2])
    np.testing.assert_array_equal(a[3], b[3])


def test_rows_hold() -> None:
    C = np.array([[1.0, 0.0], [0.6, 0.8], [0.0, 1.0]])
    lower = np.array([-1.0, 0.5, -BIG])
    upper = np.array([1.0, BIG, 2.0])
    z = np.array([0.5, 0.5])  # C z = (0.5, 0.7, 0.5)
    assert active_set.rows_hold(C, lower, upper, z, 0.0)
    assert active_set.rows_hold(C, lower, upper, np.array([1.0, 2.0]), 0.0)  # on the bounds
    assert not active_set.rows_hold(C, lower, upper, np.array([1.0 + 1e-9, 2.0]), 0.0)
    assert active_set.rows_hold(C, lower, upper, np.array([1.0 + 1e-9, 2.0]), 1e-8)
    assert not active_set.rows_hold(C, lower, upper, np.array([0.0, 0.5]), 1e-3)  # 0.4 < 0.5 (row 1)
    assert not active_set.rows_hold(C, lower, upper, np.array([0.5, 3.0]), 1e-3)  # 3 > 2 (row 2)
    assert active_set.rows_hold(C, lower, upper, np.array([0.5, -1e15]), 0.0) is False  # row 1
    assert active_set.rows_hold(C[[0, 2]], lower[[0, 2]], upper[[0, 2]], np.array([0.5, -1e15]), 0.0)  # absent
    assert not active_set.rows_hold(C, lower, upper, np.array([np.nan, 0.5]), 1.0)
    assert not active_set.rows_hold(C, lower, upper, np.array([0.5, np.inf]), 1.0)
    assert not active_set.rows_hold(np.array([[np.nan, 0.0]]), lower[:1], upper[:1], z, 1.0)


def test_cached_solver_is_callable_after_the_filter_kernels_loaded(tmp_path) -> None:
    """Regression: with numba's on-disk cache warm (the session's `compiled_kernels` fixture), a
    fresh process that loads the filter kernels first and then calls `solve` from Python gets an
    answer. (After an edit of active_set.py, filter_kernel's stale cache made that call fail with
    "NRT_adapt_ndarray_to_python: descr is NULL"; `kernel_cache` now drops stale caches.)"""
    import subprocess
    import sys

    script = (
        "import numpy as np\n"
        "from rta_attitude import config\n"
        "from rta_attitude.filter import active_set\n"
        "from rta_attitude.filter.asif import AsifFilter\n"
        "cfg = config.load()\n"
        "AsifFilter(cfg).filter(cfg.scenario('paper-example').x0, np.zeros(3))\n"
        "z = active_set.solve(np.eye(3), -np.ones(3), np.ones(3), np.array([2.0, 0.0, 0.0]), 100)[0]\n"
        "print(repr(z.tolist()))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[1.0, 0.0, 0.0]"


def test_stale_kernel_caches_are_dropped_when_any_kernel_source_changes(tmp_path) -> None:
    """A change to any kernel source drops every kernel module's numba cache (a caller's cache links its
    callees in); unchanged sources keep them; other modules' caches are never touched."""
    from rta_attitude.kernel_cache import drop_stale_caches, kernel_modules

    for rel in ("filter/active_set.py", "filter/pipeline.py", "constraints/rows.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(f"import numba.core  # {rel}\n")
    (tmp_path / "files.py").write_text("# no kernels here\n")
    assert [p.relative_to(tmp_path).as_posix() for p in kernel_modules(tmp_path)] == [
        "constraints/rows.py", "filter/active_set.py", "filter/pipeline.py"]

    def caches() -> list[Path]:
        return sorted(p for p in tmp_path.rglob("__pycache__/*") if p.suffix in (".nbi", ".nbc"))

    def write_caches() -> list[Path]:
        for path in kernel_modules(tmp_path):
            (path.parent / "__pycache__").mkdir(exist_ok=True)
            for ext in ("nbi", "nbc"):
                (path.parent / "__pycache__" / f"{path.stem}.solve-1.py311.{ext}").touch()
        return caches()

    assert write_caches() and drop_stale_caches(tmp_path)  # no stamp yet: dropped, stamp written
    assert not caches()
    written = write_caches()
    assert not drop_stale_caches(tmp_path)  # same sources: the caches stay
    assert caches() == written
    (tmp_path / "filter" / "active_set.py").write_text("import numba.core  # edited\n")  # a callee changes
    assert drop_stale_caches(tmp_path)
    assert not caches()
    other = tmp_path / "__pycache__" / "files.f-1.py311.nbi"
    other.touch()  # a module without kernels: not touched
    (tmp_path / "constraints" / "rows.py").write_text("import numba.core  # edited again\n")
    drop_stale_caches(tmp_path)
    assert other.exists()
