r"""SH exponential (Sec. 4): PS, PS*, OL, HYB and two references.

Methods (``f`` an SH vector, ``1 = (sqrt(4 pi), 0, ...)``, ``*`` the truncated
SH product of :mod:`shtools.sh.triple`):

``"ps"`` — PS-p, the product series (eq. 17) of degree ``p`` accumulated left to
right, :math:`f^{(k+1)*} = f^{k*} * f`.

``"ps*"`` — PS*-p: DC isolation (eqs. 19–20), scaling/squaring (eq. 21) with
:math:`q = \max(0, \lfloor\log_2\|\hat f\|\rfloor + c)` squarings (the paper's
margin :math:`c = 3` by default), and the
factored series of degree ``p`` (eq. 22), even powers built as
:math:`f^{2*}=f*f`, :math:`f^{2k*} = f^{(2k-2)*} * f^{2*}`.

``"ol"`` — optimal linear approximation (eq. 23): DC isolation, then
:math:`a(\|\hat f\|)\mathbf 1 + b(\|\hat f\|)\hat f` with the tables ``ol_norm,
ol_a, ol_b`` of :mod:`shtools.sh.tables` (eq. 24), linearly interpolated and
clamped at the table ends.

``"hyb"`` — HYB: DC isolation, scaling by :math:`2^q` with the same rule for
``q`` as PS*, OL on the scaled vector, then ``q`` squarings.

``"exact"`` — the infinite product series :math:`\exp_*` evaluated by
diagonalising the product matrix (eq. 28):
:math:`\mathbf 1 + R_f^T q(D_f) R_f \mathbf f`, :math:`q(x) = (e^x - 1)/x`.

``"volterra"`` — the Volterra exponential (eq. 10),
:math:`\int_S \exp(f(s))\,\mathbf y(s)\,ds` by quadrature.

PS*, OL and HYB run on **one driver**, :func:`exp_batched`, which takes a
*product backend* (:class:`ProductBackend`): :class:`TensorProducts` here (the
triple-tensor products of :mod:`shtools.sh.triple`, by the exact quadrature
factors of Γ or another registered kernel) or the runtime's parity-split
float32 quadrature (:class:`shtools.runtime.fast_exp.QuadratureProducts`).
The number of squarings differs between vectors of a batch; rows are sorted
by it and squared in at most ``max(q)`` passes over the prefix that still needs
one, so no Python loop runs per vector.  ``acc_order`` accumulates the series
products and squarings at a higher order and truncates only the result
(Sec. 4: "errors ... can be further reduced by accumulating products at higher
order").
"""

from __future__ import annotations

import functools
import math
from concurrent.futures import ThreadPoolExecutor
from enum import StrEnum
from typing import Protocol

import numpy as np

from shtools.blend import smoothstep
from shtools.sh._kernels import run_product
from shtools.sh.basis import SQRT_4PI, basis, check_order, order_from_size
from shtools.sh.quadrature import sphere_quadrature
from shtools.sh.triple import CHUNK_BYTES, _pad, product, product_matrix


class ExpMethod(StrEnum):
    """The SH exponential methods of :func:`exp` (the one list; settings and CLI import it)."""

    HYB = "hyb"
    PS_STAR = "ps*"
    PS = "ps"
    OL = "ol"
    EXACT = "exact"
    VOLTERRA = "volterra"


EXP_METHODS = tuple(m.value for m in ExpMethod)
DEFAULT_DEGREE = {"ps": 8, "ps*": 2}
"""Series degree ``p`` of PS-p and PS*-p when not given."""
#: The margin ``c`` of the squaring count ``q = max(0, floor(log2 |f_hat|) + c)`` of
#: Sec. 4.1: the scaled vector's norm is below ``2^(1 - c)`` (1/4 at the paper's 3).
SQUARING_MARGIN = 3


#: Top share of each octave of ``|f_hat|`` over which the exp blends the results of
#: ``q`` and ``q + 1`` squarings (:func:`squaring_weights`).  The squaring count steps
#: where ``|f_hat|`` crosses a power of 2, and the scaled series' error with it: a
#: jump of up to 0.2 % of the visibility at the paper's margin, 3 % at margin 1, a
#: ring on a receiver surface.  Blended, the exp is continuous in ``f``; the rows of
#: the band (this share of them, about) take one square more (PS*-2) or one series
#: and one square more (the other series, HYB).
SQUARING_BLEND = 0.25


def squaring_weights(norm, margin: int = SQUARING_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """Squarings ``q`` (:func:`squarings`) and the weight ``w`` of the result with
    ``q + 1`` of each vector, shapes of ``norm``.

    With ``u = log2 |f_hat| + margin``, ``w`` rises by a smoothstep from 0 to 1 over the
    last :data:`SQUARING_BLEND` of each unit of ``u``.  The scaled exp ``e(x)``,
    ``x = f_hat / 2^q``, is blended as ``(1 - w) e(x) + w e(x/2)^2`` before the ``q``
    squarings, which meets the result of ``q + 1`` squarings where ``q`` steps up;
    ``w = 0`` where ``q`` stays 0 (``u < 0``).
    """
    u = _log_count(norm, margin)
    floor = np.floor(u)
    t = np.clip((u - floor - (1.0 - SQUARING_BLEND)) / SQUARING_BLEND, 0.0, 1.0)
    w = np.where(u >= 0, smoothstep(t), 0.0)
    return np.maximum(floor, 0).astype(np.int64), w


def squarings(norm, margin: int = SQUARING_MARGIN) -> np.ndarray:
    """Number of squarings ``max(0, floor(log2 norm) + margin)`` (Sec. 4.1), shape of
    ``norm``."""
    return np.maximum(np.floor(_log_count(norm, margin)), 0).astype(np.int64)


def _log_count(norm, margin: int) -> np.ndarray:
    """``log2 norm + margin`` in float64 (a very negative number for norm 0)."""
    norm = np.asarray(norm, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.log2(np.where(norm > 0, norm, 1e-300)) + int(margin)


def _one(batch: int, size: int, dtype) -> np.ndarray:
    one = np.zeros((batch, size), dtype=dtype)
    one[:, 0] = SQRT_4PI
    return one


def _product_series(f: np.ndarray, degree: int, order: int) -> np.ndarray:
    """Eq. 17 truncated at ``degree``, powers accumulated left to right."""
    b, size = f.shape
    g = _one(b, size, f.dtype)
    power = f
    for k in range(1, degree + 1):
        if k > 1:
            power = product(power, f, order)
        g += power / math.factorial(k)
    return g


def _exact(f: np.ndarray) -> np.ndarray:
    m = product_matrix(f)
    lam, vec = np.linalg.eigh(m)
    small = np.abs(lam) < 1e-12
    q = np.where(small, 1.0 + 0.5 * lam, np.expm1(lam) / np.where(small, 1.0, lam))
    c = np.einsum("bji,bj->bi", vec, f) * q
    g = np.einsum("bij,bj->bi", vec, c)
    g[:, 0] += SQRT_4PI
    return g


def exp(f, method: str = "hyb", *, degree: int | None = None, acc_order: int | None = None,
        tables: dict | None = None, quad_degree: int | None = None,
        margin: int = SQUARING_MARGIN) -> np.ndarray:
    """SH exponential of log-visibility vectors.

    Parameters
    ----------
    f : array_like, shape (..., n*n)
        SH vectors (e.g. sums of blocker log vectors).  float32 input keeps the
        PS/PS*/OL/HYB arithmetic in float32.
    method : {"hyb", "ps*", "ps", "ol", "exact", "volterra"}
        See the module docstring.
    degree : int, optional
        Series degree ``p`` of PS-p (default 8) and PS*-p (default 2).
    acc_order : int, optional
        Order (``>= n``, default ``n``) at which the products of PS and PS* and
        the squarings of PS* and HYB are accumulated before truncating back to
        ``n``.  For HYB, ``n + 2`` markedly reduces the error of the squarings
        against product-space accumulation (tests/sh/test_exp_log.py checks it).
    tables : dict, optional
        OL tables of order ``n`` with ``ol_norm, ol_a, ol_b`` (as from
        :func:`shtools.sh.tables.build_log_tables` or a tables asset) for
        ``"ol"``/``"hyb"``; built and cached per order when omitted.
    quad_degree : int, optional
        Quadrature degree of ``"volterra"`` (default ``6*n + 18``).
    margin : int
        Squaring-count margin of PS* and HYB (:func:`squarings`).

    Returns
    -------
    ndarray, shape (..., n*n)
        ``exp(f)`` by the chosen method.
    """
    f = np.asarray(f)
    dtype = f.dtype if f.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    f = f.astype(dtype, copy=False)
    n = order_from_size(f.shape[-1])
    if method not in EXP_METHODS:
        raise ValueError(f"unknown exp method {method!r}; use one of {EXP_METHODS}")
    work = n if acc_order is None else check_order(acc_order)
    if work < n:
        raise ValueError(f"acc_order {work} must be >= the order {n} of the input")
    if degree is None:
        degree = DEFAULT_DEGREE.get(method, 0)
    elif isinstance(degree, bool) or int(degree) != degree or degree < 1:
        raise ValueError(f"series degree must be an integer >= 1, got {degree!r}")
    lead = f.shape[:-1]
    flat = f.reshape(-1, n * n)
    if method in ("ol", "hyb") and tables is None:
        from shtools.sh.tables import default_tables

        tables = default_tables(n)
    if method in ("ps*", "hyb", "ol"):  # the one driver, on triple-tensor products
        g = exp_batched(_pad(flat, work), method, TensorProducts(work, dtype), tables,
                        degree=int(degree), out_order=n, margin=margin)
        return g.reshape(*lead, n * n)
    # bytes of working memory per vector: product matrices for "exact", nodes of the
    # quadrature for "volterra", a dozen SH vectors otherwise
    per_item = 3 * n**4 * 8 if method == "exact" else 16 * (work + 1) ** 2 * 8
    if method == "volterra":
        qd = 6 * n + 18 if quad_degree is None else int(quad_degree)
        per_item = 3 * sphere_quadrature(qd)[0].shape[0] * 8
    step = max(1, CHUNK_BYTES // per_item)
    out = np.empty((flat.shape[0], n * n), dtype=dtype)
    for s in range(0, flat.shape[0], step):
        chunk = flat[s : s + step]
        if method == "exact":
            g = _exact(chunk.astype(np.float64))
        elif method == "volterra":
            g = volterra(chunk.astype(np.float64), qd, chunk=step)
        else:  # "ps"
            g = _product_series(_pad(chunk, work), int(degree), work)
        out[s : s + step] = g[:, : n * n]
    return out.reshape(*lead, n * n)


# --------------------------------------------------------------------------- backends
class ProductBackend(Protocol):
    """Truncated SH products of order-``n`` vectors held as *parts* (list of ``(B, n_k)``).

    A backend may split a vector into coefficient classes (the runtime's
    parity-split quadrature does) or keep it whole (one part); the exp driver
    only adds, scales and multiplies parts, so chains of products split and
    merge once.  Part 0 holds coefficient 0 (the DC term) in its column 0.
    """

    order: int
    dtype: np.dtype

    def split(self, f: np.ndarray, copy: bool = True) -> list[np.ndarray]: ...
    def merge(self, parts, out_order: int | None = None, out=None) -> np.ndarray: ...
    def class_sizes(self, out_order: int | None = None) -> list[int]: ...
    def workspace(self, rows: int) -> list: ...
    def workspace_layout(self) -> tuple[int, int]: ...
    def square_split(self, parts, out_order: int | None = None, ws=None) -> list: ...
    def product_split(self, f_parts, g_parts) -> list: ...
    def square_values(self, parts, ws=None): ...
    def project_square(self, values, rows: slice, out_order: int | None = None,
                       out=None) -> list: ...


class TensorProducts:
    """A one-part :class:`ProductBackend`: products by :mod:`shtools.sh.triple` kernels.

    Parameters
    ----------
    order : int
        SH order of inputs and outputs.
    dtype : numpy dtype
    kernel : str
        A product kernel of :mod:`shtools.sh._kernels` (``"cp"``: the exact
        quadrature factors of the triple tensor on BLAS; ``"dense"``: contraction
        with the dense tensor; or one registered by a benchmark).
    """

    def __init__(self, order: int, dtype=np.float64, kernel: str = "cp"):
        self.order = int(order)
        self.dtype = np.dtype(dtype)
        self.kernel = kernel

    def split(self, f, copy: bool = True):
        return [np.array(f, dtype=self.dtype, order="C", copy=copy or None)]

    def merge(self, parts, out_order=None, out=None):
        top = (self.order if out_order is None else out_order) ** 2
        if out is None:
            return np.ascontiguousarray(parts[0][:, :top])
        out[...] = parts[0][:, :top]
        return out

    def workspace(self, rows: int) -> list:
        return []

    def workspace_layout(self) -> tuple[int, int]:
        return 0, 0

    def _run(self, f, g, out_order):
        return run_product(np.ascontiguousarray(f), None if g is None else
                           np.ascontiguousarray(g), self.order, out_order, kernel=self.kernel)

    def square_split(self, parts, out_order=None, ws=None):
        out = self.order if out_order is None else out_order
        return [np.ascontiguousarray(self._run(parts[0], None, out))]

    def product_split(self, f_parts, g_parts):
        return [np.ascontiguousarray(self._run(f_parts[0], g_parts[0], self.order))]

    def class_sizes(self, out_order: int | None = None) -> list[int]:
        return [(self.order if out_order is None else out_order) ** 2]

    def square_values(self, parts, ws=None):
        return parts  # the square is formed when projected

    def project_square(self, values, rows, out_order=None, out=None):
        sq = self.square_split([values[0][rows]], out_order)
        if out is None:
            return sq
        out[0][...] = sq[0]
        return out


# --------------------------------------------------------------------------- driver
def exp_batched(f, method: str, backend: ProductBackend, tables: dict | None = None, *,
                degree: int | None = None, chunk: int = 4096, threads: int = 1,
                out_order: int | None = None, workspaces: list | None = None,
                margin: int = SQUARING_MARGIN) -> np.ndarray:
    """PS*-p, HYB or OL exponential of many vectors on a product backend (the one driver).

    DC isolation, the squaring count ``q`` of Sec. 4.1, the OL model or the
    factored PS*-p series (eq. 22), then ``q`` squarings; where ``q`` steps, the
    results of ``q`` and ``q + 1`` are blended (:func:`squaring_weights`), so the exp
    is continuous in ``f``.  Rows are sorted by
    ``q`` so the rows still squaring are a prefix; each row's last squaring
    projects onto the ``out_order`` coefficients only.  ``f_hat = 0`` rows are
    exactly ``exp(dc)``.

    Parameters
    ----------
    f : array_like, shape (B, n*n)
        Log vectors at the backend's order ``n`` (float32 stays float32).
    method : {"hyb", "ps*", "ol"}
    backend : ProductBackend
        Of order ``n`` and ``f``'s dtype.
    tables : dict, optional
        OL tables ``ol_norm, ol_a, ol_b`` (needed by hyb and ol).
    degree : int, optional
        PS*-p degree (default ``DEFAULT_DEGREE["ps*"]``).
    chunk : int
        Vectors per block (bounds memory).
    threads : int
        Blocks evaluated concurrently (NumPy/BLAS release the GIL).
    out_order : int, optional
        Order of the result (default ``n``).
    workspaces : list, optional
        Backend scratch kept by the caller between calls (one per thread).
    margin : int
        Squaring-count margin (:func:`squarings`).

    Returns
    -------
    ndarray, shape (B, out_order^2)
    """
    f = np.asarray(f)
    dtype = backend.dtype
    f = f.astype(dtype, copy=False)
    order = backend.order
    if f.shape[-1] != order * order:
        raise ValueError(f"vectors of size {f.shape[-1]} do not match the backend's order "
                         f"{order}")
    n_out = order if out_order is None else int(out_order)
    if not 1 <= n_out <= order:
        raise ValueError(f"out_order must be in 1..{order}, got {out_order!r}")
    if method not in ("hyb", "ps*", "ol"):
        raise ValueError(f"the exp driver runs hyb, ps* and ol, got {method!r}")
    if method in ("hyb", "ol") and tables is None:
        raise ValueError("the hyb and ol methods need OL tables")
    p = DEFAULT_DEGREE["ps*"] if degree is None else int(degree)
    out = np.empty((f.shape[0], n_out * n_out), dtype=dtype)
    starts = range(0, f.shape[0], chunk)
    n_workers = max(1, min(int(threads), len(starts)))
    spaces = _workspaces(backend, min(chunk, f.shape[0]), n_workers,
                         [] if workspaces is None else workspaces)

    def work(k):
        for s in starts[k::n_workers]:
            _exp_block(f[s : s + chunk], method, tables, p, backend, n_out,
                       out[s : s + chunk], spaces[k], margin)

    if n_workers > 1:
        with ThreadPoolExecutor(max_workers=n_workers) as pool:
            list(pool.map(work, range(n_workers)))
    else:
        work(0)
    return out


def _workspaces(ops, rows: int, count: int, kept: list) -> list:
    """``count`` workspaces of at least ``rows`` rows for ``ops``, reusing ``kept``
    (which is updated in place) when the shapes fit."""
    n_arrays, width = ops.workspace_layout()
    for k in range(count):
        fits = (k < len(kept) and len(kept[k]) == n_arrays
                and (n_arrays == 0 or (kept[k][0].shape[0] >= rows
                                       and kept[k][0].shape[1] == width
                                       and kept[k][0].dtype == ops.dtype)))
        if not fits:
            space = ops.workspace(rows)
            if k < len(kept):
                kept[k] = space
            else:
                kept.append(space)
    return kept[:count]


def _ol_split(parts, norm: np.ndarray, tables: dict):
    """OL (eq. 23) on parts of ``f_hat``: ``a(|f|) * 1 + b(|f|) * f_hat``."""
    a = np.interp(norm, tables["ol_norm"], tables["ol_a"])
    b = np.interp(norm, tables["ol_norm"], tables["ol_b"])
    out = [p * b[:, None].astype(p.dtype) for p in parts]
    out[0][:, 0] = a * SQRT_4PI
    return out


def _factored_series(parts, degree: int, ops, ws=None):
    """Eq. 22 for exp on parts: even part plus ``f *`` odd part.

    Even powers are built as :math:`f^{2*} = f * f`, :math:`f^{2k*} = f^{(2k-2)*} * f^{2*}`.
    """
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


def _quadratic_series(parts, square, s: float):
    """PS*-2 of ``s f`` from the class parts of ``f`` and of ``f * f``:
    ``1 + s f + (s^2 / 2) f^2``, written into ``square`` (returned)."""
    c2 = 0.5 * s * s
    for e, p in zip(square, parts, strict=True):
        e *= e.dtype.type(c2)
        e += p if s == 1.0 else p * p.dtype.type(s)
    square[0][:, 0] += SQRT_4PI
    return square


def _exp_block(f, method, tables, degree, ops, n_out: int, out, ws=None,
               margin: int = SQUARING_MARGIN) -> None:
    """exp of ``f (B, n*n)`` truncated to ``n_out``, written into ``out (B, n_out^2)``."""
    dc = np.exp(f[:, 0].astype(np.float64) / SQRT_4PI)
    # |f_hat| of the coefficients after the DC (DC isolated), summed in f's precision
    # (float32 has ample for the squaring count: its rounding moves q only where
    # |f_hat| is within 1e-7 of a power of 2) and then kept in float64
    norm = np.sqrt(np.einsum("bi,bi->b", f[:, 1:], f[:, 1:]).astype(np.float64))
    if method == "ol":
        parts = ops.split(f)
        parts[0][:, 0] = 0.0
        ops.merge(_ol_split(parts, norm, tables), n_out, out=out)
        out *= dc[:, None].astype(out.dtype)
        return
    q, w = squaring_weights(norm, margin)
    # vectors sorted by squaring count (descending), so those still needing a square
    # at each step are a prefix, squared in place without gathers; f_hat = 0 rows
    # (no blocker in view) come last and are exactly exp(dc)
    key = np.where(norm > 0, q + 1, 0)  # small ints: a fast radix argsort
    by_norm = np.argsort(-key, kind="stable")
    live = int(np.count_nonzero(key))
    q_sorted = q[by_norm[:live]]
    norm_sorted = norm[by_norm[:live]]
    scale = np.ldexp(1.0, -q_sorted)
    column = scale[:, None].astype(f.dtype)  # exact: powers of 2
    scaled = np.take(f, by_norm[:live], axis=0)
    scaled[:, 0] = 0.0  # f_hat: DC isolated
    scaled *= column
    scaled = ops.split(scaled, copy=False)
    w_sorted = w[by_norm[:live]]
    band = np.flatnonzero(w_sorted > 0)
    # PS*-2 (the default series) is 1 + x + x^2/2: the band's e(x/2) below reuses the
    # square of x (x/2 squared is exactly x^2 / 4: halving is exact in binary floating
    # point) instead of squaring again
    square = ops.square_split(scaled, ws=ws) if method == "ps*" and degree == 2 else None
    square_band = None if square is None or not band.size else [
        np.take(e, band, axis=0) for e in square]  # copies, before the in-place series
    if square is not None:
        g = _quadratic_series(scaled, square, 1.0)
    else:
        g = _scaled_exp(scaled, method, norm_sorted * scale, tables, degree, ops, ws)
    # in a blend band of the squaring count, the scaled exp e(x) blends toward
    # e(x/2)^2: after the row's q squarings that is the result of q + 1 squarings,
    # where the next octave starts (the exp is continuous in f)
    if band.size:
        x_band = [np.take(p, band, axis=0) for p in scaled]
        if square_band is not None:
            e_half = _quadratic_series(x_band, square_band, 0.5)
        else:
            e_half = _scaled_exp([p * p.dtype.type(0.5) for p in x_band], method,
                                 0.5 * norm_sorted[band] * scale[band], tables, degree, ops,
                                 ws)
        twice = ops.square_split(e_half, ws=ws)
        wb = w_sorted[band, None].astype(out.dtype)
        for p, t in zip(g, twice, strict=True):
            at = np.take(p, band, axis=0)  # (a gather: faster than p[band], read once)
            at += wb * (t[:, : p.shape[1]] - at)
            p[band] = at
    # each row's result, in class parts (sorted rows), merged once at the end
    res = [np.zeros((f.shape[0], k), dtype=out.dtype) for k in ops.class_sizes(n_out)]
    res[0][live:, 0] = SQRT_4PI
    q_max = int(q_sorted.max(initial=0))
    done = int(np.count_nonzero(q_sorted > 0))
    for r, p in zip(res, g, strict=True):
        r[done:live] = p[done:, : r.shape[1]]
    for step in range(q_max):
        count = done
        done = int(np.count_nonzero(q_sorted > step + 1))
        # rows [done, count) take their last square: project onto the kept
        # coefficients only; rows [0, done) keep squaring at full order
        vals = ops.square_values([p[:count] for p in g], ws)
        ops.project_square(vals, slice(done, count), n_out,
                           out=[r[done:count] for r in res])
        if done:
            ops.project_square(vals, slice(0, done), out=[p[:done] for p in g])
    out[by_norm] = ops.merge(res, n_out)
    out *= dc[:, None].astype(out.dtype)


def _scaled_exp(parts, method, norm, tables, degree, ops, ws=None):
    """exp of scaled, DC-isolated vectors (class parts): OL for HYB, else PS*-p's series."""
    if method == "hyb":
        return _ol_split(parts, norm, tables)
    return _factored_series(parts, degree, ops, ws)


# --------------------------------------------------------------------------- volterra
@functools.lru_cache(maxsize=32)
def _volterra_operators(order: int, out_order: int, quad_degree: int, dtype_name: str):
    dirs, w = sphere_quadrature(quad_degree)
    y = basis(dirs, order)
    recon = np.ascontiguousarray(y.T, dtype=dtype_name)
    proj = np.ascontiguousarray(y[:, : out_order * out_order] * w[:, None], dtype=dtype_name)
    recon.setflags(write=False)
    proj.setflags(write=False)
    return recon, proj


def volterra(f, quad_degree: int, *, out_order: int | None = None,
             chunk: int = 4096) -> np.ndarray:
    """The Volterra exponential (eq. 10), :math:`\\int_S \\exp(f(s))\\,\\mathbf y(s)\\,ds`.

    Parameters
    ----------
    f : ndarray, shape (B, n*n)
        float32 or float64 (the arithmetic type).
    quad_degree : int
        Degree of the quadrature (:func:`shtools.sh.sphere_quadrature`).
    out_order : int, optional
        Order of the result (default ``n``).
    chunk : int
        Vectors per block.

    Returns
    -------
    ndarray, shape (B, out_order^2)
    """
    order = order_from_size(f.shape[-1])
    n_out = order if out_order is None else int(out_order)
    recon, proj = _volterra_operators(order, n_out, int(quad_degree), f.dtype.name)
    out = np.empty((f.shape[0], n_out * n_out), dtype=f.dtype)
    for s in range(0, f.shape[0], chunk):
        v = f[s : s + chunk] @ recon
        np.exp(v, out=v)
        out[s : s + chunk] = v @ proj
    return out
