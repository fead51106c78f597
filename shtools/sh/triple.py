r"""The SH triple-product tensor Γ (eq. 4) and SH products (eqs. 3, 5).

:math:`\Gamma_{ijk} = \int_S y_i y_j y_k\,ds` is computed once per
``(order, out_order)`` by the quadrature of :mod:`shtools.sh.quadrature` of
degree ``(n_out - 1) + 2 (n - 1)``, which is *exact* because the integrand is a
polynomial of that degree; entries below :data:`GAMMA_ZERO` (round-off of
entries that vanish by the selection rules) are dropped.  The sparse tensor is
kept as ordered nonzeros ``(i, j, k, value)`` and grouped by the unordered
input pair ``j <= k``:

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
from dataclasses import dataclass

import numpy as np

from shtools.sh._kernels import run_product
from shtools.sh.basis import basis, check_order, order_from_size
from shtools.sh.quadrature import sphere_quadrature

GAMMA_ZERO = 1e-10
"""|Γ| below this is round-off of a structural zero (true nonzeros exceed 4e-3 up to n = 8)."""

CHUNK_BYTES = 48 * 2**20
"""Working-set bound of the batched kernels (the brief caps memory near 200 MB)."""


@dataclass(frozen=True, eq=False)
class TripleTensor:
    """Sparse triple-product tensor ``Γ[i, j, k]`` with ``i < out_order**2``, ``j, k < order**2``.

    Attributes
    ----------
    order, out_order : int
        Input and output SH orders.
    i, j, k : ndarray, shape (N,)
        Indices of every (ordered) nonzero entry.
    values : ndarray, shape (N,)
        Their values.
    pair_j, pair_k : ndarray, shape (P,)
        Unordered input pairs ``j <= k`` that carry at least one nonzero.
    pair_coef : ndarray, shape (P, out_order**2)
        ``Γ[i, j, k]`` per pair and output, for products.
    square_coef : ndarray, shape (P, out_order**2)
        The same with ``j < k`` doubled, for squares.
    """

    order: int
    out_order: int
    i: np.ndarray
    j: np.ndarray
    k: np.ndarray
    values: np.ndarray
    pair_j: np.ndarray
    pair_k: np.ndarray
    pair_coef: np.ndarray
    square_coef: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(out_order**2, order**2, order**2)``."""
        return (self.out_order**2, self.order**2, self.order**2)

    @property
    def nnz(self) -> int:
        """Number of ordered nonzero entries."""
        return int(self.values.size)

    def todense(self) -> np.ndarray:
        """Dense tensor, shape ``(out_order**2, order**2, order**2)``."""
        dense = np.zeros(self.shape)
        dense[self.i, self.j, self.k] = self.values
        return dense


@functools.lru_cache(maxsize=32)
def _triple_tensor_cached(order: int, out_order: int) -> TripleTensor:
    dirs, w = sphere_quadrature((out_order - 1) + 2 * (order - 1))
    y_out = basis(dirs, out_order)  # (Q, n_out^2)
    y_in = basis(dirs, order)  # (Q, n^2)
    dense = np.einsum("qi,qj,qk->ijk", y_out * w[:, None], y_in, y_in, optimize=True)
    # Make Γ exactly symmetric (quadrature round-off differs between permutations):
    # every entry takes the value stored at its sorted index triple.
    if out_order == order:
        idx = np.sort(np.indices(dense.shape).reshape(3, -1), axis=0)
    else:
        i_, j_, k_ = np.indices(dense.shape).reshape(3, -1)
        idx = (i_, np.minimum(j_, k_), np.maximum(j_, k_))
    dense = dense[tuple(idx)].reshape(dense.shape)
    dense[np.abs(dense) < GAMMA_ZERO] = 0.0
    i, j, k = np.nonzero(dense)
    values = dense[i, j, k]
    upper = np.triu(np.any(dense != 0.0, axis=0))  # (n^2, n^2), pairs j <= k
    pair_j, pair_k = np.nonzero(upper)
    pair_coef = dense[:, pair_j, pair_k].T.copy()  # (P, n_out^2)
    square_coef = pair_coef * np.where(pair_j < pair_k, 2.0, 1.0)[:, None]
    arrays = (i, j, k, values, pair_j, pair_k, pair_coef, square_coef)
    for a in arrays:
        a.setflags(write=False)
    return TripleTensor(order, out_order, *arrays)


def triple_tensor(order: int, out_order: int | None = None) -> TripleTensor:
    """Sparse SH triple-product tensor (eq. 4), exact, cached per orders.

    Parameters
    ----------
    order : int
        SH order ``n`` of the two inputs ``j, k``.
    out_order : int, optional
        SH order of the output index ``i`` (default ``order``).

    Returns
    -------
    TripleTensor
        Ordered nonzeros and the pair grouping used by :func:`product`.
    """
    order = check_order(order)
    out_order = order if out_order is None else check_order(out_order)
    return _triple_tensor_cached(order, out_order)


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
