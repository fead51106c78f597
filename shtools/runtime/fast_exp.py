r"""The runtime's product backend: quadrature SH products in float32 on BLAS.

Every truncated SH product :math:`(\mathbf f * \mathbf g)_i = \int f g\, y_i` is
evaluated as two small matrix products through a quadrature that integrates
the degree :math:`3(n-1)` integrand exactly: reconstruct ``f`` and ``g`` at the
``Q`` directions, multiply pointwise, project back.  Up to order 6 the rule is
the one with the fewest nodes known here (Lebedev's for orders 4-6); at orders 5
and 6 the products are split by the parity of the band ``l`` over half of it (one
node of each antipodal pair); from order 7 on, by two parities over a quarter of
a product Gauss rule.
For tens of thousands of vectors this runs on BLAS in float32 and is far faster
than contracting the sparse triple-product tensor.

:class:`QuadratureProducts` is a :class:`shtools.sh.exponential.ProductBackend`;
:func:`fast_exp` runs the one exp driver of :mod:`shtools.sh.exponential`
(:func:`~shtools.sh.exponential.exp_batched`) on it, and the Volterra
exponential with a lighter quadrature.  Tests check it against
:func:`shtools.sh.exp`.
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np

from shtools.sh import basis
from shtools.sh.exponential import SQUARING_MARGIN, exp_batched, volterra
from shtools.sh.quadrature import quarter_sphere_quadrature, sphere_quadrature

#: Methods implemented here; others fall back to :func:`shtools.sh.exp`.
FAST_METHODS = ("hyb", "ps*", "ol", "volterra")
#: Quadrature degree of the fast Volterra exp as a multiple of the order: exp of a
#: log-visibility reconstruction is smooth, and 4n + 6 keeps the projection within
#: 1e-4 of :func:`shtools.sh.exp`'s denser rule (tests/runtime/test_fast_exp.py).
VOLTERRA_DEGREE = (4, 6)


#: Parity classes of the SH coefficients under the two reflections that map the
#: product quadrature onto itself, z -> -z (sign (-1)^(l+m)) and phi -> phi + pi
#: (sign (-1)^m): a = (even, even), b = (odd, even), c = (even, odd), d = (odd, odd).
#: The projection onto class k of f * g collects f_i g_j with i XOR j == k (the
#: same with the 2 classes of :data:`HALF_ORDERS`, even and odd l), keyed by the
#: number of classes.
_CLASS_PAIRS = {c: tuple(tuple((i, i ^ k) for i in range(c)) for k in range(c)) for c in (2, 4)}
#: From this order on, products use the 4 parity classes (4x fewer matrix flops
#: for ~4x more elementwise work).  Up to order 6 the 4-class split is slower: its
#: sixteen elementwise passes per square are bound by memory traffic (on the
#: Lebedev rule of order 6, 0.27 ms a square of 2,048 vectors, the 2 classes of
#: :data:`HALF_ORDERS` 0.19 ms).
SPLIT_MIN_ORDER = 7
#: Orders whose products split in 2 classes by the parity under s -> -s (sign
#: (-1)^l) over half of the (centrally symmetric) Lebedev rule: a function's values
#: at s and -s are a +- b of the even-l and odd-l reconstructions at s, so the
#: matrix products shrink by half for 3 elementwise passes more per square (the
#: inversion fixes no node, so both classes use all half nodes).  Measured on
#: order 6 squares of 2,048 vectors, one BLAS thread: 0.19 ms (parts padded by
#: :func:`padded_width`) against 0.27 ms on the full rule.
HALF_ORDERS = (5, 6)


#: Lebedev rules (V. I. Lebedev and D. N. Laikov, "A quadrature formula for the
#: sphere of the 131st algebraic order of accuracy", Doklady Mathematics 59, 1999)
#: by degree of exactness: orbits as (generator, weight), each orbit every signed
#: permutation of its generator; weights sum to 4 pi.  Exact to the same degree
#: with fewer nodes than the product Gauss rule (38 vs 50, 86 vs 128), so the
#: products of orders 4 and 6 cost that much fewer flops.
_LEBEDEV = {
    9: (((1.0, 0.0, 0.0), 0.11967972013675403),
        ((0.5773502691896257, 0.5773502691896257, 0.5773502691896257), 0.4039190554615448),
        ((0.8880738339771153, 0.4597008433809831, 0.0), 0.35903916041026207)),
    15: (((1.0, 0.0, 0.0), 0.14506632743848968),
         ((0.5773502691896257, 0.5773502691896257, 0.5773502691896257),
          0.15009158815708187),
         ((0.6943540066026664, 0.6943540066026664, 0.18906355288539498),
          0.1492445168690702),
         ((0.8525183117012676, 0.3696028464541502, 0.3696028464541502),
          0.13961936079092707),
         ((0.9273306571511725, 0.3742430390903412, 0.0), 0.1484377866929852)),
}


def lebedev_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes ``(Q, 3)`` and weights ``(Q,)`` of the Lebedev rule exact to ``degree``
    (one of :data:`_LEBEDEV`), nodes in a fixed order."""
    dirs, weights = [], []
    for generator, weight in _LEBEDEV[degree]:
        points = set()
        for perm in itertools.permutations(generator):
            for signs in itertools.product((1.0, -1.0), repeat=3):
                points.add(tuple(sg * c if c else 0.0 for sg, c in zip(signs, perm,
                                                                       strict=True)))
        dirs.extend(sorted(points))
        weights.extend([weight] * len(points))
    return np.array(dirs), np.array(weights)


def _product_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """The fewest-node rule exact to ``degree`` that this module knows."""
    rules = [sphere_quadrature(degree)]
    rules += [lebedev_rule(d) for d in _LEBEDEV if d >= degree]
    return min(rules, key=lambda rule: rule[1].shape[0])  # the first of equal sizes


def half_rule(dirs: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One node of each antipodal pair ``(s, -s)`` of a centrally symmetric rule
    (the one whose first nonzero coordinate is positive), shapes ``(Q/2, 3)`` and
    ``(Q/2,)``; weights doubled, so ``sum_q w_q g(s_q)`` integrates an even ``g``
    (``g(-s) = g(s)``) exactly."""
    lead = np.where(dirs[:, 0] != 0, dirs[:, 0], np.where(dirs[:, 1] != 0, dirs[:, 1],
                                                          dirs[:, 2]))
    keep = lead > 0
    mirror = np.argmin(np.linalg.norm(dirs[keep][:, None] + dirs[None], axis=2), axis=1)
    if (2 * np.count_nonzero(keep) != len(weights)
            or not np.allclose(dirs[mirror], -dirs[keep], atol=1e-12)
            or not np.allclose(weights[mirror], weights[keep], rtol=1e-12)):
        raise ValueError("the rule is not centrally symmetric")
    return dirs[keep], 2.0 * weights[keep]


def padded_width(columns: int) -> int:
    """``columns`` rounded up to a multiple of 8 when that adds at most half as many.

    OpenBLAS's float32 kernels run a product with a multiple of 8 output columns
    much faster: ``(2048, 43) @ (43, n)`` took 46 us at n = 15 and 32 us at 16,
    51 us at 21 and 44 us at 24, 28 us at 6 and 20 us at 8, but 28 us at 10 and
    32 us at 16 (one BLAS thread).
    """
    up = -(-columns // 8) * 8
    return up if 2 * (up - columns) <= columns else columns


@functools.lru_cache(maxsize=16)
def _split_operators(order: int, dtype_name: str):
    """Class-split quadrature operators of an exact order-``n`` product.

    The rule exact to degree ``3(n-1)`` is symmetric under z -> -z and
    phi -> phi + pi (:func:`shtools.sh.quadrature.quarter_sphere_quadrature`).
    Each SH coefficient is even or odd under both, so a function's values at
    the 4 images of a base point are ``a +- b +- c +- d`` of the 4 class
    reconstructions at that point, and a product needs reconstructions at a
    quarter of the nodes only (odd classes vanish at z = 0).  At
    :data:`HALF_ORDERS` there are 2 classes (even and odd band ``l``) on
    :func:`half_rule` of the fewest-node rule exact to that degree
    (:func:`_product_rule`); at the other orders below :data:`SPLIT_MIN_ORDER`,
    one class (all coefficients) on that rule.

    Returns
    -------
    classes : tuple of ndarray of int
        Coefficient indices of each class, ascending (so ascending in band: a
        prefix of each is a lower order).
    recon : tuple of ndarray, shapes (n_k, Qb)
    proj : tuple of ndarray, shapes (Qb, w_k)
        Projection; includes the factor 4 of the images (for the split).  Its
        columns beyond ``n_k`` (up to :func:`padded_width` for the 2 classes) are 0.
    proj_sq : tuple of ndarray, shapes (Qb, w_k)
        ``proj`` with the factor 2 of the cross terms of a square folded in.
    """
    degree = max(0, 3 * (order - 1))
    band = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    m = np.arange(order * order) - band * band - band
    if order >= SPLIT_MIN_ORDER:
        dirs, w = quarter_sphere_quadrature(degree)
        cls = (band + m) % 2 + 2 * (np.abs(m) % 2)
        n_classes, sq_factor = 4, (1.0, 2.0, 2.0, 2.0)
    elif order in HALF_ORDERS:
        dirs, w = half_rule(*_product_rule(degree))
        cls = band % 2
        n_classes, sq_factor = 2, (1.0, 2.0)
    else:
        dirs, w = _product_rule(degree)
        cls = np.zeros(order * order, dtype=np.int64)
        n_classes, sq_factor = 1, (1.0,)
    y = basis(dirs, order)  # (Qb, n*n)
    classes, recon, proj, proj_sq = [], [], [], []
    for k in range(n_classes):
        idx = np.flatnonzero(cls == k)
        yk = y[:, idx]
        # the half split's parts carry zero columns up to padded_width (BLAS speed)
        cols = padded_width(idx.size) if n_classes == 2 else idx.size
        yp = np.zeros((len(w), cols))
        yp[:, : idx.size] = yk
        mats = (np.ascontiguousarray(yk.T, dtype=dtype_name),
                np.ascontiguousarray(yp * w[:, None], dtype=dtype_name),
                np.ascontiguousarray(yp * (w * sq_factor[k])[:, None], dtype=dtype_name))
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
    :func:`_split_operators` (a list of ``(B, w_k)`` arrays) by the ``*_split``
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
        """Columns of each class part truncated to ``out_order`` (default ``n``): its
        coefficients below that order, then zero or higher-order columns up to
        :func:`padded_width` (at most the part's width)."""
        top = (self.order if out_order is None else out_order) ** 2
        counts = [int(np.count_nonzero(c < top)) for c in self.classes]
        if len(self.classes) != 2:
            return counts
        return [min(padded_width(k), p.shape[1]) for k, p in zip(counts, self.proj,
                                                                   strict=True)]

    def split(self, f: np.ndarray, copy: bool = True) -> list[np.ndarray]:
        """``(B, n*n)`` -> contiguous ``(B, w_k)`` class parts (a copy unless
        ``copy=False`` and there is one class; the 2 classes padded with zero
        columns to :func:`padded_width`)."""
        if len(self.classes) == 1:
            return [np.array(f, dtype=self.dtype, order="C", copy=copy or None)]
        if len(self.classes) == 4:
            return [np.take(f, c, axis=1) for c in self.classes]
        parts = []
        for c, p in zip(self.classes, self.proj, strict=True):
            part = np.zeros((f.shape[0], p.shape[1]), dtype=self.dtype)
            part[:, : c.size] = f[:, c]
            parts.append(part)
        return parts

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
        return [np.empty((rows, r.shape[1]), self.dtype) for r in self.recon * 2]

    def workspace_layout(self) -> tuple[int, int]:
        """``(arrays, columns)`` of a :meth:`workspace`."""
        return 2 * len(self.recon), self.recon[0].shape[1]

    def project_square(self, vals, rows=slice(None), out_order: int | None = None, out=None):
        """Class parts of ``f * f`` for ``rows`` of :meth:`square_values` (truncated to
        ``out_order`` when given; into ``out`` when given)."""
        sizes = None if out_order is None else self.class_sizes(out_order)
        return self._project(vals, rows, sizes, square=True, out=out)

    def _values(self, parts, ws=None):
        if ws is None:  # (the padding columns of a part are not read)
            return [row_matmul(p[:, : r.shape[0]], r)
                    for p, r in zip(parts, self.recon, strict=True)]
        rows = parts[0].shape[0]
        return [row_matmul(p[:, : r.shape[0]], r, out=w[:rows])
                for p, r, w in zip(parts, self.recon, ws, strict=False)]

    def _project(self, vals, rows=slice(None), sizes=None, square=False, out=None):
        mats = self.proj_sq if square else self.proj
        sizes = sizes or [p.shape[1] for p in mats]
        if out is None:
            return [row_matmul(v[rows], p[:, :s])
                    for v, p, s in zip(vals, mats, sizes, strict=True)]
        for v, p, s, o in zip(vals, mats, sizes, out, strict=True):
            row_matmul(v[rows], p[:, :s], out=o)
        return out

    def square_values(self, parts, ws=None):
        """Per-class values of ``f^2`` at the base points, to project with ``proj_sq``.

        ``ws`` is an optional :meth:`workspace` (the result lives in it).
        """
        vals = self._values(parts, ws)
        if len(vals) == 1:
            np.multiply(vals[0], vals[0], out=vals[0])
            return vals
        if len(vals) == 2:  # values a +- b at the two images of a base point
            a, b = vals
            vb = np.empty_like(b) if ws is None else ws[3][: a.shape[0]]
            np.multiply(a, b, out=vb)
            a *= a
            b *= b
            a += b
            return [a, vb]
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
        for pairs in _CLASS_PAIRS[len(vf)]:
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


#: Rows per matrix product, and the multiple a product's rows are padded to with
#: zero rows.  BLAS libraries run products of other shapes on other kernels
#: (OpenBLAS's small-matrix path, its matrix-vector path for one row, edge kernels
#: for a ragged row count), and some kernels sum a row in another order by its
#: place in the block (OpenBLAS's AVX-512 SGEMM on AMD Zen rows 6-11 of every 12),
#: so a vector's product changes in its last bits with the rows beside it.
#: :func:`row_matmul` multiplies in blocks of 256 rows from the first: a row taken
#: in the same block at the same place gives the same bytes, which is what a cache
#: that refreshes whole blocks (:mod:`shtools.runtime.shading_cache`) relies on.
PRODUCT_BLOCK_ROWS = 256
PRODUCT_ROW_MULTIPLE = 8


def row_matmul(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``a @ b`` (into ``out``) in blocks of :data:`PRODUCT_BLOCK_ROWS` rows.

    Rows ``k * PRODUCT_BLOCK_ROWS`` to ``(k + 1) * PRODUCT_BLOCK_ROWS`` of ``a`` give
    the same bytes whatever follows them; a ragged last block is cut at a multiple
    of :data:`PRODUCT_ROW_MULTIPLE` and its rest padded to one.
    """
    rows = a.shape[0]
    if out is None:
        out = np.empty((rows, b.shape[1]), dtype=np.result_type(a, b))
    full = rows - rows % PRODUCT_BLOCK_ROWS
    if full:  # one call: NumPy runs one BLAS product per block of the stack
        np.matmul(a[:full].reshape(-1, PRODUCT_BLOCK_ROWS, a.shape[1]), b,
                  out=out[:full].reshape(-1, PRODUCT_BLOCK_ROWS, b.shape[1]))
    whole = rows - rows % PRODUCT_ROW_MULTIPLE
    if whole > full:
        np.matmul(a[full:whole], b, out=out[full:whole])
    if whole < rows:
        padded = np.zeros((PRODUCT_ROW_MULTIPLE, a.shape[1]), dtype=a.dtype)
        padded[:rows - whole] = a[whole:]
        out[whole:] = (padded @ b)[:rows - whole]
    return out


#: Vectors per block of :func:`fast_exp`: rows are sorted by their squaring count
#: within a block, so a larger block squares longer runs of rows at a time, until
#: its scratch outgrows the caches (the battle frame's exp of ``bench_runtime``, one
#: BLAS thread: 37 / 32 / 29 / 32 ms at 1024 / 2048 / 4096 / 8192).
EXP_CHUNK = 4096


def fast_exp(f, method: str, tables: dict | None = None, *, degree: int | None = None,
             chunk: int = EXP_CHUNK, threads: int = 1, out_order: int | None = None,
             workspaces: list | None = None, margin: int = SQUARING_MARGIN) -> np.ndarray:
    """SH exponential of many vectors (``"hyb"``, ``"ps*"``, ``"ol"`` or ``"volterra"``).

    The driver of :func:`shtools.sh.exponential.exp_batched` on
    :class:`QuadratureProducts` (Volterra: :func:`shtools.sh.exponential.volterra`
    with a quadrature of degree ``4n + 6``).

    Parameters
    ----------
    f : array_like, shape (B, n*n)
        Log-visibility vectors (float32 stays float32).
    method : {"hyb", "ps*", "ol", "volterra"}
    tables : dict, optional
        OL tables ``ol_norm, ol_a, ol_b`` of order ``n`` (needed for hyb/ol).
    degree : int, optional
        PS*-p series degree (default :data:`shtools.sh.exponential.DEFAULT_DEGREE`).
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
    margin : int
        Squaring-count margin of PS* and HYB
        (:func:`shtools.sh.exponential.squarings`).

    Returns
    -------
    ndarray, shape (B, out_order^2)
    """
    f = np.asarray(f)
    dtype = f.dtype if f.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    f = f.astype(dtype, copy=False)
    order = math.isqrt(f.shape[-1])
    if method not in FAST_METHODS:
        raise ValueError(f"fast_exp supports {FAST_METHODS}, got {method!r}")
    if method == "volterra":
        n_out = order if out_order is None else int(out_order)
        if not 1 <= n_out <= order:
            raise ValueError(f"out_order must be in 1..{order}, got {out_order!r}")
        return volterra(f, VOLTERRA_DEGREE[0] * order + VOLTERRA_DEGREE[1], out_order=n_out,
                        chunk=chunk)
    return exp_batched(f, method, QuadratureProducts(order, dtype), tables, degree=degree,
                       chunk=chunk, threads=threads, out_order=out_order,
                       workspaces=workspaces, margin=margin)
