r"""Rotation of SH vectors by 3×3 rotation matrices, any order.

The rotated function is :math:`(\mathcal R f)(s) = f(R^{T} s)`, so a cap about
``a`` becomes a cap about ``R a``.  Rotation does not mix bands; its matrix is
block diagonal with

.. math::

    D_{ij} = \int_S y_i(s)\, y_j(R^{T} s)\, ds,

computed *exactly* with the quadrature of :mod:`shtools.sh.quadrature` of degree
``2 (n - 1)`` (the integrand is a polynomial of that degree), i.e. the
projection of the rotated basis.  Cost per matrix: two basis evaluations at
``Q ~ n^2`` points and one ``(n^2, Q) @ (Q, n^2)`` product; entries outside the
diagonal blocks are exactly zero by construction.
"""

from __future__ import annotations

import numpy as np

from shtools.sh.basis import band_of, basis, check_order, order_from_size
from shtools.sh.quadrature import sphere_quadrature

ROTATION_TOL = 1e-6
"""Tolerance of the check that ``R`` is a rotation (``R^T R = I``, ``det R = 1``)."""


def _check_rotation(R: np.ndarray) -> np.ndarray:
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have shape (..., 3, 3), got {R.shape}")
    eye = np.einsum("...ji,...jk->...ik", R, R)
    if not (np.allclose(eye, np.eye(3), atol=ROTATION_TOL)
            and np.allclose(np.linalg.det(R), 1.0, atol=ROTATION_TOL)):
        raise ValueError("R must be a proper rotation matrix (orthonormal, det +1)")
    return R


def rotation_matrix(R, order: int) -> np.ndarray:
    """SH rotation matrix of a 3×3 rotation.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Proper rotation matrices.
    order : int
        SH order ``n``.

    Returns
    -------
    ndarray, shape (..., n*n, n*n)
        ``D`` with ``rotate(f, R) = D @ f``: block diagonal, orthogonal,
        ``D(R1 @ R2) = D(R1) @ D(R2)``.
    """
    order = check_order(order)
    R = _check_rotation(R)
    dirs, w = sphere_quadrature(2 * (order - 1))
    y = basis(dirs, order)  # (Q, n^2)
    rotated_dirs = np.einsum("...ji,qj->...qi", R, dirs)  # R^T s
    y_rot = basis(rotated_dirs, order)  # (..., Q, n^2)
    d = np.einsum("qi,...qj->...ij", y * w[:, None], y_rot)
    band = band_of(order)
    d *= band[:, None] == band[None, :]  # exact zeros off the band blocks
    return d


def rotate(f, R) -> np.ndarray:
    """Rotate SH vectors: the result represents ``s -> f(R^T s)``.

    Parameters
    ----------
    f : array_like, shape (..., n*n)
        SH vectors.
    R : array_like, shape (3, 3)
        Proper rotation matrix (a stack ``(..., 3, 3)`` broadcasting against
        ``f``'s leading axes is accepted too).

    Returns
    -------
    ndarray, shape (..., n*n)
        Rotated vectors.
    """
    f = np.asarray(f)
    n = order_from_size(f.shape[-1])
    d = rotation_matrix(R, n)
    if d.ndim == 2:
        return f @ d.T.astype(f.dtype if f.dtype.kind == "f" else np.float64)
    return np.einsum("...ij,...j->...i", d, f)


def rotate_about_y(coeffs, angle: float) -> np.ndarray:
    """RGB SH coefficients turned ``angle`` radians about +Y (an environment's turntable).

    Parameters
    ----------
    coeffs : array_like, shape (n*n, 3)
    angle : float

    Returns
    -------
    ndarray, shape (n*n, 3)
    """
    c, s = np.cos(angle), np.sin(angle)
    r_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return rotate(np.asarray(coeffs, dtype=float).T, r_y).T
