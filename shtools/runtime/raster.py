"""Triangle rasterisation in vectorised NumPy: candidate fragments and a depth buffer.

The one place that turns projected triangles into pixel fragments.  It is
numpy-only, so both the runtime (the shadow maps of
:mod:`shtools.runtime.ssoc`) and the preview renderer
(:mod:`shtools.export.raster`) import it.

Triangles are expanded into the pixels of their screen bounding boxes in
bounded batches (``np.repeat`` over per-triangle pixel counts) and tested with
barycentric edge functions at the pixel centres ``(x + 0.5, y + 0.5)``.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

#: Candidate pixels expanded per batch (bounds memory to ~ a few hundred MB).
FRAGMENT_BUDGET = 4_000_000
#: Barycentric slack so that pixels on a shared edge are not lost to rounding.
EDGE_EPS = 1e-7


def triangle_fragments(sx, sy, width: int, height: int, *, budget: int = FRAGMENT_BUDGET
                       ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Pixels covered by projected triangles, in batches.

    Parameters
    ----------
    sx, sy : ndarray, shape (F, 3)
        Screen coordinates (pixels; pixel ``(i, j)`` has its centre at
        ``(i + 0.5, j + 0.5)``) of each triangle's corners.
    width, height : int
        Image size in pixels.
    budget : int
        Candidate pixels per batch.

    Yields
    ------
    tri : ndarray of int, shape (P,)
        Triangle index (into the rows of ``sx``) of each covered pixel.
    px, py : ndarray of int, shape (P,)
        Pixel column and row.
    bary : ndarray, shape (P, 3)
        Screen-space barycentric coordinates of the pixel centre.
    """
    x3, y3 = np.asarray(sx, dtype=np.float64), np.asarray(sy, dtype=np.float64)
    W, H = int(width), int(height)
    xmin = np.clip(np.ceil(x3.min(1) - 0.5), 0, W).astype(np.int64)
    xmax = np.clip(np.floor(x3.max(1) - 0.5), -1, W - 1).astype(np.int64)
    ymin = np.clip(np.ceil(y3.min(1) - 0.5), 0, H).astype(np.int64)
    ymax = np.clip(np.floor(y3.max(1) - 0.5), -1, H - 1).astype(np.int64)
    bw, bh = xmax - xmin + 1, ymax - ymin + 1
    # signed doubled area; degenerate or off-screen triangles are skipped
    area = (x3[:, 1] - x3[:, 0]) * (y3[:, 2] - y3[:, 0]) - (x3[:, 2] - x3[:, 0]) * (
        y3[:, 1] - y3[:, 0])
    keep = (bw > 0) & (bh > 0) & (np.abs(area) > 1e-12)
    tri = np.flatnonzero(keep)
    counts = (bw * bh)[tri]
    # barycentrics as affine functions of the pixel centre: l_k = a_k x + b_k y + c_k
    with np.errstate(divide="ignore"):
        inv_area = np.where(np.abs(area) > 1e-12, 1.0 / area, 0.0)
    x0, y0 = x3[:, 0], y3[:, 0]
    ex2, ey2 = x3[:, 2] - x0, y3[:, 2] - y0
    ex1, ey1 = x3[:, 1] - x0, y3[:, 1] - y0
    coef = np.stack([
        ey2 * inv_area, -ex2 * inv_area, (ex2 * y0 - ey2 * x0) * inv_area,
        -ey1 * inv_area, ex1 * inv_area, (ey1 * x0 - ex1 * y0) * inv_area,
    ], axis=1)
    order = np.argsort(counts, kind="stable")
    tri, counts = tri[order], counts[order]
    csum = np.cumsum(counts)
    start = 0
    while start < len(tri):
        base = csum[start - 1] if start else 0
        stop = int(np.searchsorted(csum, base + budget, side="right"))
        stop = max(stop, start + 1)
        t = tri[start:stop]
        cnt = counts[start:stop]
        start = stop
        frag_tri = np.repeat(t, cnt)
        local = np.arange(frag_tri.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        w_t = np.repeat(bw[t], cnt)
        py, px = np.divmod(local, w_t)
        px += np.repeat(xmin[t], cnt)
        py += np.repeat(ymin[t], cnt)
        cx, cy = px + 0.5, py + 0.5
        c = np.repeat(coef[t], cnt, axis=0)
        l1 = c[:, 0] * cx + c[:, 1] * cy + c[:, 2]
        l2 = c[:, 3] * cx + c[:, 4] * cy + c[:, 5]
        l0 = 1.0 - l1 - l2
        inside = (l0 >= -EDGE_EPS) & (l1 >= -EDGE_EPS) & (l2 >= -EDGE_EPS)
        if not inside.any():
            continue
        bary = np.stack([l0[inside], l1[inside], l2[inside]], axis=1)
        yield frag_tri[inside], px[inside], py[inside], bary


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
