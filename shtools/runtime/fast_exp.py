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


#: Parity classes of the SH coefficients under the two reflections that map the
#: product quadrature onto itself, z -> -z (sign (-1)^(l+m)) and phi -> phi + pi
#: (sign (-1)^m): a = (even, even), b = (odd, even), c = (even, odd), d = (odd, odd).
#: The projection onto class k of f * g collects f_i g_j with i XOR j == k.
_CLASS_PAIRS = tuple(tuple((i, i ^ k) for i in range(4)) for k in range(4))
#: From this order on, products use the 4 parity classes (4x fewer matrix flops
#: for ~4x more elementwise work: 1.3-1.6x faster at order 6, measured in
#: benchmarks/bench_runtime.py); below it the plain full quadrature is faster.
SPLIT_MIN_ORDER = 5


@functools.lru_cache(maxsize=16)
def _split_operators(order: int, dtype_name: str):
    """Class-split quadrature operators of an exact order-``n`` product.

    The Gauss-Legendre x uniform-azimuth rule exact to degree ``3(n-1)`` is
    symmetric under z -> -z and phi -> phi + pi (the azimuth count is made
    even).  Each SH coefficient is even or odd under both, so a function's
    values at the 4 images of a base point (z >= 0, 0 <= phi < pi) are
    ``a +- b +- c +- d`` of the 4 class reconstructions at that point, and a
    product needs reconstructions at a quarter of the nodes only.  A z = 0
    node is its own mirror and is counted twice at half weight (odd classes
    vanish there).  Below :data:`SPLIT_MIN_ORDER` there is one class (all
    coefficients) on the full rule.

    Returns
    -------
    classes : tuple of ndarray of int
        Coefficient indices of each class, ascending (so ascending in band: a
        prefix of each is a lower order).
    recon : tuple of ndarray, shapes (n_k, Qb)
    proj : tuple of ndarray, shapes (Qb, n_k)
        Projection; includes the factor 4 of the images (for the split).
    proj_sq : tuple of ndarray, shapes (Qb, n_k)
        ``proj`` with the factor 2 of the cross terms of a square folded in.
    """
    degree = max(0, 3 * (order - 1))
    if order < SPLIT_MIN_ORDER:
        dirs, w = sphere_quadrature(degree)
        cls = np.zeros(order * order, dtype=np.int64)
        n_classes, sq_factor = 1, (1.0,)
    else:
        n_gauss = degree // 2 + 1
        n_phi = degree + 1 + (degree + 1) % 2  # even: phi + pi is a node
        z, wz = np.polynomial.legendre.leggauss(n_gauss)
        keep = z >= -1e-12
        z, wz = np.abs(z[keep]), wz[keep] * np.where(np.abs(z[keep]) < 1e-12, 0.5, 1.0)
        phi = 2.0 * np.pi * (np.arange(n_phi // 2) + 0.5) / n_phi
        zz, pp = np.meshgrid(z, phi, indexing="ij")
        r = np.sqrt(np.clip(1.0 - zz * zz, 0.0, None))
        dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1).reshape(-1, 3)
        w = np.repeat(wz * (2.0 * np.pi / n_phi), n_phi // 2) * 4.0
        band = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
        m = np.arange(order * order) - band * band - band
        cls = (band + m) % 2 + 2 * (np.abs(m) % 2)
        n_classes, sq_factor = 4, (1.0, 2.0, 2.0, 2.0)
    y = basis(dirs, order)  # (Qb, n*n)
    classes, recon, proj, proj_sq = [], [], [], []
    for k in range(n_classes):
        idx = np.flatnonzero(cls == k)
        yk = y[:, idx]
        mats = (np.ascontiguousarray(yk.T, dtype=dtype_name),
                np.ascontiguousarray(yk * w[:, None], dtype=dtype_name),
                np.ascontiguousarray(yk * (w * sq_factor[k])[:, None], dtype=dtype_name))
        for a in (idx, *mats):
            a.setflags(write=False)
        classes.append(idx)
        recon.append(mats[0])
        proj.append(mats[1])
        proj_sq.append(mats[2])
    return tuple(classes), tuple(recon), tuple(proj), tuple(proj_sq)


class QuadratureProducts:
    """Exact truncated SH products/squares of order-``n`` vectors via quadrature.

    Vectors are handled *split* into the 4 parity classes of
    :func:`_split_operators` (a list of ``(B, n_k)`` arrays) by the ``*_split``
    methods, so chains of products (the exp) split and merge once.

    Parameters
    ----------
    order : int
        SH order ``n`` of inputs and outputs.
    dtype : numpy dtype
        Arithmetic type (float32 for the runtime).
    """

    def __init__(self, order: int, dtype=np.float32):
        self.order = int(order)
        self.dtype = np.dtype(dtype)
        (self.classes, self.recon, self.proj,
         self.proj_sq) = _split_operators(self.order, self.dtype.name)

    def class_sizes(self, out_order: int | None = None) -> list[int]:
        """Coefficients of each class below ``out_order`` (default ``n``)."""
        top = (self.order if out_order is None else out_order) ** 2
        return [int(np.count_nonzero(c < top)) for c in self.classes]

    def split(self, f: np.ndarray, copy: bool = True) -> list[np.ndarray]:
        """``(B, n*n)`` -> contiguous ``(B, n_k)`` class parts (a copy unless
        ``copy=False`` and there is one class)."""
        if len(self.classes) == 1:
            return [np.array(f, dtype=self.dtype, order="C", copy=copy or None)]
        return [np.take(f, c, axis=1) for c in self.classes]

    def merge(self, parts, out_order: int | None = None, out: np.ndarray | None = None
              ) -> np.ndarray:
        """Class parts (possibly truncated to ``out_order``) -> ``(B, out_order^2)``."""
        top = (self.order if out_order is None else out_order) ** 2
        if len(parts) == 1:  # one class: the coefficients in order
            if out is None:
                return parts[0][:, :top] if parts[0].shape[1] == top else parts[0][:, :top].copy()
            out[...] = parts[0][:, :top]
            return out
        if out is None:
            out = np.empty((parts[0].shape[0], top), dtype=parts[0].dtype)
        for c, p in zip(self.classes, parts, strict=True):
            cols = c[c < top]
            out[:, cols] = p[:, : cols.size]
        return out

    def workspace(self, rows: int) -> list[np.ndarray]:
        """Scratch for :meth:`square_values` on up to ``rows`` vectors.

        Reusing it matters: fresh arrays above glibc's mmap threshold (128 KiB)
        are page-faulted on every call, which costs more than the arithmetic.
        """
        q_b = self.recon[0].shape[1]
        return [np.empty((rows, q_b), self.dtype) for _ in range(2 * len(self.recon))]

    def _values(self, parts, ws=None):
        if ws is None:
            return [p @ r for p, r in zip(parts, self.recon, strict=True)]
        rows = parts[0].shape[0]
        return [np.matmul(p, r, out=w[:rows])
                for p, r, w in zip(parts, self.recon, ws, strict=False)]

    def _project(self, vals, rows=slice(None), sizes=None, square=False, out=None):
        mats = self.proj_sq if square else self.proj
        sizes = sizes or [p.shape[1] for p in mats]
        if out is None:
            return [v[rows] @ p[:, :s] for v, p, s in zip(vals, mats, sizes, strict=True)]
        for v, p, s, o in zip(vals, mats, sizes, out, strict=True):
            np.matmul(v[rows], p[:, :s], out=o)
        return out

    def square_values(self, parts, ws=None):
        """Per-class values of ``f^2`` at the base points, to project with ``proj_sq``.

        ``ws`` is an optional :meth:`workspace` (the result lives in it).
        """
        vals = self._values(parts, ws)
        if len(vals) == 1:
            np.multiply(vals[0], vals[0], out=vals[0])
            return vals
        a, b, c, d = vals
        if ws is None:
            vb, vc, vd, tmp = (np.empty_like(a) for _ in range(4))
        else:
            vb, vc, vd, tmp = (w[: a.shape[0]] for w in ws[4:])
        np.multiply(c, d, out=tmp)
        np.multiply(a, b, out=vb)
        vb += tmp
        np.multiply(a, c, out=vc)
        np.multiply(b, d, out=tmp)
        vc += tmp
        np.multiply(a, d, out=vd)
        np.multiply(b, c, out=tmp)
        vd += tmp
        a *= a
        b *= b
        a += b
        c *= c
        a += c
        d *= d
        a += d
        return [a, vb, vc, vd]

    def square_split(self, parts, out_order: int | None = None, ws=None):
        """``f * f`` on class parts (truncated to ``out_order`` when given)."""
        return self._project(self.square_values(parts, ws), square=True,
                             sizes=None if out_order is None else self.class_sizes(out_order))

    def product_split(self, f_parts, g_parts):
        """``f * g`` on class parts."""
        vf = self._values(f_parts)
        vg = self._values(g_parts)
        if len(vf) == 1:
            vf[0] *= vg[0]
            return self._project(vf)
        vals = []
        for pairs in _CLASS_PAIRS:
            acc = np.multiply(vf[pairs[0][0]], vg[pairs[0][1]])
            for i, j in pairs[1:]:
                acc += vf[i] * vg[j]
            vals.append(acc)
        return self._project(vals)

    def square(self, f: np.ndarray) -> np.ndarray:
        """``f * f``, shape ``(B, n*n)``."""
        return self.merge(self.square_split(self.split(f, copy=False)))

    def product(self, f: np.ndarray, g: np.ndarray) -> np.ndarray:
        """``f * g``, shape ``(B, n*n)``."""
        return self.merge(self.product_split(self.split(f, copy=False),
                                             self.split(g, copy=False)))


def fast_exp(f, method: str, tables: dict | None = None, *, degree: int | None = None,
             chunk: int = 4096, threads: int = 1, out_order: int | None = None,
             workspaces: list | None = None) -> np.ndarray:
    """SH exponential of many vectors (``"hyb"``, ``"ps*"``, ``"ol"`` or ``"volterra"``).

    Parameters
    ----------
    f : array_like, shape (B, n*n)
        Log-visibility vectors (float32 stays float32).
    method : {"hyb", "ps*", "ol", "volterra"}
    tables : dict, optional
        OL tables ``ol_norm, ol_a, ol_b`` of order ``n`` (needed for hyb/ol).
    degree : int, optional
        PS*-p series degree (default 2).
    chunk : int
        Vectors per block (bounds memory: the reused scratch is about
        ``chunk * 1 KB`` at order 6).
    threads : int
        Blocks evaluated concurrently (NumPy/BLAS release the GIL).
    out_order : int, optional
        Return only the first ``out_order^2`` coefficients (default ``n``); the
        exp is still computed at order ``n``, but the last squaring projects
        onto the kept coefficients only.
    workspaces : list, optional
        Scratch kept by the caller between calls (one entry per thread, filled
        on first use).  Fresh multi-100-KB scratch is page-faulted on every
        call, which costs a third of the exp of a few thousand vectors.

    Returns
    -------
    ndarray, shape (B, out_order^2)
    """
    f = np.asarray(f)
    dtype = f.dtype if f.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    f = f.astype(dtype, copy=False)
    size = f.shape[-1]
    order = math.isqrt(size)
    n_out = order if out_order is None else int(out_order)
    if not 1 <= n_out <= order:
        raise ValueError(f"out_order must be in 1..{order}, got {out_order!r}")
    if method not in FAST_METHODS:
        raise ValueError(f"fast_exp supports {FAST_METHODS}, got {method!r}")
    if method in ("hyb", "ol") and tables is None:
        raise ValueError("the hyb and ol methods need OL tables")
    p = DEFAULT_PS_STAR_DEGREE if degree is None else int(degree)
    ops = QuadratureProducts(order, dtype)
    out = np.empty((f.shape[0], n_out * n_out), dtype=dtype)
    starts = range(0, f.shape[0], chunk)
    if method == "volterra":
        dirs, w = sphere_quadrature(VOLTERRA_DEGREE[0] * order + VOLTERRA_DEGREE[1])
        y = basis(dirs, order)
        recon = np.ascontiguousarray(y.T, dtype=dtype)
        proj = np.ascontiguousarray(y[:, : n_out * n_out] * w[:, None], dtype=dtype)
        for s in starts:
            v = f[s : s + chunk] @ recon
            np.exp(v, out=v)
            out[s : s + chunk] = v @ proj
        return out

    n_workers = max(1, min(int(threads), len(starts)))
    spaces = _workspaces(ops, min(chunk, f.shape[0]), n_workers,
                         [] if workspaces is None else workspaces)

    def work(k):
        for s in starts[k::n_workers]:
            _exp_block(f[s : s + chunk], method, tables, p, ops, n_out, out[s : s + chunk],
                       spaces[k])

    if n_workers > 1:
        with ThreadPoolExecutor(max_workers=n_workers) as pool:
            list(pool.map(work, range(n_workers)))
    else:
        work(0)
    return out


def _workspaces(ops: QuadratureProducts, rows: int, count: int, kept: list) -> list:
    """``count`` workspaces of at least ``rows`` rows for ``ops``, reusing ``kept``
    (which is updated in place) when the shapes fit."""
    q_b, n_arrays = ops.recon[0].shape[1], 2 * len(ops.recon)
    for k in range(count):
        fits = (k < len(kept) and len(kept[k]) == n_arrays and kept[k][0].shape[0] >= rows
                and kept[k][0].shape[1] == q_b and kept[k][0].dtype == ops.dtype)
        if not fits:
            space = ops.workspace(rows)
            if k < len(kept):
                kept[k] = space
            else:
                kept.append(space)
    return kept[:count]


def _ol_split(parts, norm: np.ndarray, tables: dict):
    """OL (Sec. 4.2) on class parts of ``f_hat``: ``a(|f|) * 1 + b(|f|) * f_hat``."""
    a = np.interp(norm, tables["ol_norm"], tables["ol_a"])
    b = np.interp(norm, tables["ol_norm"], tables["ol_b"])
    out = [p * b[:, None].astype(p.dtype) for p in parts]
    out[0][:, 0] = a * SQRT_4PI
    return out


def _factored_series(parts, degree: int, ops: QuadratureProducts, ws=None):
    """Eq. 22 for exp on class parts: even part plus ``f *`` odd part (as
    :mod:`shtools.sh.exponential`)."""
    coef = [1.0 / math.factorial(k) for k in range(degree + 1)]
    even = [np.zeros_like(p) for p in parts]
    even[0][:, 0] = SQRT_4PI * coef[0]
    odd = [np.zeros_like(p) for p in parts]
    odd[0][:, 0] = SQRT_4PI * coef[1]
    f2 = ops.square_split(parts, ws=ws) if degree >= 2 else None
    power = f2
    for k in range(1, degree // 2 + 1):
        if k > 1:
            power = ops.product_split(power, f2)
        for e, o, pw in zip(even, odd, power, strict=True):
            e += coef[2 * k] * pw
            if 2 * k + 1 <= degree:
                o += coef[2 * k + 1] * pw
    if degree <= 2:  # the odd part is h_1 * 1, and f * 1 = f exactly
        for e, p in zip(even, parts, strict=True):
            e += coef[1] * p
        return even
    return [e + x for e, x in zip(even, ops.product_split(parts, odd), strict=True)]


def _exp_block(f, method, tables, degree, ops: QuadratureProducts, n_out: int, out,
               ws=None) -> None:
    """exp of ``f (B, n*n)`` truncated to ``n_out``, written into ``out (B, n_out^2)``.

    ``ws`` is a :meth:`QuadratureProducts.workspace` of at least ``B`` rows.
    """
    dc = np.exp(f[:, 0].astype(np.float64) / SQRT_4PI)
    parts = ops.split(f)
    parts[0][:, 0] = 0.0  # f_hat: DC isolated
    norm = np.sqrt(sum(np.einsum("bi,bi->b", p, p, dtype=np.float64) for p in parts))
    if method == "ol":
        ops.merge(_ol_split(parts, norm, tables), n_out, out=out)
        out *= dc[:, None].astype(out.dtype)
        return
    # vectors sorted by norm (descending), so those still needing a square at
    # each step are a prefix, squared in place without gathers; f_hat = 0 rows
    # (no blocker in view) come last and are exactly exp(dc)
    q = squarings(norm)
    key = np.where(norm > 0, q + 1, 0)  # small ints: a fast radix argsort
    by_norm = np.argsort(-key, kind="stable")
    live = int(np.count_nonzero(key))
    q_sorted = q[by_norm[:live]]
    norm_sorted = norm[by_norm[:live]]
    scale = np.ldexp(1.0, -q_sorted)
    scaled = [p[by_norm[:live]] * scale[:, None].astype(p.dtype) for p in parts]
    if method == "hyb":
        g = _ol_split(scaled, norm_sorted * scale, tables)
    else:
        g = _factored_series(scaled, degree, ops, ws)
    res = np.empty((f.shape[0], n_out * n_out), dtype=out.dtype)
    res[live:] = 0.0
    res[live:, 0] = SQRT_4PI
    q_max = int(q_sorted.max(initial=0))
    done = int(np.count_nonzero(q_sorted > 0))
    ops.merge([p[done:] for p in g], n_out, out=res[done:live])
    sizes = ops.class_sizes(n_out)
    for step in range(q_max):
        count = done
        done = int(np.count_nonzero(q_sorted > step + 1))
        # rows [done, count) take their last square: project onto the kept
        # coefficients only; rows [0, done) keep squaring at full order
        vals = ops.square_values([p[:count] for p in g], ws)
        ops.merge(ops._project(vals, slice(done, count), sizes, square=True), n_out,
                  out=res[done:count])
        if done:
            ops._project(vals, slice(0, done), square=True, out=[p[:done] for p in g])
    out[by_norm] = res
    out *= dc[:, None].astype(out.dtype)
