r"""Product quadrature on the sphere, projection (eq. 1) and reconstruction (eq. 2).

The rule is Gauss–Legendre in :math:`z = \cos\vartheta` times the uniform
(trapezoidal) rule in :math:`\varphi`.  With ``N`` Gauss nodes and ``M``
azimuths it integrates exactly every polynomial in ``(x, y, z)`` of total
degree ``<= min(2N - 1, M - 1)`` restricted to the sphere: such a polynomial
is a sum of terms :math:`p(z)\,e^{i m \varphi}` with ``|m| <= degree``; the
``M``-point uniform rule integrates every ``e^{i m phi}`` with ``0 < |m| < M`` to
zero exactly, and what is left (``m = 0``) is a polynomial of degree ``<= degree``
in ``z``, which the Gauss rule integrates exactly when ``2N - 1 >= degree``.
:func:`sphere_quadrature` picks ``N = floor(degree/2) + 1`` and
``M = degree + 1``.

Projection of samples :math:`f(s_q)` is :math:`\mathbf f = \sum_q w_q f(s_q)
\mathbf y(s_q)` (eq. 1), exact when ``f`` is a polynomial of degree
``<= degree - (order - 1)``; reconstruction is :math:`\tilde f(s) = \mathbf f
\cdot \mathbf y(s)` (eq. 2).
"""

from __future__ import annotations

import functools

import numpy as np

from shtools.sh.basis import basis, check_order, order_from_size


@functools.lru_cache(maxsize=64)
def _quadrature_cached(degree: int) -> tuple[np.ndarray, np.ndarray]:
    z, wz, phi, n_phi = _gauss_azimuth_grid(degree, even_azimuths=False)
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(np.clip(1.0 - zz * zz, 0.0, None))
    dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    weights = np.repeat(wz * (2.0 * np.pi / n_phi), n_phi)
    dirs.setflags(write=False)
    weights.setflags(write=False)
    return dirs, weights


def sphere_quadrature(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature on the unit sphere exact for polynomials of total degree ``<= degree``.

    Parameters
    ----------
    degree : int
        Polynomial degree (>= 0) integrated exactly.

    Returns
    -------
    dirs : ndarray, shape (Q, 3)
        Unit directions, ``Q = (degree // 2 + 1) * (degree + 1)``.
    weights : ndarray, shape (Q,)
        Positive weights summing to ``4*pi``.

    Notes
    -----
    The arrays are cached and read-only; copy them before modifying.
    """
    if isinstance(degree, bool) or int(degree) != degree or degree < 0:
        raise ValueError(f"quadrature degree must be an integer >= 0, got {degree!r}")
    return _quadrature_cached(int(degree))


def project(values, dirs, weights, order: int) -> np.ndarray:
    """Project sampled spherical functions onto the SH basis (eq. 1).

    Parameters
    ----------
    values : array_like, shape (..., Q)
        Function values at ``dirs``.
    dirs : array_like, shape (Q, 3)
        Quadrature directions.
    weights : array_like, shape (Q,)
        Quadrature weights.
    order : int
        SH order ``n`` of the result.

    Returns
    -------
    ndarray, shape (..., n*n)
        ``sum_q weights[q] * values[..., q] * y(dirs[q])``.
    """
    order = check_order(order)
    y = basis(np.asarray(dirs, dtype=np.float64), order)  # (Q, n*n)
    yw = y * np.asarray(weights, dtype=np.float64)[:, None]
    return np.asarray(values) @ yw


def reconstruct(coeffs, dirs) -> np.ndarray:
    """Evaluate SH vectors at directions (eq. 2).

    Parameters
    ----------
    coeffs : array_like, shape (..., n*n)
        SH vectors.
    dirs : array_like, shape (Q, 3)
        Unit directions.

    Returns
    -------
    ndarray, shape (..., Q)
        ``coeffs . y(dirs[q])`` for every direction.
    """
    c = np.asarray(coeffs)
    order = order_from_size(c.shape[-1])
    y = basis(np.asarray(dirs, dtype=np.float64), order)  # (Q, n*n)
    return c @ y.T


def _gauss_azimuth_grid(degree: int, even_azimuths: bool):
    """Gauss-Legendre nodes in z and uniform azimuths of a degree-exact product rule.

    Returns ``(z, wz, phi, n_phi)`` with ``N = degree // 2 + 1`` Gauss nodes and
    ``M = degree + 1`` azimuths (made even when ``even_azimuths``, so that
    ``phi + pi`` is a node).
    """
    n_gauss = degree // 2 + 1
    n_phi = degree + 1 + ((degree + 1) % 2 if even_azimuths else 0)
    z, wz = np.polynomial.legendre.leggauss(n_gauss)
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    return z, wz, phi, n_phi


@functools.lru_cache(maxsize=64)
def _half_cached(degree: int) -> tuple[np.ndarray, np.ndarray]:
    z, wz, _, n_phi = _gauss_azimuth_grid(degree, even_azimuths=True)
    keep = z >= -1e-12
    z, wz = np.abs(z[keep]), wz[keep] * np.where(np.abs(z[keep]) < 1e-12, 0.5, 1.0)
    phi = 2.0 * np.pi * (np.arange(n_phi // 2) + 0.5) / n_phi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(np.clip(1.0 - zz * zz, 0.0, None))
    dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    weights = np.repeat(wz * (2.0 * np.pi / n_phi), n_phi // 2) * 4.0
    dirs.setflags(write=False)
    weights.setflags(write=False)
    return dirs, weights


def quarter_sphere_quadrature(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Base points of the degree-exact rule under z -> -z and phi -> phi + pi.

    The rule of :func:`sphere_quadrature` with an even azimuth count is
    symmetric under both reflections, so a function whose SH coefficients are
    split by parity (even/odd in ``l + m`` and in ``m``) is known at all nodes
    from its values at the base points ``z >= 0``, ``0 <= phi < pi`` (a quarter of
    them).  A ``z = 0`` node is its own mirror and keeps half its weight; the
    weights include the factor 4 of the images, so ``sum_q w_q g(s_q)``
    integrates a function even under both reflections exactly.

    Returns
    -------
    dirs : ndarray, shape (Qb, 3)
    weights : ndarray, shape (Qb,)
        Cached and read-only.
    """
    if isinstance(degree, bool) or int(degree) != degree or degree < 0:
        raise ValueError(f"quadrature degree must be an integer >= 0, got {degree!r}")
    return _half_cached(int(degree))
