"""The generated unrolled sparse product kernel (moved out of the library: ``exec``).

Python source is generated once per ``(order, out_order, square)`` from the
nonzeros of Γ.  Terms are grouped by the unordered input pair ``j <= k`` (one
product ``f_j g_k + f_k g_j`` per pair) and, within each output, by equal
coefficient value (Γ has many repeated values, e.g. ``Γ_0jj = 1/sqrt(4 pi)``),
so each distinct coefficient costs one multiply.  It runs on a
coefficient-major layout ``(n^2, chunk)`` with chunks that fit in cache, so
every generated line is one vectorised NumPy operation over the chunk.  This is
how product-space methods classically evaluate the tensor (Snyder 2006 code
generation); the benchmarks compare the log-space runtime against it.
Importing this module registers it as the product kernel ``"unrolled"``.
"""

from __future__ import annotations

import functools
from collections import defaultdict

import numpy as np

from shtools.sh._kernels import PRODUCT_KERNELS

UNROLL_CHUNK = 8192
"""Vectors per chunk of the unrolled kernel (rows of 64 KiB in float64 stay in L2)."""

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


def unrolled_kernel(f, g, order, out_order):
    """Products (``g is None``: squares) of rows by the generated kernel, ``(B, n_out^2)``."""
    kernel = _unrolled(order, out_order, g is None)
    batch = f.shape[0]
    out = np.empty((out_order * out_order, batch), dtype=f.dtype)
    for s in range(0, batch, UNROLL_CHUNK):
        e = min(batch, s + UNROLL_CHUNK)
        fc = np.ascontiguousarray(f[s:e].T)
        gc = fc if g is None else np.ascontiguousarray(g[s:e].T)
        kernel(fc, gc, out[:, s:e])
    return out.T


PRODUCT_KERNELS.register(unrolled_kernel, "unrolled")
