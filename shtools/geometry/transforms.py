"""Rigid transforms: unit quaternions, TRS matrices and slerp.

Conventions (those of glTF 2.0, "Transformations"): quaternions are
``(x, y, z, w)``, matrices act on column vectors, and a node transform is
``T @ R @ S``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "decompose_trs",
    "euler_to_quaternion",
    "matrix_quaternion",
    "quaternion_matrix",
    "quaternion_multiply",
    "slerp",
    "trs_matrix",
]

#: below this cosine between keys, slerp falls back to normalised lerp (no division
#: by a vanishing sin)
_SLERP_LINEAR_DOT = 0.9995


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrices of unit quaternions.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        ``(x, y, z, w)``; normalised here.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def trs_matrix(translation, rotation, scale) -> np.ndarray:
    """``T @ R @ S`` as a 4x4 matrix (glTF node transform), shape ``(4, 4)``."""
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(rotation) * np.asarray(scale, dtype=np.float64)[None, :]
    m[:3, 3] = translation
    return m


def slerp(q0, q1, u) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions along the shortest arc.

    Parameters
    ----------
    q0, q1 : array_like, shape (4,)
    u : float
        In [0, 1].

    Returns
    -------
    ndarray, shape (4,)
        Unit quaternion.
    """
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    q0 = q0 / np.linalg.norm(q0)
    q1 = q1 / np.linalg.norm(q1)
    dot = float(q0 @ q1)
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > _SLERP_LINEAR_DOT:
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    angle = np.arccos(min(dot, 1.0))
    s = np.sin(angle)
    return (np.sin((1 - u) * angle) * q0 + np.sin(u * angle) * q1) / s


def decompose_trs(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """TRS of an affine matrix without shear (what glTF allows for animated nodes)."""
    t = m[:3, 3].copy()
    s = np.linalg.norm(m[:3, :3], axis=0)
    r = m[:3, :3] / np.where(s > 0, s, 1.0)
    if np.linalg.det(r) < 0:
        s[0], r[:, 0] = -s[0], -r[:, 0]
    return t, matrix_quaternion(r), s


def matrix_quaternion(r: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix."""
    trace = np.trace(r)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = s / 4
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def euler_to_quaternion(degrees: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of ``R = Rz @ Ry @ Rx`` from angles in degrees (x, y, z)."""
    hx, hy, hz = np.radians(np.asarray(degrees, dtype=float)) / 2
    qx = np.array([math.sin(hx), 0, 0, math.cos(hx)])
    qy = np.array([0, math.sin(hy), 0, math.cos(hy)])
    qz = np.array([0, 0, math.sin(hz), math.cos(hz)])
    return quaternion_multiply(quaternion_multiply(qz, qy), qx)


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (x, y, z, w); ``a*b`` rotates by b then a."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])
