r"""Batched SH exponentials for the runtime, with products by exact quadrature.

Same algorithms and definitions as :func:`shtools.sh.exp` (Sec. 4: DC isolation,
scaling/squaring with :math:`q = \max(0, \lfloor\log_2\|\hat f\|\rfloor + 3)`,
the factored PS*-p series, OL and HYB), but every truncated SH product
:math:`(\mathbf f * \mathbf g)_i = \int f g\, y_i` is evaluated as two small
matrix products through a quadrature that integrates the degree
:math:`3(n-1)` integrand exactly: reconstruct ``f`` and ``g`` at the ``Q``
directions, multiply pointwise, project back.  For tens of thousands of
vectors this runs on BLAS in float32 and is far faster than contracting the
sparse triple-product tensor.  Tests check it against :func:`shtools.sh.exp`.
"""

from __future__ import annotations

import functools
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from shtools.sh import basis, sphere_quadrature, squarings

SQRT_4PI = math.sqrt(4.0 * math.pi)
#: Methods implemented here; others fall back to :func:`shtools.sh.exp`.
FAST_METHODS = ("hyb", "ps*", "ol", "volterra")
#: Quadrature degree of the fast Volterra exp as a multiple of the order: exp of a
#: log-visibility reconstruction is smooth, and 4n + 6 keeps the projection within
#: 1e-4 of :func:`shtools.sh.exp`'s denser rule (tests/runtime/test_fast_exp.py).
VOLTERRA_DEGREE = (4, 6)
#: Default PS*-p degree (as :data:`shtools.sh.exponential.DEFAULT_DEGREE`).
DEFAULT_PS_STAR_DEGREE = 2


@functools.lru_cache(maxsize=16)
def _product_operators(order: int, dtype_name: str) -> tuple[np.ndarray, np.ndarray]:
    """``recon (n*n, Q)`` and ``proj (Q, n*n)`` of an exact-product quadrature."""
    dirs, w = sphere_quadrature(max(0, 3 * (order - 1)))
    y = basis(dirs, order)  # (Q, n*n)
    recon = np.ascontiguousarray(y.T, dtype=dtype_name)
    proj = np.ascontiguousarray(y * w[:, None], dtype=dtype_name)
    recon.setflags(write=False)
    proj.setflags(write=False)
    return recon, proj


class QuadratureProducts:
    """Exact truncated SH products/squares of order-``n`` vectors via quadrature.

    Parameters
    ----------
    order : int
        SH order ``n`` of inputs and outputs.
    dtype : numpy dtype
        Arithmetic type (float32 for the runtime).
    """

    def __init__(self, order: int, dtype=np.float32):
        self.order = int(order)
        self.recon, self.proj = _product_operators(self.order, np.dtype(dtype).name)

    def square(self, f: np.ndarray) -> np.ndarray:
        """``f * f``, shape ``(B, n*n)``."""
        v = f @ self.recon
        np.multiply(v, v, out=v)
        return v @ self.proj

    def product(self, f: np.ndarray, g: np.ndarray) -> np.ndarray:
        """``f * g``, shape ``(B, n*n)``."""
        v = f @ self.recon
        v *= g @ self.recon
        return v @ self.proj


def fast_exp(f, method: str, tables: dict | None = None, *, degree: int | None = None,
             chunk: int = 8192, threads: int = 1) -> np.ndarray:
    """SH exponential of many vectors (``"hyb"``, ``"ps*"`` or ``"ol"``).

    Parameters
    ----------
    f : array_like, shape (B, n*n)
        Log-visibility vectors (float32 stays float32).
    method : {"hyb", "ps*", "ol"}
    tables : dict, optional
        OL tables ``ol_norm, ol_a, ol_b`` of order ``n`` (needed for hyb/ol).
    degree : int, optional
        PS*-p series degree (default 2).
    chunk : int
        Vectors per block (bounds memory).
    threads : int
        Blocks evaluated concurrently (NumPy/BLAS release the GIL).

    Returns
    -------
    ndarray, shape (B, n*n)
    """
    f = np.asarray(f)
    dtype = f.dtype if f.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    f = f.astype(dtype, copy=False)
    size = f.shape[-1]
    order = math.isqrt(size)
    if method not in FAST_METHODS:
        raise ValueError(f"fast_exp supports {FAST_METHODS}, got {method!r}")
    if method in ("hyb", "ol") and tables is None:
        raise ValueError("the hyb and ol methods need OL tables")
    p = DEFAULT_PS_STAR_DEGREE if degree is None else int(degree)
    ops = QuadratureProducts(order, dtype)
    out = np.empty_like(f)
    starts = range(0, f.shape[0], chunk)
    if method != "volterra" and threads > 1 and len(starts) > 1:
        def work(s):
            out[s : s + chunk] = _exp_block(f[s : s + chunk], method, tables, p, ops)

        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(work, starts))
        return out
    if method == "volterra":
        dirs, w = sphere_quadrature(VOLTERRA_DEGREE[0] * order + VOLTERRA_DEGREE[1])
        y = basis(dirs, order)
        recon = np.ascontiguousarray(y.T, dtype=dtype)
        proj = np.ascontiguousarray(y * w[:, None], dtype=dtype)
        for s in range(0, f.shape[0], chunk):
            v = f[s : s + chunk] @ recon
            np.exp(v, out=v)
            out[s : s + chunk] = v @ proj
        return out
    for s in range(0, f.shape[0], chunk):
        out[s : s + chunk] = _exp_block(f[s : s + chunk], method, tables, p, ops)
    return out


def _ol(f_hat: np.ndarray, norm: np.ndarray, tables: dict) -> np.ndarray:
    a = np.interp(norm, tables["ol_norm"], tables["ol_a"])
    b = np.interp(norm, tables["ol_norm"], tables["ol_b"])
    g = f_hat * b[:, None].astype(f_hat.dtype)
    g[:, 0] = a * SQRT_4PI
    return g


def _factored_series(f: np.ndarray, degree: int, ops: QuadratureProducts) -> np.ndarray:
    """Eq. 22 for exp: even part plus ``f *`` odd part (as :mod:`shtools.sh.exponential`)."""
    coef = [1.0 / math.factorial(k) for k in range(degree + 1)]
    even = np.zeros_like(f)
    even[:, 0] = SQRT_4PI * coef[0]
    odd = np.zeros_like(f)
    odd[:, 0] = SQRT_4PI * coef[1]
    f2 = ops.square(f) if degree >= 2 else None
    power = f2
    for k in range(1, degree // 2 + 1):
        if k > 1:
            power = ops.product(power, f2)
        even += coef[2 * k] * power
        if 2 * k + 1 <= degree:
            odd += coef[2 * k + 1] * power
    if degree <= 2:  # the odd part is h_1 * 1, and f * 1 = f exactly
        return even + coef[1] * f
    return even + ops.product(f, odd)


def _exp_block(f, method, tables, degree, ops: QuadratureProducts) -> np.ndarray:
    dc = np.exp(f[:, 0].astype(np.float64) / SQRT_4PI)
    f_hat = f.copy()
    f_hat[:, 0] = 0.0
    norm = np.sqrt(np.einsum("bi,bi->b", f_hat, f_hat, dtype=np.float64))
    if method == "ol":
        g = _ol(f_hat, norm, tables)
    else:
        q = squarings(norm)
        # vectors sorted by squaring count (descending): those still needing a
        # square at each step are a prefix, squared in place without gathers
        by_q = np.argsort(-q, kind="stable")
        q_sorted = q[by_q]
        scale = np.ldexp(1.0, -q_sorted)
        scaled = f_hat[by_q] * scale[:, None].astype(f.dtype)
        if method == "hyb":
            g = _ol(scaled, norm[by_q] * scale, tables)
        else:
            g = _factored_series(scaled, degree, ops)
        for step in range(int(q.max(initial=0))):
            count = int(np.count_nonzero(q_sorted > step))
            g[:count] = ops.square(g[:count])
        unsorted = np.empty_like(g)
        unsorted[by_q] = g
        g = unsorted
    g *= dc[:, None].astype(g.dtype)
    return g
