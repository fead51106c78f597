r"""Batched kernels for the SH product and square (used by :mod:`shtools.sh.triple`).

Two exact evaluations of :math:`(\mathbf f * \mathbf g)_i = \sum_{jk}\Gamma_{ijk} f_j g_k`:

*Sparse unrolled kernel* (``kernel="sparse"``): Python source
is generated once per ``(order, out_order, square)`` from the nonzeros of Γ.
Terms are grouped by the unordered input pair ``j <= k`` (one product
``f_j g_k + f_k g_j`` per pair) and, within each output, by equal coefficient
value (Γ has many repeated values, e.g. :math:`\Gamma_{0jj} = 1/\sqrt{4\pi}`),
so each distinct coefficient costs one multiply.  It runs on a
coefficient-major layout ``(n^2, chunk)`` with chunks that fit in cache, so
every generated line is one vectorised NumPy operation over the chunk.

*Quadrature (CP) kernel* (``kernel="cp"``, the default): the exact quadrature of degree
``(n_out - 1) + 2(n - 1)`` factors Γ as :math:`\Gamma_{ijk} = \sum_q w_q
y_i(s_q) y_j(s_q) y_k(s_q)`, a canonical-polyadic decomposition of rank ``Q``,
so the product is three small matrix products: reconstruct ``f`` and ``g`` at
the nodes, multiply, project.  BLAS runs these near peak: in
``benchmarks/bench_sh.py`` runs on the 2-core build machine (65,536 vectors,
one BLAS thread) it was 1.4x (order 4) to 2.4x (order 6) faster than the
sparse kernel in float64, hence the default; both beat a dense contraction
over Γ by more than 10x.
"""

from __future__ import annotations

import functools
from collections import defaultdict

import numpy as np

from shtools.sh.basis import basis
from shtools.sh.quadrature import sphere_quadrature

KERNELS = ("cp", "sparse")

UNROLL_CHUNK = 8192
"""Vectors per chunk of the unrolled kernel (rows of 64 KiB in float64 stay in L2)."""

CP_CHUNK = 4096
"""Vectors per chunk of the quadrature kernel."""

COEF_DIGITS = 15
"""Coefficients equal to this many decimals share one multiply (|Γ| < 1)."""


@functools.lru_cache(maxsize=64)
def _unrolled(order: int, out_order: int, is_square: bool):
    """Compile ``kernel(F, G, O)`` with F, G ``(n^2, b)`` and O ``(n_out^2, b)``."""
    from shtools.sh.triple import triple_tensor

    t = triple_tensor(order, out_order)
    coef = t.square_coef if is_square else t.pair_coef
    lines = ["def kernel(F, G, O):"]
    for p, (j, k) in enumerate(zip(t.pair_j.tolist(), t.pair_k.tolist(), strict=True)):
        if is_square or j == k:
            lines.append(f"    p{p} = F[{j}] * {'F' if is_square else 'G'}[{k}]")
        else:
            lines.append(f"    p{p} = F[{j}] * G[{k}] + F[{k}] * G[{j}]")
    for i in range(out_order * out_order):
        groups: dict[float, list[int]] = defaultdict(list)
        for p in np.nonzero(coef[:, i])[0].tolist():
            groups[round(float(coef[p, i]), COEF_DIGITS)].append(p)
        terms = [f"{c!r} * (" + " + ".join(f"p{p}" for p in ps) + ")"
                 for c, ps in groups.items()]
        lines.append(f"    O[{i}] = " + (" + ".join(terms) if terms else "0.0"))
    namespace: dict = {}
    exec(compile("\n".join(lines), f"<sh-product-{order}-{out_order}-{is_square}>", "exec"),
         namespace)
    return namespace["kernel"]


@functools.lru_cache(maxsize=64)
def _cp_factors(order: int, out_order: int, dtype: str):
    dirs, w = sphere_quadrature((out_order - 1) + 2 * (order - 1))
    y_in = np.ascontiguousarray(basis(dirs, order).T, dtype=dtype)  # (n^2, Q)
    y_out = np.ascontiguousarray(basis(dirs, out_order) * w[:, None], dtype=dtype)  # (Q, n_out^2)
    return y_in, y_out


def run_product(f: np.ndarray, g: np.ndarray | None, order: int, out_order: int,
                kernel: str = "cp") -> np.ndarray:
    """Products of rows of ``f`` and ``g`` (``g is None``: squares).

    Parameters
    ----------
    f, g : ndarray, shape (B, order**2)
        C-contiguous float32 or float64 arrays of the same dtype.
    order, out_order : int
        Input and output SH orders.
    kernel : {"cp", "sparse"}
        Evaluation strategy (module docstring); both are exact.

    Returns
    -------
    ndarray, shape (B, out_order**2)
        May be a transposed view of a coefficient-major array.
    """
    batch = f.shape[0]
    size_out = out_order * out_order
    if kernel not in KERNELS:
        raise ValueError(f"unknown product kernel {kernel!r}; use one of {KERNELS}")
    if kernel == "sparse":
        kernel = _unrolled(order, out_order, g is None)
        out = np.empty((size_out, batch), dtype=f.dtype)
        for s in range(0, batch, UNROLL_CHUNK):
            e = min(batch, s + UNROLL_CHUNK)
            fc = np.ascontiguousarray(f[s:e].T)
            gc = fc if g is None else np.ascontiguousarray(g[s:e].T)
            kernel(fc, gc, out[:, s:e])
        return out.T
    y_in, y_out = _cp_factors(order, out_order, f.dtype.str)
    out = np.empty((batch, size_out), dtype=f.dtype)
    for s in range(0, batch, CP_CHUNK):
        e = min(batch, s + CP_CHUNK)
        at_nodes = f[s:e] @ y_in
        if g is None:
            at_nodes *= at_nodes
        else:
            at_nodes *= g[s:e] @ y_in
        np.matmul(at_nodes, y_out, out=out[s:e])
    return out
