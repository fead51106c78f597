r"""Batched kernels for the SH product and square (used by :mod:`shtools.sh.triple`).

Exact evaluations of :math:`(\mathbf f * \mathbf g)_i = \sum_{jk}\Gamma_{ijk} f_j g_k`,
registered by name in :data:`PRODUCT_KERNELS` (a :class:`shtools.registry.Registry`; a
benchmark may register more, e.g. the generated unrolled kernel of
``benchmarks/unrolled_kernel.py``):

*Quadrature (CP) kernel* (``"cp"``, the default): the exact quadrature of degree
``(n_out - 1) + 2(n - 1)`` factors Γ as :math:`\Gamma_{ijk} = \sum_q w_q
y_i(s_q) y_j(s_q) y_k(s_q)`, a canonical-polyadic decomposition of rank ``Q``,
so the product is three small matrix products: reconstruct ``f`` and ``g`` at
the nodes, multiply, project.  BLAS runs these near peak, which makes it faster
than the sparse kernel (``benchmarks/bench_sh.py`` measures both).

*Sparse tensor kernel* (``"sparse"``): the nonzeros of Γ grouped by the
unordered input pair ``j <= k`` (:class:`shtools.sh.gamma.TripleTensor`): one
gathered product ``f_j g_k + f_k g_j`` per pair, then one matrix product with
the ``(P, n_out^2)`` pair coefficients.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from shtools.registry import Registry
from shtools.sh.basis import basis
from shtools.sh.gamma import triple_tensor
from shtools.sh.quadrature import sphere_quadrature

CP_CHUNK = 4096
"""Vectors per chunk of the quadrature kernel."""
SPARSE_CHUNK = 1024
"""Vectors per chunk of the sparse kernel (the pair products are ``(chunk, P)``)."""

#: kernel(f, g or None, order, out_order) -> (B, out_order**2)
ProductKernel = Callable[[np.ndarray, np.ndarray | None, int, int], np.ndarray]


@functools.lru_cache(maxsize=64)
def _cp_factors(order: int, out_order: int, dtype: str):
    dirs, w = sphere_quadrature((out_order - 1) + 2 * (order - 1))
    y_in = np.ascontiguousarray(basis(dirs, order).T, dtype=dtype)  # (n^2, Q)
    y_out = np.ascontiguousarray(basis(dirs, out_order) * w[:, None], dtype=dtype)  # (Q, n_out^2)
    y_in.setflags(write=False)
    y_out.setflags(write=False)
    return y_in, y_out


def _cp_kernel(f, g, order, out_order):
    y_in, y_out = _cp_factors(order, out_order, f.dtype.str)
    out = np.empty((f.shape[0], out_order * out_order), dtype=f.dtype)
    for s in range(0, f.shape[0], CP_CHUNK):
        e = min(f.shape[0], s + CP_CHUNK)
        at_nodes = f[s:e] @ y_in
        if g is None:
            at_nodes *= at_nodes
        else:
            at_nodes *= g[s:e] @ y_in
        np.matmul(at_nodes, y_out, out=out[s:e])
    return out


@functools.lru_cache(maxsize=64)
def _sparse_factors(order: int, out_order: int, dtype: str):
    t = triple_tensor(order, out_order)
    off = np.flatnonzero(t.pair_j != t.pair_k)
    arrays = (t.pair_coef.astype(dtype), t.square_coef.astype(dtype), off)
    for a in arrays:
        a.setflags(write=False)
    return t.pair_j, t.pair_k, *arrays


def _sparse_kernel(f, g, order, out_order):
    pj, pk, pair_coef, square_coef, off = _sparse_factors(order, out_order, f.dtype.str)
    out = np.empty((f.shape[0], out_order * out_order), dtype=f.dtype)
    for s in range(0, f.shape[0], SPARSE_CHUNK):
        e = min(f.shape[0], s + SPARSE_CHUNK)
        fc = f[s:e]
        if g is None:
            np.matmul(fc[:, pj] * fc[:, pk], square_coef, out=out[s:e])
        else:
            gc = g[s:e]
            pairs = fc[:, pj] * gc[:, pk]
            pairs[:, off] += fc[:, pk[off]] * gc[:, pj[off]]
            np.matmul(pairs, pair_coef, out=out[s:e])
    return out


#: name -> kernel; "cp" is the default of every product in shtools
PRODUCT_KERNELS: Registry[ProductKernel] = Registry("product kernel")
PRODUCT_KERNELS.register(_cp_kernel, "cp")
PRODUCT_KERNELS.register(_sparse_kernel, "sparse")


def run_product(f: np.ndarray, g: np.ndarray | None, order: int, out_order: int,
                kernel: str = "cp") -> np.ndarray:
    """Products of rows of ``f`` and ``g`` (``g is None``: squares).

    Parameters
    ----------
    f, g : ndarray, shape (B, order**2)
        C-contiguous float32 or float64 arrays of the same dtype.
    order, out_order : int
        Input and output SH orders.
    kernel : str
        A name in :data:`PRODUCT_KERNELS` (module docstring); all are exact.

    Returns
    -------
    ndarray, shape (B, out_order**2)
        May be a transposed view of a coefficient-major array.
    """
    return PRODUCT_KERNELS[kernel](f, g, order, out_order)
