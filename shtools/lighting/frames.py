r"""Frame changes of SH vectors: rotations and reflections of the argument.

For an orthogonal matrix ``M`` (rotation or reflection), the function
:math:`f'(s) = f(M^T s)` (``f`` carried along by ``M``) has the coefficients
:math:`\mathbf f' = T(M)\,\mathbf f` with

.. math:: T_{ik} = \int_{S^2} y_i(s)\, y_k(M^T s)\, ds,

a block-diagonal matrix (bands do not mix).  The integrand is a polynomial of
degree ``<= 2(n-1)``, so :func:`shtools.sh.quadrature.sphere_quadrature` of that
degree computes ``T`` exactly (up to rounding).  Unlike an Euler-angle SH
rotation this also handles reflections, which the image-to-world mapping of
lat-long maps needs.
"""

from __future__ import annotations

import math

import numpy as np

from shtools.sh.basis import basis, check_order
from shtools.sh.quadrature import sphere_quadrature

#: Orthogonality tolerance for frame matrices (float64 rounding of user input).
ORTHOGONALITY_TOL = 1e-9


def frame_transform_matrix(m, order: int) -> np.ndarray:
    """SH matrix of the direction map ``s -> M s``.

    Parameters
    ----------
    m : array_like, shape (3, 3)
        Orthogonal matrix (``det = +1`` rotation or ``-1`` reflection).
    order : int
        SH order ``n``.

    Returns
    -------
    ndarray, shape (n*n, n*n)
        ``T`` such that ``T @ f`` are the coefficients of ``s -> f(M^T s)``.
    """
    order = check_order(order)
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (3, 3) or not np.allclose(m @ m.T, np.eye(3), atol=ORTHOGONALITY_TOL):
        raise ValueError("frame matrix must be an orthogonal (3, 3) matrix")
    dirs, weights = sphere_quadrature(2 * (order - 1))
    y = basis(dirs, order)  # (Q, n*n)
    y_moved = basis(dirs @ m, order)  # rows are (M^T s)^T = s^T M
    return (y * weights[:, None]).T @ y_moved


def transform(coeffs, m) -> np.ndarray:
    """Carry SH functions along an orthogonal map: coefficients of ``f(M^T s)``.

    Parameters
    ----------
    coeffs : array_like, shape (n*n, ...)
        SH coefficients along the first axis (e.g. ``(n*n, 3)`` RGB).
    m : array_like, shape (3, 3)
        Orthogonal matrix.

    Returns
    -------
    ndarray, shape (n*n, ...)
    """
    c = np.asarray(coeffs, dtype=np.float64)
    order = math.isqrt(c.shape[0])
    t = frame_transform_matrix(m, order)
    return np.tensordot(t, c, axes=(1, 0))


def rotation_about_y(degrees: float) -> np.ndarray:
    """Rotation by ``degrees`` about +y (right-hand rule: +90 takes -z to -x).

    Returns
    -------
    ndarray, shape (3, 3)
    """
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


#: Maps a Z-up frame (x, y, z) to the Y-up world: z -> +y, y -> -z, x -> x.
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
