r"""SH products (SHEXP, Ren et al. 2006, eqs. 3 and 5) through the triple-product tensor Γ.

Γ (eq. 4) is exact and sparse (:mod:`shtools.sh.gamma`): its ordered nonzeros
``(i, j, k, value)`` are grouped by the unordered input pair ``j <= k``:

.. math::

    (\mathbf f * \mathbf g)_i
      = \sum_{j} \Gamma_{ijj} f_j g_j
      + \sum_{j < k} \Gamma_{ijk} (f_j g_k + f_k g_j).

Products and squares are evaluated by :mod:`shtools.sh._kernels`: by default
through the exact rank-``Q`` factorisation of Γ given by the quadrature (three
small BLAS matrix products), or by the pair grouping above (gathered pair
products times the pair coefficients).
The product matrix is :math:`(M_f)_{ij} = \sum_k \Gamma_{ijk} f_k` (eq. 5) and the triple
integral is :math:`(a, b, c) = (a * b)\cdot c`.

Truncation: the product of two order-``n`` functions has order ``2n - 1``;
``order=`` (the output order) keeps more of it, so products can be accumulated
at a higher order and truncated at the end (Sec. 4).
"""

from __future__ import annotations

import functools

import numpy as np

from shtools.sh._kernels import run_product
from shtools.sh.basis import check_order, order_from_size
from shtools.sh.gamma import TripleTensor, triple_tensor

__all__ = ["CHUNK_BYTES", "TripleTensor", "product", "product_matrix", "square", "triple",
           "triple_tensor"]

CHUNK_BYTES = 48 * 2**20
"""Working-set bound of the batched kernels: their temporaries stay a small part of a
worker's memory however many vectors a call gets."""


def _pad(f: np.ndarray, order: int) -> np.ndarray:
    size = order * order
    if f.shape[-1] == size:
        return f
    out = np.zeros((*f.shape[:-1], size), dtype=f.dtype)
    out[..., : f.shape[-1]] = f
    return out


def _float_dtype(*arrays) -> np.dtype:
    dt = np.result_type(*arrays)
    return dt if dt in (np.float32, np.float64) else np.dtype(np.float64)


def product(f, g, order: int | None = None, *, kernel: str = "cp") -> np.ndarray:
    """Truncated SH product ``f * g`` (eq. 3).

    Parameters
    ----------
    f, g : array_like, shape (..., n_f*n_f) and (..., n_g*n_g)
        SH vectors (broadcast against each other; orders may differ).
    order : int, optional
        Output order (default: the order of ``f``).  A higher order keeps more of
        the exact product (whose order is ``n_f + n_g - 1``).
    kernel : str
        Evaluation (:data:`shtools.sh._kernels.PRODUCT_KERNELS`): ``"cp"``,
        quadrature factors of Γ on BLAS (default, faster), or ``"sparse"``, the
        sparse Γ contraction; all exact.

    Returns
    -------
    ndarray, shape (..., order**2)
        ``sum_jk Γ[i, j, k] f_j g_k``; float32 if both inputs are float32.
    """
    f = np.asarray(f)
    g = np.asarray(g)
    dtype = _float_dtype(f, g)
    n_in = max(order_from_size(f.shape[-1]), order_from_size(g.shape[-1]))
    n_out = order_from_size(f.shape[-1]) if order is None else check_order(order)
    f, g = np.broadcast_arrays(_pad(f.astype(dtype, copy=False), n_in),
                               _pad(g.astype(dtype, copy=False), n_in))
    lead = f.shape[:-1]
    f2 = f.reshape(-1, n_in * n_in)
    g2 = g.reshape(-1, n_in * n_in)
    out = run_product(np.ascontiguousarray(f2), np.ascontiguousarray(g2), n_in, n_out,
                      kernel=kernel)
    return out.reshape(*lead, n_out * n_out)


def square(f, order: int | None = None) -> np.ndarray:
    """SH square ``f * f`` (cheaper than :func:`product`).

    Parameters
    ----------
    f : array_like, shape (..., n*n)
        SH vectors.
    order : int, optional
        Output order (default ``n``).

    Returns
    -------
    ndarray, shape (..., order**2)
    """
    f = np.asarray(f)
    dtype = _float_dtype(f)
    f = f.astype(dtype, copy=False)
    n_in = order_from_size(f.shape[-1])
    n_out = n_in if order is None else check_order(order)
    lead = f.shape[:-1]
    f2 = f.reshape(-1, n_in * n_in)
    out = run_product(np.ascontiguousarray(f2), None, n_in, n_out)
    return out.reshape(*lead, n_out * n_out)


def product_matrix(f, order: int | None = None) -> np.ndarray:
    """SH product matrix ``M_f`` (eq. 5): ``f * g = M_f @ g``.

    Parameters
    ----------
    f : array_like, shape (..., n*n)
        SH vectors.
    order : int, optional
        Order of the square matrix (default ``n``); ``f`` is zero-padded or
        truncated to it.

    Returns
    -------
    ndarray, shape (..., order**2, order**2)
        Symmetric matrices ``M[i, j] = sum_k Γ[i, j, k] f_k``.
    """
    f = np.asarray(f, dtype=np.float64)
    n_f = order_from_size(f.shape[-1])
    n = n_f if order is None else check_order(order)
    size = n * n
    f = _pad(f, n)[..., :size]
    lead = f.shape[:-1]
    flat_f = f.reshape(-1, size)
    out = flat_f @ _product_matrix_map(n).T
    return out.reshape(*lead, size, size)


@functools.lru_cache(maxsize=16)
def _product_matrix_map(order: int) -> np.ndarray:
    """Linear map ``f -> vec(M_f)``, shape ``(n^4, n^2)``."""
    t = triple_tensor(order, order)
    size = order * order
    mat = np.zeros((size * size, size))
    np.add.at(mat, (t.i * size + t.j, t.k), t.values)
    mat.setflags(write=False)
    return mat


def triple(a, b, c) -> np.ndarray:
    """Triple integral ``(a, b, c) = sum_ijk Γ[i, j, k] a_i b_j c_k``.

    Parameters
    ----------
    a, b, c : array_like, shape (..., n*n)
        SH vectors of the same order (broadcast over leading axes).

    Returns
    -------
    ndarray, shape (...)
        Integral over the sphere of the product of the three reconstructions.
    """
    c = np.asarray(c)
    n = order_from_size(c.shape[-1])
    return np.sum(product(a, b, order=n) * c, axis=-1)
