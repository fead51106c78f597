r"""SH exponential (Sec. 4): PS, PS*, OL, HYB and two references.

Methods (``f`` an SH vector, ``1 = (sqrt(4 pi), 0, ...)``, ``*`` the truncated
SH product of :mod:`shtools.sh.triple`):

``"ps"`` — PS-p, the product series (eq. 17) of degree ``p`` accumulated left to
right, :math:`f^{(k+1)*} = f^{k*} * f`.

``"ps*"`` — PS*-p: DC isolation (eqs. 19–20), scaling/squaring (eq. 21) with
:math:`q = \max(0, \lfloor\log_2\|\hat f\|\rfloor + 3)` squarings, and the
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

The number of squarings differs between vectors of a batch; the batch is
squared in at most ``max(q)`` passes over the vectors that still need one, so
no Python loop runs per vector.  ``acc_order`` accumulates the series products
and squarings at a higher order and truncates only the result (Sec. 4: "errors
... can be further reduced by accumulating products at higher order").
"""

from __future__ import annotations

import math
from enum import StrEnum

import numpy as np

from shtools.sh.basis import check_order, order_from_size
from shtools.sh.quadrature import project, reconstruct, sphere_quadrature
from shtools.sh.triple import CHUNK_BYTES, _pad, product, product_matrix, square

SQRT_4PI = math.sqrt(4.0 * math.pi)


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


def squarings(norm) -> np.ndarray:
    """Number of squarings ``max(0, floor(log2 norm) + 3)`` (Sec. 4.1), shape of ``norm``."""
    norm = np.asarray(norm, dtype=np.float64)
    with np.errstate(divide="ignore"):
        q = np.floor(np.log2(np.where(norm > 0, norm, 1e-300))) + 3
    return np.maximum(q, 0).astype(np.int64)


def _one(batch: int, size: int, dtype) -> np.ndarray:
    one = np.zeros((batch, size), dtype=dtype)
    one[:, 0] = SQRT_4PI
    return one


def _dc_isolate(f: np.ndarray):
    """Return ``(exp(f0/sqrt(4 pi)) (B,), f_hat (B, N), ||f_hat|| (B,))``."""
    f_hat = f.copy()
    f_hat[:, 0] = 0.0
    norm = np.sqrt(np.einsum("bi,bi->b", f_hat, f_hat, dtype=np.float64))
    return np.exp(f[:, 0].astype(np.float64) / SQRT_4PI), f_hat, norm


def _repeated_squaring(g: np.ndarray, q: np.ndarray, order: int,
                       in_order: int | None = None) -> np.ndarray:
    """Square row ``b`` of ``g`` ``q[b]`` times (eq. 21), in ``max(q)`` batched passes.

    ``g`` has ``order**2`` columns; if only its first ``in_order**2`` can be
    nonzero, the first pass squares just those (cheaper, same result).
    """
    qmax = int(q.max(initial=0))
    if qmax == 0:
        return g
    perm = np.argsort(-q, kind="stable")  # rows needing more squarings first
    q_sorted = q[perm]
    work = g[perm]
    for step in range(qmax):
        count = int(np.count_nonzero(q_sorted > step))  # a prefix of the sorted rows
        cols = order * order if step or in_order is None else in_order * in_order
        work[:count] = square(work[:count, :cols], order)
    out = np.empty_like(work)
    out[perm] = work
    return out


def _factored_series(f: np.ndarray, degree: int, order: int) -> np.ndarray:
    """Eq. 22 for ``h = exp`` (``degree >= 1``): even part plus ``f * odd part``."""
    b, size = f.shape
    coef = [1.0 / math.factorial(k) for k in range(degree + 1)]
    even = _one(b, size, f.dtype)  # h_0 = 1
    odd = _one(b, size, f.dtype)  # h_1 = 1
    f2 = square(f, order) if degree >= 2 else None
    power = f2  # f^{2k*}, built as f^{(2k-2)*} * f^{2*}
    for k in range(1, degree // 2 + 1):
        if k > 1:
            power = product(power, f2, order)
        even += coef[2 * k] * power
        if 2 * k + 1 <= degree:
            odd += coef[2 * k + 1] * power
    if degree <= 2:  # the odd part is just 1, and f * 1 = f exactly
        return even + f
    return even + product(f, odd, order)


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


def _ol(f_hat: np.ndarray, norm: np.ndarray, tables: dict) -> np.ndarray:
    a = np.interp(norm, tables["ol_norm"], tables["ol_a"])
    b = np.interp(norm, tables["ol_norm"], tables["ol_b"])
    g = f_hat * b[:, None].astype(f_hat.dtype)
    g[:, 0] = a * SQRT_4PI
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
        tables: dict | None = None, quad_degree: int | None = None) -> np.ndarray:
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
        (order 4, 3–25 random caps: median 3.6 % -> 2.9 % relative L2 against
        product-space accumulation; see tests/sh/test_exp_log.py).
    tables : dict, optional
        OL tables of order ``n`` with ``ol_norm, ol_a, ol_b`` (as from
        :func:`shtools.sh.tables.build_log_tables` or a tables asset) for
        ``"ol"``/``"hyb"``; built and cached per order when omitted.
    quad_degree : int, optional
        Quadrature degree of ``"volterra"`` (default ``6*n + 18``).

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
    # bytes of working memory per vector: product matrices for "exact", nodes of the
    # quadrature for "volterra", a dozen SH vectors (and product nodes) otherwise
    per_item = 3 * n**4 * 8 if method == "exact" else 16 * (work + 1) ** 2 * 8
    if method == "volterra":
        qd = 6 * n + 18 if quad_degree is None else int(quad_degree)
        dirs, w = sphere_quadrature(qd)
        per_item = 3 * dirs.shape[0] * 8
    step = max(1, CHUNK_BYTES // per_item)
    out = np.empty((flat.shape[0], n * n), dtype=dtype)
    for s in range(0, flat.shape[0], step):
        chunk = flat[s : s + step]
        if method == "exact":
            g = _exact(chunk.astype(np.float64))
        elif method == "volterra":
            values = reconstruct(chunk.astype(np.float64), dirs)
            g = project(np.exp(values), dirs, w, n)
        elif method == "ps":
            g = _product_series(_pad(chunk, work), int(degree), work)
        else:
            dc, f_hat, norm = _dc_isolate(chunk)
            if method == "ol":
                g = _ol(f_hat, norm, tables)
            else:
                q = squarings(norm)
                scale = np.ldexp(1.0, -q)
                scaled = f_hat * scale[:, None].astype(dtype)
                if method == "hyb":
                    g = _repeated_squaring(_pad(_ol(scaled, norm * scale, tables), work), q,
                                           work, in_order=n)
                else:
                    g = _repeated_squaring(_factored_series(_pad(scaled, work), int(degree), work),
                                           q, work)
            g *= dc[:, None].astype(dtype)
        out[s : s + step] = g[:, : n * n]
    return out.reshape(*lead, n * n)
