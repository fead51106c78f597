"""Batching per-cluster accumulation into fixed-size tiles (amortises NumPy call overhead).

Each receiver cluster accumulates over its own cut (Sec. 6.3).  A cluster of a
few hundred vertices times a few dozen spheres is too small an array for NumPy
to run at full speed, so clusters are cut into tiles of ``TILE_ROWS``
vertices, each with its own sphere list: the cluster's cut without the spheres
that lie behind the tangent plane of every receiver of the tile (rule 1 of
Sec. 6.2 removes them, so dropping them is exact), ordered so that the spheres
that may straddle or be behind some receiver's plane come first and the
self-shadow rules run on that prefix only.  Tiles are sorted by list size and
stacked into blocks ``(K, TILE_ROWS, S)`` of about ``chunk_pairs`` pairs, the
lists padded with radius-0 spheres (which contribute exactly nothing).  A
cluster's last tile is padded by repeating one of its vertices; the duplicate
rows compute the same value and are written back harmlessly.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from shtools.runtime.accumulate import BlockKernel, accumulate_blocks
from shtools.runtime.log_table import CapLogTable

#: Receivers per tile: small enough that padding a cluster's last tile wastes
#: little, large enough that (tile x cut) blocks batch well.
TILE_ROWS = 32
#: Tiles are blocked apart by the share of their sphere list that needs the
#: self-shadow rules, in this many steps (flat ground far from the blockers
#: needs none, a blocker's own surface nearly all).
RULE_SHARES = 2
#: A block stops growing before its lists' padding (radius-0 spheres up to the
#: block's longest list) exceeds this many pairs and this share of its pairs:
#: padding costs as much as real pairs, and a block's fixed cost (a few hundred
#: NumPy calls) is worth about this many pairs.
PADDING_PAIRS = 4096
PADDING_FRACTION = 0.1
#: Tiles per batched plane test in :func:`_tile_sphere_lists` (bounds its
#: ``(tiles, TILE_ROWS, S)`` scratch to a few MB).
_CURVED_TILES_PER_CHUNK = 256


def accumulate_clusters(points, normals, cluster_order, cluster_offsets, sphere_centers,
                        sphere_radii, sphere_weights, cut_sizes, table: CapLogTable, *,
                        self_shadow: bool = True, chunk_pairs: int = 1 << 15,
                        threads: int = 1, kernels: list[BlockKernel] | None = None,
                        stats: dict | None = None) -> np.ndarray:
    """Eq. 38 log sums for receivers grouped in clusters with per-cluster sphere lists.

    Parameters
    ----------
    points, normals : ndarray, shape (V, 3)
    cluster_order : ndarray of int, shape (V,)
        Vertex indices sorted by cluster.
    cluster_offsets : ndarray of int, shape (C + 1,)
        Cluster ``c`` holds ``cluster_order[offsets[c]:offsets[c+1]]``.
    sphere_centers : ndarray, shape (C, S, 3)
        Each cluster's cut, padded to ``S`` (the largest cut).
    sphere_radii : ndarray, shape (C, S)
        Radii, 0 in the padding.
    sphere_weights : ndarray, shape (C, S, n) or None
        Ratio weights (eq. 37); None for all ones.
    cut_sizes : ndarray of int, shape (C,)
        Valid spheres per cluster (the first ``cut_sizes[c]`` of each row).
    table : CapLogTable
    self_shadow : bool
    chunk_pairs : int
        Target pairs per block.
    threads : int
        Worker threads (NumPy releases the GIL in its loops).
    kernels : list of BlockKernel, optional
        Reused kernels, one per thread (keep scratch buffers between frames).
    stats : dict, optional
        Receives ``pairs_evaluated``: pairs the kernel actually ran (after
        dropping spheres behind whole tiles, with tile and list padding).

    Returns
    -------
    ndarray, shape (V, n*n) float32
    """
    n = table.order
    pts = np.asarray(points, dtype=np.float32)
    nrm = np.asarray(normals, dtype=np.float32)
    out = np.zeros((pts.shape[0], n * n), dtype=np.float32)
    counts = np.diff(cluster_offsets)
    n_tiles = -(-counts // TILE_ROWS)  # ceil
    tile_cluster = np.repeat(np.arange(counts.size), n_tiles)
    if tile_cluster.size == 0:
        return out
    # rows of each tile: offsets into the cluster, clamped to its last vertex (padding)
    first_tile = np.concatenate([[0], np.cumsum(n_tiles)[:-1]])
    tile_in_cluster = np.arange(tile_cluster.size) - first_tile[tile_cluster]
    local = tile_in_cluster[:, None] * TILE_ROWS + np.arange(TILE_ROWS)[None, :]
    local = np.minimum(local, counts[tile_cluster][:, None] - 1)
    rows = cluster_order[cluster_offsets[tile_cluster][:, None] + local]  # (NT, TILE_ROWS)
    cen = np.asarray(sphere_centers, dtype=np.float32)
    rad = np.asarray(sphere_radii, dtype=np.float32)
    wts = None if sphere_weights is None else np.asarray(sphere_weights, dtype=np.float32)
    # each tile's own sphere list: its cluster's cut without the spheres that are
    # behind the tangent plane of every receiver of the tile (they contribute
    # exactly 0 under the self-shadow rules; ~18 % of the pairs in a battle scene)
    tile_spheres, sizes, rule_sizes = _tile_sphere_lists(pts, nrm, rows, tile_cluster, cen, rad,
                                             np.asarray(cut_sizes), self_shadow)
    # tiles grouped by the share of their list that needs the self-shadow rules
    # (a block runs the rules on its largest such prefix), then sorted by list
    # size so each block pads little
    share = np.ceil(RULE_SHARES * rule_sizes / np.maximum(sizes, 1)).astype(np.int64)
    by_size = np.lexsort((sizes, share))
    blocks = []
    sorted_sizes = np.maximum(sizes[by_size], 1)
    ends = np.flatnonzero(np.diff(share[by_size])) + 1
    for first, last in zip(np.r_[0, ends], np.r_[ends, by_size.size], strict=True):
        start = first
        while start < last:
            # grow the block while it stays within chunk_pairs at its largest list
            # (the sizes ascend within a group, so the last tile's size is the block's)
            # and its padding stays within what a block costs anyway
            run_sizes = sorted_sizes[start:last]
            pairs = np.arange(1, last - start + 1) * TILE_ROWS * run_sizes
            padding = pairs - TILE_ROWS * np.cumsum(run_sizes)
            fits = (pairs <= chunk_pairs) & (
                padding <= np.maximum(PADDING_PAIRS, PADDING_FRACTION * pairs))
            stop = start + max(1, int(np.argmin(fits)) if not fits.all() else fits.size)
            blocks.append((by_size[start:stop], int(sorted_sizes[stop - 1])))
            start = stop

    # the cuts as rows of (cluster, sphere) pairs: one np.take per block gathers a
    # block's lists (several times faster than fancy indexing with two index arrays)
    n_s = cen.shape[1]
    cen_rows, rad_rows = cen.reshape(-1, 3), rad.reshape(-1)
    wts_rows = None if wts is None else wts.reshape(-1, wts.shape[2])

    def run(block_list, kern):
        for tiles, s_max in block_list:
            pair = tile_cluster[tiles][:, None] * n_s + tile_spheres[tiles, :s_max]
            # past a tile's own list: radius 0 (dropped spheres contribute 0 anyway)
            radius = np.take(rad_rows, pair)
            np.copyto(radius, np.float32(0.0),
                      where=np.arange(radius.shape[1])[None, :] >= sizes[tiles][:, None])
            r = rows[tiles]
            res = accumulate_blocks(
                np.take(pts, r, axis=0), np.take(nrm, r, axis=0),
                np.take(cen_rows, pair, axis=0), radius, table,
                weights=None if wts_rows is None else np.take(wts_rows, pair, axis=0),
                self_shadow=self_shadow, kernel=kern, rule_rows=int(rule_sizes[tiles].max()))
            # padded rows repeat a vertex of the same cluster: identical values
            out[r.ravel()] = res.reshape(-1, n * n)

    if stats is not None:
        stats["pairs_evaluated"] = int(sum(t.size * TILE_ROWS * m for t, m in blocks))
    kernels = list(kernels) if kernels else []
    while len(kernels) < max(1, threads):
        kernels.append(BlockKernel(table))
    if threads <= 1 or len(blocks) < 2:
        run(blocks, kernels[0])
        return out
    # NumPy releases the GIL inside its array loops, so threads share the cores;
    # blocks are dealt round-robin (they are sorted by size, so loads balance)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        futures = [pool.submit(run, blocks[k::threads], kernels[k]) for k in range(threads)]
        for f in futures:
            f.result()
    return out


def _tile_sphere_lists(pts, nrm, rows, tile_cluster, cen, rad, cut_sizes, self_shadow):
    """Per-tile sphere lists (indices into the cluster's cut) and their lengths.

    Parameters
    ----------
    pts, nrm : ndarray, shape (V, 3) float32
    rows : ndarray of int, shape (NT, T)
        Receivers of each tile.
    tile_cluster : ndarray of int, shape (NT,)
    cen : ndarray, shape (C, S, 3); rad : ndarray, shape (C, S)
        Padded cuts.
    cut_sizes : ndarray of int, shape (C,)
    self_shadow : bool
        Drop spheres behind every receiver's tangent plane (rule 1 of Sec. 6.2).

    Returns
    -------
    spheres : ndarray of int, shape (NT, S)
        Kept spheres that may straddle or be behind a receiver's tangent plane,
        then the kept spheres in front of every receiver, then the dropped ones.
    sizes : ndarray of int, shape (NT,)
        Kept spheres per tile.
    rule_sizes : ndarray of int, shape (NT,)
        Leading spheres of each list that need the self-shadow rules.
    """
    n_s = cen.shape[1]
    keep = np.arange(n_s)[None, :] < cut_sizes[tile_cluster][:, None]  # (NT, S)
    ruled = keep.copy()  # may be behind or straddle some receiver's plane
    if self_shadow and n_s:
        # h = N . P - N . p for every (receiver, sphere of its tile's cut)
        height = np.einsum("vi,vi->v", pts, nrm)
        tile_n = np.take(nrm, rows, axis=0)  # (NT, T, 3); faster than nrm[rows]
        flat = (tile_n == tile_n[:, :1]).all(axis=(1, 2))
        # tiles whose receivers share one normal (flat ground): h ranges exactly over
        # N . P - [max, min] of N . p, per (tile, sphere)
        ft = np.flatnonzero(flat)
        if ft.size:
            tile_h = height[rows[ft]]
            n_dot_p = np.einsum("ki,ksi->ks", tile_n[ft, 0], cen[tile_cluster[ft]])
            radius = rad[tile_cluster[ft]]
            keep[ft] &= n_dot_p - tile_h.min(axis=1)[:, None] > -radius
            ruled[ft] &= n_dot_p - tile_h.max(axis=1)[:, None] < radius
        # other tiles: every (receiver, sphere) pair, batched matrix products over
        # chunks of tiles (each tile against its cluster's padded cut)
        # by cut size, each chunk against its own longest cut only (the cuts are
        # padded to the frame's longest; past a tile's cut, keep is already False)
        curved = np.flatnonzero(~flat)
        curved = curved[np.argsort(cut_sizes[tile_cluster[curved]], kind="stable")]
        for start in range(0, curved.size, _CURVED_TILES_PER_CHUNK):
            tiles = curved[start:start + _CURVED_TILES_PER_CHUNK]
            c = tile_cluster[tiles]
            s_c = int(cut_sizes[c].max())
            h = np.matmul(tile_n[tiles], cen[c, :s_c].transpose(0, 2, 1))  # (k, T, s_c)
            h -= height[rows[tiles]][:, :, None]
            radius = rad[c, :s_c]
            keep[tiles, :s_c] &= _over_rows(np.maximum, h) > -radius  # not behind all planes
            ruled[tiles, :s_c] &= _over_rows(np.minimum, h) < radius  # not in front of all
    else:
        ruled[:] = False
    # list order: spheres needing the rules, then those in front, then dropped ones
    key = np.where(keep, np.where(ruled, 0, 1), 2).astype(np.int8)
    spheres = np.argsort(key, axis=1, kind="stable")
    return spheres, keep.sum(axis=1), np.count_nonzero(keep & ruled, axis=1)


def _over_rows(op, h: np.ndarray) -> np.ndarray:
    """``op.reduce(h, axis=1)`` by halving (contiguous passes; several times faster
    than NumPy's strided reduction over a middle axis)."""
    while h.shape[1] > 1 and h.shape[1] % 2 == 0:
        half = h.shape[1] // 2
        h = op(h[:, :half], h[:, half:])
    return op.reduce(h, axis=1)
