r"""SH logarithm (Sec. 5): eigen-inversion of the product series and the naive projection.

``"eigen"`` (eqs. 30–32): diagonalise the product matrix
:math:`M_g = R_g^T D_g R_g` (eq. 5, 27), clip its eigenvalues at
:math:`\epsilon\,\lambda_{\max}` (eq. 32, :math:`\epsilon = 0.02` by default)
and invert the diagonalised product-series exponential (eq. 28):

.. math::

    \log(\mathbf g) = R_g^T\, q'(\tilde D_g)\, R_g\, (\mathbf g - \mathbf 1),
    \qquad q'(x) = \frac{\log x}{x - 1}.

Because it inverts :math:`\exp_*` including its truncation, ``exp*(log g)``
reproduces ``g`` closely (the property tables of circle logs rely on).

``"naive"`` (eq. 25): project :math:`\log(\max(g(s), \epsilon))` with a
quadrature (:mod:`shtools.sh.quadrature`); kept as a reference and for
comparison.
"""

from __future__ import annotations

import numpy as np

from shtools.sh.basis import SQRT_4PI, order_from_size
from shtools.sh.quadrature import project, reconstruct, sphere_quadrature
from shtools.sh.triple import CHUNK_BYTES, product_matrix

LOG_EPS = 0.02
"""Default eigenvalue floor relative to the largest eigenvalue (the paper's 0.02)."""


def _q_prime(x: np.ndarray) -> np.ndarray:
    """``log(x) / (x - 1)`` with the limit 1 at ``x = 1`` (eq. 31)."""
    d = x - 1.0
    small = np.abs(d) < 1e-8
    safe = np.where(small, 1.0, d)
    return np.where(small, 1.0 - 0.5 * d, np.log1p(safe) / safe)


def _log_eigen(g: np.ndarray, eps: float) -> np.ndarray:
    m = product_matrix(g)  # (B, n^2, n^2)
    lam, vec = np.linalg.eigh(m)  # M = V diag(lam) V^T, R_g = V^T
    floor = eps * lam[:, -1:]
    floor = np.where(floor > 0, floor, np.finfo(np.float64).tiny)
    lam = np.maximum(lam, floor)  # eq. 32
    rhs = g.copy()
    rhs[:, 0] -= SQRT_4PI  # g - 1
    c = np.einsum("bji,bj->bi", vec, rhs) * _q_prime(lam)
    out = np.einsum("bij,bj->bi", vec, c)
    return out


def log_zonal(g, eps: float = LOG_EPS) -> np.ndarray:
    r"""The ``"eigen"`` :func:`log` of zonal vectors (symmetric about ``+z``), ``(B, n*n)``.

    The product matrix of a zonal vector maps each ``m`` to itself (the Gaunt
    coefficients of two ``m`` and a zonal ``0`` vanish unless the ``m`` match), so
    :math:`M_g` is block diagonal by ``m`` and the log of a zonal vector, which only
    reads the ``m = 0`` block, is zonal.  Only the eigenvalues of the other blocks
    are needed (the floor of eq. 32 is relative to the largest of all); the result
    equals :func:`log`'s to rounding, for ``n`` eigenproblems of size ``n - |m|``
    instead of one of size ``n^2``.

    Parameters
    ----------
    g : array_like, shape (B, n*n)
        Zonal vectors (only the ``m = 0`` coefficients are read).
    eps : float
        Relative eigenvalue floor (eq. 32).
    """
    g = np.asarray(g, dtype=np.float64)
    n = order_from_size(g.shape[-1])
    flat = g.reshape(-1, n * n)
    zonal = np.zeros_like(flat)
    l = np.arange(n)
    m0 = l * l + l  # flat index of (l, 0)
    zonal[:, m0] = flat[:, m0]
    m = product_matrix(zonal)  # (B, n^2, n^2), block diagonal by m
    lam, vec = np.linalg.eigh(m[:, m0][:, :, m0])
    lam_max = lam[:, -1]
    for k in range(1, n):  # the other blocks (+k and -k are the same matrix)
        idx = l[k:] * l[k:] + l[k:] + k
        lam_max = np.maximum(lam_max, np.linalg.eigvalsh(m[:, idx][:, :, idx])[:, -1])
    floor = (eps * lam_max)[:, None]
    floor = np.where(floor > 0, floor, np.finfo(np.float64).tiny)
    lam = np.maximum(lam, floor)  # eq. 32
    rhs = flat[:, m0].copy()
    rhs[:, 0] -= SQRT_4PI  # g - 1
    c = np.einsum("bji,bj->bi", vec, rhs) * _q_prime(lam)
    out = np.zeros_like(flat)
    out[:, m0] = np.einsum("bij,bj->bi", vec, c)
    return out.reshape(g.shape)


def log(g, method: str = "eigen", eps: float = LOG_EPS, *, quad_degree: int | None = None):
    """SH logarithm of visibility vectors.

    Parameters
    ----------
    g : array_like, shape (..., n*n)
        SH vectors (e.g. visibility of a blocker).
    method : {"eigen", "naive"}
        ``"eigen"``: eqs. 30–32 with the eigenvalue floor ``eps * lambda_max``.
        ``"naive"``: eq. 25, ``project(log(max(g(s), eps)))`` by quadrature.
    eps : float
        Relative eigenvalue floor (``"eigen"``) or absolute clip of ``g(s)``
        (``"naive"``).
    quad_degree : int, optional
        Quadrature degree for ``"naive"`` (default ``4*n + 16``; the integrand is
        not a polynomial, so this sets the accuracy).

    Returns
    -------
    ndarray, shape (..., n*n)
        ``f`` with ``exp(f) ~= g``.
    """
    g = np.asarray(g, dtype=np.float64)
    n = order_from_size(g.shape[-1])
    if not eps > 0:
        raise ValueError(f"eps must be > 0, got {eps!r}")
    lead = g.shape[:-1]
    flat = g.reshape(-1, n * n)
    out = np.empty_like(flat)
    if method == "eigen":
        step = max(1, CHUNK_BYTES // (4 * n**4 * 8))
        for s in range(0, flat.shape[0], step):
            out[s : s + step] = _log_eigen(flat[s : s + step], eps)
    elif method == "naive":
        degree = 4 * n + 16 if quad_degree is None else quad_degree
        dirs, w = sphere_quadrature(degree)
        step = max(1, CHUNK_BYTES // (2 * dirs.shape[0] * 8))
        for s in range(0, flat.shape[0], step):
            values = reconstruct(flat[s : s + step], dirs)
            out[s : s + step] = project(np.log(np.maximum(values, eps)), dirs, w, n)
    else:
        raise ValueError(f"unknown log method {method!r}; use 'eigen' or 'naive'")
    return out.reshape(*lead, n * n)


__all__ = ["LOG_EPS", "log", "log_zonal"]
