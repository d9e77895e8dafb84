"""The vehicle's inertia tensor as data: its matrix from the configured moments and products, its check at
load, and the bound on Euler's coupling torque that the admissible set and the filter's sampled-data rows
share (docs/conventions.md, "Inertia").

The configuration gives the tensor's diagonal (`spacecraft.inertia_kgm2`: J_xx, J_yy, J_zz) and its
off-diagonal entries (`spacecraft.products_of_inertia_kgm2`: J_xy, J_xz, J_yz, the tensor's entries, so
J_xy = -int x y dm), in body axes:

    J = [[J_xx, J_xy, J_xz],
         [J_xy, J_yy, J_yz],
         [J_xz, J_yz, J_zz]]

With the products all zero (the default, the paper's 6U) the body axes are principal and every kernel runs
its principal-axis arithmetic, operation for operation as before; otherwise the general one.

`euler_bound` is plain Python on floats so that the compiled kernels compile this very function
(`dynamics.spacecraft.euler_bound`, with numba.njit) and the configuration's admissible set calls it as it is:
one formula. (That mention of numba. also puts this file among the sources `kernel_cache` hashes, so an edit here
recompiles the kernels that inline it.)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from rta_attitude.errors import ConfigError

TRIANGLE_RTOL = 1e-12
"""The triangle inequalities of the principal moments hold to this fraction of the largest (a thin rod or a
flat plate sits on the edge: J_1 + J_2 = J_3)."""


def inertia_matrix(moments: tuple[float, float, float], products: tuple[float, float, float]) -> NDArray[np.float64]:
    """The symmetric tensor (3, 3) of the diagonal (J_xx, J_yy, J_zz) and the products (J_xy, J_xz, J_yz), kg m^2."""
    (xx, yy, zz), (xy, xz, yz) = moments, products
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]], dtype=float)


def check_inertia(J: NDArray[np.float64], where: str) -> None:
    """A rigid body's tensor or one ConfigError line: positive definite, and its principal moments meet the
    triangle inequalities (J_1 + J_2 >= J_3 for every ordering: no body has any other)."""
    if not np.all(np.isfinite(J)):
        raise ConfigError(f"{where} must be finite, got {J.tolist()!r}")
    moments = principal_moments(J)
    if not moments[0] > 0.0:
        raise ConfigError(f"{where}: the inertia tensor must be positive definite; its principal moments are "
                          f"{', '.join(f'{m:.6g}' for m in moments)} kg m^2")
    if moments[0] + moments[1] < moments[2] * (1.0 - TRIANGLE_RTOL):
        raise ConfigError(f"{where}: the principal moments {', '.join(f'{m:.6g}' for m in moments)} kg m^2 break the "
                          f"triangle inequality J_1 + J_2 >= J_3 (no rigid body has them)")


def euler_bound(J: NDArray[np.float64], W0: float, W1: float, W2: float, j: int) -> float:
    """A bound on |(w x J w)_j| (N m) for every body rate with |w_k| <= W_k.

    (w x J w)_j = w_b (J' w)_c - w_c (J' w)_b for any J' = J - mu I ((b, c) = (j + 1, j + 2) mod 3, since
    w x w = 0); mu = (J_bb + J_cc) / 2 makes it, for a diagonal J, |J_bb - J_cc| W_b W_c: Euler's exact
    worst case, the bound the principal-axis kernels use.
        |(w x J w)_j| <= W_b sum_k |J'_ck| W_k + W_c sum_k |J'_bk| W_k."""
    b, c = (j + 1) % 3, (j + 2) % 3
    mu = 0.5 * (J[b, b] + J[c, c])
    W = (W0, W1, W2)
    row_c = 0.0
    row_b = 0.0
    for k in range(3):
        row_c += abs(J[c, k] - (mu if k == c else 0.0)) * W[k]
        row_b += abs(J[b, k] - (mu if k == b else 0.0)) * W[k]
    return W[b] * row_c + W[c] * row_b


def euler_rate_bound(J: NDArray[np.float64], W0: float, W1: float, W2: float, A0: float, A1: float, A2: float,
                     j: int) -> float:
    """A bound on |d/dt (w x J w)_j| (N m / s) for |w_k| <= W_k and |w_dot_k| <= A_k: with J' of `euler_bound`,
    w' x J' w + w x J' w' gives A_b sum_k |J'_ck| W_k + W_b sum_k |J'_ck| A_k + (b and c swapped)."""
    b, c = (j + 1) % 3, (j + 2) % 3
    mu = 0.5 * (J[b, b] + J[c, c])
    W = (W0, W1, W2)
    A = (A0, A1, A2)
    cw = ca = bw = ba = 0.0
    for k in range(3):
        jc = abs(J[c, k] - (mu if k == c else 0.0))
        jb = abs(J[b, k] - (mu if k == b else 0.0))
        cw += jc * W[k]
        ca += jc * A[k]
        bw += jb * W[k]
        ba += jb * A[k]
    return A[b] * cw + W[b] * ca + A[c] * bw + W[c] * ba


def is_principal(products: tuple[float, float, float]) -> bool:
    """The body axes are the tensor's principal axes (every product exactly zero)."""
    return all(v == 0.0 for v in products)


def principal_moments(J: NDArray[np.float64]) -> NDArray[np.float64]:
    """The eigenvalues of J, ascending, kg m^2."""
    return np.linalg.eigvalsh(J)


__all__ = ["TRIANGLE_RTOL", "check_inertia", "euler_bound", "euler_rate_bound", "inertia_matrix", "is_principal",
           "principal_moments"]
