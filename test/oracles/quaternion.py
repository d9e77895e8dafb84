"""Scalar-last quaternion algebra (Markley & Crassidis), batched on the last axis (..., 4).

q = [q1 q2 q3 | q4] rotates Hill-frame vectors into the body frame: v_B = A(q) v_H.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def normalize(q: Array) -> Array:
    """q / |q| on (..., 4)."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def conjugate(q: Array) -> Array:
    """Inverse of a unit quaternion (..., 4): vector part negated."""
    out = np.array(q, dtype=float, copy=True)
    out[..., :3] *= -1.0
    return out


def product(q: Array, p: Array) -> Array:
    """Markley's product q (x) p on (..., 4), with A(q (x) p) = A(q) A(p).

    q (x) p = [q4 p_v + p4 q_v - q_v x p_v ; q4 p4 - q_v . p_v].
    """
    qv, q4 = q[..., :3], q[..., 3:4]
    pv, p4 = p[..., :3], p[..., 3:4]
    vec = q4 * pv + p4 * qv - np.cross(qv, pv)
    sca = q4 * p4 - np.sum(qv * pv, axis=-1, keepdims=True)
    return np.concatenate([vec, sca], axis=-1)


def attitude_matrix(q: Array) -> Array:
    """A(q) (..., 3, 3): Hill -> body, A = (q4^2 - |q_v|^2) I + 2 q_v q_v^T - 2 q4 [q_v x]."""
    q = np.asarray(q, dtype=float)
    q1, q2, q3, q4 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    A = np.empty((*q.shape[:-1], 3, 3))
    s11, s22, s33, s44 = q1 * q1, q2 * q2, q3 * q3, q4 * q4
    A[..., 0, 0] = s11 - s22 - s33 + s44
    A[..., 1, 1] = -s11 + s22 - s33 + s44
    A[..., 2, 2] = -s11 - s22 + s33 + s44
    A[..., 0, 1] = 2.0 * (q1 * q2 + q3 * q4)
    A[..., 0, 2] = 2.0 * (q1 * q3 - q2 * q4)
    A[..., 1, 0] = 2.0 * (q1 * q2 - q3 * q4)
    A[..., 1, 2] = 2.0 * (q2 * q3 + q1 * q4)
    A[..., 2, 0] = 2.0 * (q1 * q3 + q2 * q4)
    A[..., 2, 1] = 2.0 * (q2 * q3 - q1 * q4)
    return A


def kinematics(q: Array, omega: Array) -> Array:
    """q_dot = 1/2 Xi(q) omega (..., 4), written out (the hot path of the integrator)."""
    q1, q2, q3, q4 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    w1, w2, w3 = omega[..., 0], omega[..., 1], omega[..., 2]
    out = np.empty(np.broadcast_shapes(q.shape, (*omega.shape[:-1], 4)))
    out[..., 0] = 0.5 * (q4 * w1 - q3 * w2 + q2 * w3)
    out[..., 1] = 0.5 * (q3 * w1 + q4 * w2 - q1 * w3)
    out[..., 2] = 0.5 * (-q2 * w1 + q1 * w2 + q4 * w3)
    out[..., 3] = -0.5 * (q1 * w1 + q2 * w2 + q3 * w3)
    return out


def xi(q: Array) -> Array:
    """Xi(q) (..., 4, 3), with q_dot = 1/2 Xi(q) omega."""
    q1, q2, q3, q4 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([q4, -q3, q2], -1),
        np.stack([q3, q4, -q1], -1),
        np.stack([-q2, q1, q4], -1),
        np.stack([-q1, -q2, -q3], -1),
    ], -2)  # fmt: skip


def error_vector(q: Array, q_c: Array) -> Array:
    """Vector part of dq = q (x) q_c^-1 (..., 3), no shortest-path sign flip (as the paper)."""
    return product(q, conjugate(q_c))[..., :3]


__all__ = ["attitude_matrix", "conjugate", "error_vector", "kinematics", "normalize", "product", "xi"]
