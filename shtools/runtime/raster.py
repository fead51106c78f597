"""Triangle rasterisation in vectorised NumPy: candidate fragments and a depth buffer.

The one place that turns projected triangles into pixel fragments.  It is
numpy-only, so both the runtime (the shadow maps of
:mod:`shtools.runtime.ssoc`) and the preview renderer
(:mod:`shtools.export.raster`) import it.

Triangles are expanded into the pixels of their screen bounding boxes in
bounded batches and tested with barycentric edge functions at the pixel centres
``(x + 0.5, y + 0.5)``: the triangles of a common box size as one broadcast block,
the others by ``np.repeat`` over their pixel counts.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

#: Candidate pixels expanded per batch (bounds memory to ~ a few hundred MB).
FRAGMENT_BUDGET = 4_000_000
#: Barycentric slack so that pixels on a shared edge are not lost to rounding.
EDGE_EPS = 1e-7
#: Pixels in all below which the triangles of one box size are not worth a block of
#: their own (a block costs a few NumPy calls, ~50 us; a repeated pixel ~70 ns).
GROUP_MIN_CANDIDATES = 4096


def triangle_fragments(sx, sy, width: int, height: int, *, budget: int = FRAGMENT_BUDGET
                       ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Pixels covered by projected triangles, in batches.

    Triangles whose screen boxes have one size ``(h, w)`` are tested together as an
    ``(n, h, w)`` block by broadcasting; the rest (sizes with fewer than
    ``GROUP_MIN_CANDIDATES`` pixels in all) are expanded pixel by pixel with
    ``np.repeat``.  Both evaluate the same edge functions with the same operations,
    so a pixel's test does not depend on the path that made it.

    Parameters
    ----------
    sx, sy : ndarray, shape (F, 3)
        Screen coordinates (pixels; pixel ``(i, j)`` has its centre at
        ``(i + 0.5, j + 0.5)``) of each triangle's corners.
    width, height : int
        Image size in pixels.
    budget : int
        Candidate pixels tested at once (bounds the scratch arrays); a yielded batch
        joins pieces until it holds at least this many fragments (at most about
        twice as many).

    Yields
    ------
    tri : ndarray of int, shape (P,)
        Triangle index (into the rows of ``sx``) of each covered pixel.  A pixel
        appears at most once per triangle; the order of the fragments is unspecified.
    px, py : ndarray of int, shape (P,)
        Pixel column and row.
    bary : ndarray, shape (P, 3)
        Screen-space barycentric coordinates of the pixel centre.
    """
    boxes = _Boxes(sx, sy, width, height)
    pieces, size = [], 0
    for piece in boxes.fragments(budget):
        pieces.append(piece)
        size += len(piece[0])
        if size >= budget:
            yield _joined(pieces)
            pieces, size = [], 0
    if pieces:
        yield _joined(pieces)


def _joined(pieces: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    if len(pieces) == 1:
        return pieces[0]
    return tuple(np.concatenate(column) for column in zip(*pieces, strict=True))


class _Boxes:
    """The triangles' screen boxes and barycentric planes, expanded into fragments.

    ``xmin, ymin, bw, bh`` ``(F,)``: each box's first pixel and size (0 off screen);
    ``tri`` ``(T,)``: the triangles drawn; ``coef`` ``(F, 6)``: ``l1, l2`` as affine
    functions of the pixel centre.
    """

    def __init__(self, sx, sy, width: int, height: int):
        x3, y3 = np.asarray(sx, dtype=np.float64), np.asarray(sy, dtype=np.float64)
        W, H = int(width), int(height)
        # corner-wise minima: a reduction along an axis of length 3 is ~5x slower
        lo_x = np.minimum(np.minimum(x3[:, 0], x3[:, 1]), x3[:, 2])
        hi_x = np.maximum(np.maximum(x3[:, 0], x3[:, 1]), x3[:, 2])
        lo_y = np.minimum(np.minimum(y3[:, 0], y3[:, 1]), y3[:, 2])
        hi_y = np.maximum(np.maximum(y3[:, 0], y3[:, 1]), y3[:, 2])
        self.xmin = np.clip(np.ceil(lo_x - 0.5), 0, W).astype(np.int64)
        xmax = np.clip(np.floor(hi_x - 0.5), -1, W - 1).astype(np.int64)
        self.ymin = np.clip(np.ceil(lo_y - 0.5), 0, H).astype(np.int64)
        ymax = np.clip(np.floor(hi_y - 0.5), -1, H - 1).astype(np.int64)
        self.bw, self.bh = xmax - self.xmin + 1, ymax - self.ymin + 1
        # signed doubled area; degenerate or off-screen triangles are skipped
        area = (x3[:, 1] - x3[:, 0]) * (y3[:, 2] - y3[:, 0]) - (x3[:, 2] - x3[:, 0]) * (
            y3[:, 1] - y3[:, 0])
        keep = (self.bw > 0) & (self.bh > 0) & (np.abs(area) > 1e-12)
        self.tri = np.flatnonzero(keep)
        # barycentrics as affine functions of the pixel centre: l_k = a_k x + b_k y + c_k
        with np.errstate(divide="ignore"):
            inv_area = np.where(np.abs(area) > 1e-12, 1.0 / area, 0.0)
        x0, y0 = x3[:, 0], y3[:, 0]
        ex2, ey2 = x3[:, 2] - x0, y3[:, 2] - y0
        ex1, ey1 = x3[:, 1] - x0, y3[:, 1] - y0
        self.coef = np.stack([
            ey2 * inv_area, -ex2 * inv_area, (ex2 * y0 - ey2 * x0) * inv_area,
            -ey1 * inv_area, ex1 * inv_area, (ey1 * x0 - ex1 * y0) * inv_area,
        ], axis=1)
        self.width = W

    def fragments(self, budget: int):
        """Covered pixels ``(tri, px, py, bary)``, a piece per box size, then the rest."""
        tri = self.tri
        if not len(tri):
            return
        key = self.bh[tri] * (self.width + 1) + self.bw[tri]
        order = np.argsort(key, kind="stable")
        tri, key = tri[order], key[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        stops = np.r_[starts[1:], len(tri)]
        cells = self.bw[tri[starts]] * self.bh[tri[starts]]
        grouped = cells * (stops - starts) >= GROUP_MIN_CANDIDATES
        for start, stop, cell in zip(starts[grouped], stops[grouped], cells[grouped],
                                     strict=True):
            step = max(budget // int(cell), 1)
            for first in range(int(start), int(stop), step):
                yield from self._block(tri[first:min(first + step, stop)])
        yield from self._expanded(tri[np.repeat(~grouped, stops - starts)], budget)

    def _tests(self, t, cx, cy):
        """Barycentrics ``l0, l1, l2`` and the inside test at pixel centres ``cx, cy`` of
        triangles ``t`` (int arrays, all three broadcast to one shape: ``(P,)`` or
        ``(n, h, w)``)."""
        c = self.coef[t]
        l1 = c[..., 0] * cx + c[..., 1] * cy + c[..., 2]
        l2 = c[..., 3] * cx + c[..., 4] * cy + c[..., 5]
        l0 = 1.0 - l1 - l2
        inside = (l0 >= -EDGE_EPS) & (l1 >= -EDGE_EPS) & (l2 >= -EDGE_EPS)
        return l0, l1, l2, inside

    def _block(self, t):
        """Triangles ``t`` ``(n,)`` of one box size ``(h, w)``, tested as an ``(n, h, w)``
        block; yields their fragments as :func:`triangle_fragments` does."""
        h, w = int(self.bh[t[0]]), int(self.bw[t[0]])
        cx = (self.xmin[t][:, None, None] + np.arange(w)) + 0.5
        cy = (self.ymin[t][:, None, None] + np.arange(h)[:, None]) + 0.5
        l0, l1, l2, inside = self._tests(t[:, None, None], cx, cy)
        k, row, col = np.nonzero(inside)
        if k.size:
            t = t[k]
            yield (t, self.xmin[t] + col, self.ymin[t] + row,
                   np.stack([l0[inside], l1[inside], l2[inside]], axis=1))

    def _expanded(self, tri, budget: int):
        """Triangles ``tri`` ``(n,)`` of any box size, expanded pixel by pixel in batches
        of about ``budget`` candidates."""
        counts = (self.bw * self.bh)[tri]
        csum = np.cumsum(counts)
        start = 0
        while start < len(tri):
            base = csum[start - 1] if start else 0
            stop = max(int(np.searchsorted(csum, base + budget, side="right")), start + 1)
            t, cnt = tri[start:stop], counts[start:stop]
            start = stop
            frag_tri = np.repeat(t, cnt)
            local = np.arange(frag_tri.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            py, px = np.divmod(local, self.bw[frag_tri])
            px += self.xmin[frag_tri]
            py += self.ymin[frag_tri]
            l0, l1, l2, inside = self._tests(frag_tri, px + 0.5, py + 0.5)
            if inside.any():
                yield (frag_tri[inside], px[inside], py[inside],
                       np.stack([l0[inside], l1[inside], l2[inside]], axis=1))


def depth_buffer(sx, sy, depth, width: int, height: int) -> np.ndarray:
    """Nearest perspective depth per pixel of projected triangles.

    Parameters
    ----------
    sx, sy : ndarray, shape (F, 3)
        Screen coordinates of the corners (see :func:`triangle_fragments`).
    depth : ndarray, shape (F, 3)
        Positive eye-space depth of the corners; ``1/depth`` is interpolated
        linearly in screen space (exact for planar triangles).
    width, height : int

    Returns
    -------
    ndarray, shape (height, width) float64
        Depth of the nearest surface, ``inf`` where nothing is drawn.
    """
    zbuf = np.full(int(width) * int(height), np.inf)
    inv_z = 1.0 / np.asarray(depth, dtype=np.float64)
    for tri, px, py, bary in triangle_fragments(sx, sy, width, height):
        z = 1.0 / np.einsum("ij,ij->i", bary, inv_z[tri])
        np.minimum.at(zbuf, py * int(width) + px, z)
    return zbuf.reshape(int(height), int(width))
