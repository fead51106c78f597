r"""Haar triple and double products (Ng, Ramamoorthi & Hanrahan 2004), nonstandard 2-D basis.

Functions on an ``N x N`` map are held as their coefficients in the
orthonormal nonstandard Haar basis of :func:`shtools.runtime.haar.haar2`
(Mallat layout).  The integral of three basis functions (the *tripling
coefficient*, in the map's pixel inner product) follows Ng et al.'s
parent-child theorem (Sec. 4 of the paper):

* all three the overall scaling function: ``1/N``;
* three wavelets of the same support square (side ``s`` pixels) and of the
  three different types (horizontal, vertical, diagonal): ``1/s``;
* two identical wavelets and a third function whose support strictly
  contains theirs (a coarser wavelet or the scaling function): the value
  of the third function on that support, ``+-1/s'``;
* every other triple: 0 (nested supports are necessary).

So a triple sum ``sum_ijk C_ijk a_i b_j c_k`` needs, per wavelet, only the
*parent value* of the other functions on its support -- the mean of the
function over that square, which is the function's partial reconstruction
from the coarser levels -- and, per support square, the six products of
the three distinct types.  :func:`haar_triple` evaluates it level by level
in ``O(N^2)`` per triple, without forming any map.  :func:`haar_product` is
the same rule read the other way (Ng's product of two Haar-represented
functions projected back onto the basis): the coefficients of the product
from parent values, same-square pairs and a bottom-up sum over each
square's descendants.  Both equal the pixel-domain computation exactly (the
basis spans the piecewise-constant maps); the tests check them against
brute-force sums of reconstructed maps.
"""

from __future__ import annotations

import numpy as np

#: the wavelet types of one level (horizontal, vertical, diagonal)
_TYPES = ("h", "v", "d")


def _blocks(c, h: int) -> dict:
    """The three wavelet blocks of level ``h`` (``h x h`` squares), each ``(..., h, h)``."""
    return {"h": c[..., :h, h:2 * h], "v": c[..., h:2 * h, :h], "d": c[..., h:2 * h, h:2 * h]}


def _refine(scale, w: dict) -> np.ndarray:
    """Scaling coefficients one level finer, ``(..., 2h, 2h)`` (one inverse Haar step)."""
    s, hz, vt, dg = scale, w["h"], w["v"], w["d"]
    shape = np.broadcast_shapes(s.shape, hz.shape)
    out = np.empty((*shape[:-2], 2 * shape[-2], 2 * shape[-1]))
    out[..., 0::2, 0::2] = (s + hz + vt + dg) / 2
    out[..., 0::2, 1::2] = (s - hz + vt - dg) / 2
    out[..., 1::2, 0::2] = (s + hz - vt - dg) / 2
    out[..., 1::2, 1::2] = (s - hz - vt + dg) / 2
    return out


def tripling_coefficient(i: tuple[int, int], j: tuple[int, int], k: tuple[int, int],
                         size: int) -> float:
    """Ng et al.'s tripling coefficient of three basis functions, by their Mallat positions.

    Parameters
    ----------
    i, j, k : (row, column)
        Positions in the ``size x size`` coefficient layout of :func:`haar2`.
    size : int

    Returns
    -------
    float
        ``sum_q B_i(q) B_j(q) B_k(q)`` over the map's pixels, from the
        parent-child rules of the module docstring (not from the maps).
    """
    def describe(p):
        r, c = p
        if r == 0 and c == 0:
            return ("s", 1, 0, 0)
        h = 1 << (max(r, c).bit_length() - 1)
        kind = "h" if r < h else ("v" if c < h else "d")
        return (kind, h, r % h if r >= h else r, c % h if c >= h else c)

    fs = [describe(p) for p in (i, j, k)]
    if all(f[0] == "s" for f in fs):
        return 1.0 / size
    if all(f[0] != "s" for f in fs) and len({f[1:] for f in fs}) == 1 \
            and {f[0] for f in fs} == set(_TYPES):
        return fs[0][1] / size  # 1/s with s = size/h
    for a in range(3):
        pair = [fs[b] for b in range(3) if b != a]
        if pair[0] != pair[1] or pair[0][0] == "s":
            continue
        _, h, r, c = pair[0]
        outer = fs[a]
        if outer[0] == "s":
            return 1.0 / size
        ok, oh, orow, ocol = outer
        if oh >= h:  # not strictly coarser: a same-level or finer function integrates to 0
            continue
        ratio = h // oh
        if (r // ratio, c // ratio) != (orow, ocol):
            continue  # disjoint supports
        # which quadrant of the outer square holds the inner one
        qr, qc = (r % ratio) >= ratio // 2, (c % ratio) >= ratio // 2
        sign = {"h": -1 if qc else 1, "v": -1 if qr else 1, "d": 1 if qr == qc else -1}[ok]
        return sign * oh / size
    return 0.0


def haar_triple(a, b, c) -> np.ndarray:
    """``sum_ijk C_ijk a_i b_j c_k``: the pixel sum of the product of three Haar-coded maps.

    Parameters
    ----------
    a, b, c : array_like, shape (..., N, N)
        Haar coefficients (:func:`shtools.runtime.haar.haar2` layout), broadcast
        against each other over the leading axes.

    Returns
    -------
    ndarray, shape (...)
        Equal to ``(ihaar2(a) * ihaar2(b) * ihaar2(c)).sum((-2, -1))``.
    """
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (a, b, c))
    N = a.shape[-1]
    sa, sb, sc = a[..., :1, :1], b[..., :1, :1], c[..., :1, :1]
    total = (sa * sb * sc)[..., 0, 0] / N
    h = 1
    while h < N:
        s = N / h  # support side of this level's wavelets, in pixels
        ma, mb, mc = sa / s, sb / s, sc / s  # parent values: means over each square
        wa, wb, wc = _blocks(a, h), _blocks(b, h), _blocks(c, h)
        level = 0.0
        for t in _TYPES:
            level = level + wa[t] * (wb[t] * mc + wc[t] * mb) + wb[t] * wc[t] * ma
        same = (wa["h"] * (wb["v"] * wc["d"] + wb["d"] * wc["v"])
                + wa["v"] * (wb["h"] * wc["d"] + wb["d"] * wc["h"])
                + wa["d"] * (wb["h"] * wc["v"] + wb["v"] * wc["h"])) / s
        total = total + (level + same).sum(axis=(-2, -1))
        sa, sb, sc = _refine(sa, wa), _refine(sb, wb), _refine(sc, wc)
        h *= 2
    return total


def haar_product(a, b) -> np.ndarray:
    """Haar coefficients of the product of two Haar-coded maps (Ng et al.'s double product).

    ``W_k = sum_ij C_ijk a_i b_j``: per wavelet ``k`` of support side ``s``,
    ``a_k P_b + b_k P_a`` (parent values), ``(a_y b_z + a_z b_y) / s`` (the other
    two types of the same square) and the signed sum, over ``k``'s four child
    squares, of every finer ``a_i b_i`` inside them, divided by ``s``; the
    scaling coefficient is ``(a_0 b_0 + sum_i a_i b_i) / N``.

    Parameters
    ----------
    a, b : array_like, shape (..., N, N)

    Returns
    -------
    ndarray, shape (..., N, N)
        Equal to ``haar2(ihaar2(a) * ihaar2(b))``.
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    N = a.shape[-1]
    levels = []
    h = 1
    while h < N:
        levels.append(h)
        h *= 2
    # bottom-up: E[h] = per square of level h, the sum of a_i b_i over its wavelets and all
    # finer ones inside it
    E = {}
    below = None
    for h in reversed(levels):
        wa, wb = _blocks(a, h), _blocks(b, h)
        e = sum(wa[t] * wb[t] for t in _TYPES)
        if below is not None:
            e = e + below[..., 0::2, 0::2] + below[..., 0::2, 1::2] + below[..., 1::2, 0::2] \
                + below[..., 1::2, 1::2]
        E[h] = below  # what lies strictly below level h (None at the finest)
        below = e
    out = np.zeros(a.shape)
    out[..., 0, 0] = (a[..., 0, 0] * b[..., 0, 0] + below[..., 0, 0]) / N
    sa, sb = a[..., :1, :1], b[..., :1, :1]
    others = {"h": ("v", "d"), "v": ("h", "d"), "d": ("h", "v")}
    for h in levels:
        s = N / h
        ma, mb = sa / s, sb / s
        wa, wb = _blocks(a, h), _blocks(b, h)
        child = E[h]
        if child is not None:
            tl, tr = child[..., 0::2, 0::2], child[..., 0::2, 1::2]
            bl, br = child[..., 1::2, 0::2], child[..., 1::2, 1::2]
            down = {"h": tl - tr + bl - br, "v": tl + tr - bl - br, "d": tl - tr - bl + br}
        ob = _blocks(out, h)
        for t in _TYPES:
            y, z = others[t]
            val = wa[t] * mb + wb[t] * ma + (wa[y] * wb[z] + wa[z] * wb[y]) / s
            if child is not None:
                val = val + down[t] / s
            ob[t][...] = val
        sa, sb = _refine(sa, wa), _refine(sb, wb)
    return out
