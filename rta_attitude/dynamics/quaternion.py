"""Scalar-last quaternion algebra (Markley & Crassidis), compiled for one quaternion, with batch faces.

q = [q1 q2 q3 | q4] rotates Hill-frame vectors into the body frame: v_B = A(q) v_H.

    A(q)       = (q4^2 - |q_v|^2) I + 2 q_v q_v^T - 2 q4 [q_v x]
    q (x) p    = [q4 p_v + p4 q_v - q_v x p_v ; q4 p4 - q_v . p_v],     A(q (x) p) = A(q) A(p)
    dq         = q (x) q_c^-1 (vector part: the attitude error; no shortest-path sign flip, as the paper)
    q_dot      = 1/2 Xi(q) omega, Xi rows [q4 -q3 q2; q3 q4 -q1; -q2 q1 q4; -q1 -q2 -q3]

The compiled functions are what every path calls (the plant's kinematics, the barriers, the
controller); `attitude_matrices` and `error_vectors` loop them over batches for reports and plots.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from rta_attitude.jit import LEAF

Array = NDArray[np.float64]


@numba.njit(**LEAF)
def attitude_matrix(q1: float, q2: float, q3: float, q4: float, A: Array) -> None:
    """A(q) (3, 3), Hill -> body. Row i is body axis i in Hill; column j is Hill axis j in body."""
    s11, s22, s33, s44 = q1 * q1, q2 * q2, q3 * q3, q4 * q4
    A[0, 0] = s11 - s22 - s33 + s44
    A[0, 1] = 2.0 * (q1 * q2 + q3 * q4)
    A[0, 2] = 2.0 * (q1 * q3 - q2 * q4)
    A[1, 0] = 2.0 * (q1 * q2 - q3 * q4)
    A[1, 1] = -s11 + s22 - s33 + s44
    A[1, 2] = 2.0 * (q2 * q3 + q1 * q4)
    A[2, 0] = 2.0 * (q1 * q3 + q2 * q4)
    A[2, 1] = 2.0 * (q2 * q3 - q1 * q4)
    A[2, 2] = -s11 - s22 + s33 + s44


@numba.njit(**LEAF)
def product(q: Array, p: Array, out: Array) -> None:
    """Markley's product q (x) p (4,) into out."""
    qv0, qv1, qv2, q4 = q[0], q[1], q[2], q[3]
    pv0, pv1, pv2, p4 = p[0], p[1], p[2], p[3]
    c0 = qv1 * pv2 - qv2 * pv1
    c1 = qv2 * pv0 - qv0 * pv2
    c2 = qv0 * pv1 - qv1 * pv0
    out[0] = q4 * pv0 + p4 * qv0 - c0
    out[1] = q4 * pv1 + p4 * qv1 - c1
    out[2] = q4 * pv2 + p4 * qv2 - c2
    out[3] = q4 * p4 - (qv0 * pv0 + qv1 * pv1 + qv2 * pv2)


@numba.njit(**LEAF)
def error_vector(q: Array, q_c: Array, out: Array) -> None:
    """Vector part of dq = q (x) q_c^-1 (3,) into out (q_c unit: its inverse is its conjugate); the
    vector part of `product(q, conj(q_c))`, operation for operation."""
    qv0, qv1, qv2, q4 = q[0], q[1], q[2], q[3]
    pv0, pv1, pv2, p4 = -q_c[0], -q_c[1], -q_c[2], q_c[3]
    c0 = qv1 * pv2 - qv2 * pv1
    c1 = qv2 * pv0 - qv0 * pv2
    c2 = qv0 * pv1 - qv1 * pv0
    out[0] = q4 * pv0 + p4 * qv0 - c0
    out[1] = q4 * pv1 + p4 * qv1 - c1
    out[2] = q4 * pv2 + p4 * qv2 - c2


@numba.njit(**LEAF)
def from_matrix(A: Array, out: Array) -> None:
    """The unit quaternion (4,) with attitude_matrix(q) == A (a rotation matrix (3, 3)) into out, q4 >= 0
    (Shepperd's method: the largest of q4^2, q1^2, q2^2, q3^2 is found from the diagonal first)."""
    tr = A[0, 0] + A[1, 1] + A[2, 2]
    i = 3
    best = tr
    for a in range(3):
        if A[a, a] > best:
            i, best = a, A[a, a]
    if i == 3:
        q4 = 0.5 * math.sqrt(1.0 + tr)
        f = 0.25 / q4
        out[0], out[1], out[2], out[3] = (A[1, 2] - A[2, 1]) * f, (A[2, 0] - A[0, 2]) * f, (A[0, 1] - A[1, 0]) * f, q4
    else:
        j, k = (i + 1) % 3, (i + 2) % 3
        qi = 0.5 * math.sqrt(1.0 + 2.0 * A[i, i] - tr)
        f = 0.25 / qi
        out[i], out[j], out[k], out[3] = qi, (A[i, j] + A[j, i]) * f, (A[i, k] + A[k, i]) * f, (A[j, k] - A[k, j]) * f
    n = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3])
    sign = 1.0 if out[3] >= 0.0 else -1.0
    for a in range(4):
        out[a] = sign * out[a] / n


@numba.njit(**LEAF)
def _attitude_matrices(Q: Array, out: Array) -> None:
    for k in range(Q.shape[0]):
        attitude_matrix(Q[k, 0], Q[k, 1], Q[k, 2], Q[k, 3], out[k])


@numba.njit(**LEAF)
def _error_vectors(Q: Array, Qc: Array, out: Array) -> None:
    for k in range(Q.shape[0]):
        error_vector(Q[k], Qc[k], out[k])


def attitude_matrices(q: Array) -> Array:
    """A(q) of quaternions (..., 4): (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    Q = np.ascontiguousarray(q.reshape(-1, 4))
    out = np.empty((Q.shape[0], 3, 3))
    _attitude_matrices(Q, out)
    return out.reshape((*q.shape[:-1], 3, 3))


def error_vectors(q: Array, q_c: Array) -> Array:
    """Vector parts of q (x) q_c^-1 (..., 3) for quaternions (..., 4) (q_c broadcast to q)."""
    q = np.asarray(q, dtype=float)
    Q = np.ascontiguousarray(q.reshape(-1, 4))
    Qc = np.ascontiguousarray(np.broadcast_to(np.asarray(q_c, dtype=float), q.shape).reshape(-1, 4))
    out = np.empty((Q.shape[0], 3))
    _error_vectors(Q, Qc, out)
    return out.reshape((*q.shape[:-1], 3))


def normalize(q: Array) -> Array:
    """q / |q| on (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


__all__ = ["attitude_matrices", "attitude_matrix", "error_vector", "error_vectors", "from_matrix", "normalize",
           "product"]
