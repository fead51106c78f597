"""Batching per-cluster accumulation into fixed-size tiles (amortises NumPy call overhead).

Each receiver cluster accumulates over its own cut (Sec. 6.3).  A cluster of a
few hundred vertices times a few dozen spheres is too small an array for NumPy
to run at full speed, so clusters are cut into tiles of ``TILE_ROWS``
vertices; tiles are sorted by their cluster's cut size and stacked into blocks
``(K, TILE_ROWS, S)`` of about ``chunk_pairs`` pairs, the sphere lists padded
with radius-0 spheres (which contribute exactly nothing).  A cluster's last
tile is padded by repeating one of its vertices; the duplicate rows compute the
same value and are written back harmlessly.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from shtools.runtime.accumulate import BlockKernel, accumulate_blocks
from shtools.runtime.log_table import CapLogTable

#: Receivers per tile: small enough that padding a cluster's last tile wastes
#: little, large enough that (tile x cut) blocks batch well.
TILE_ROWS = 32


def accumulate_clusters(points, normals, cluster_order, cluster_offsets, sphere_centers,
                        sphere_radii, sphere_weights, cut_sizes, table: CapLogTable, *,
                        self_shadow: bool = True, chunk_pairs: int = 1 << 16,
                        threads: int = 1, kernels: list[BlockKernel] | None = None
                        ) -> np.ndarray:
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
    # sort tiles by cut size so each block pads little
    sizes = cut_sizes[tile_cluster]
    by_size = np.argsort(sizes, kind="stable")
    cen = np.asarray(sphere_centers, dtype=np.float32)
    rad = np.asarray(sphere_radii, dtype=np.float32)
    wts = None if sphere_weights is None else np.asarray(sphere_weights, dtype=np.float32)
    blocks = []
    start = 0
    while start < by_size.size:
        s_max = max(1, int(sizes[by_size[start]]))
        # grow the block while it stays within chunk_pairs at its largest cut size
        stop = start + 1
        while stop < by_size.size:
            s_next = max(s_max, int(sizes[by_size[stop]]))
            if (stop + 1 - start) * TILE_ROWS * s_next > chunk_pairs:
                break
            s_max = s_next
            stop += 1
        blocks.append((by_size[start:stop], s_max))
        start = stop

    def run(block_list, kern):
        for tiles, s_max in block_list:
            cl = tile_cluster[tiles]
            r = rows[tiles]
            res = accumulate_blocks(
                pts[r], nrm[r], cen[cl, :s_max], rad[cl, :s_max], table,
                weights=None if wts is None else wts[cl, :s_max], self_shadow=self_shadow,
                kernel=kern)
            # padded rows repeat a vertex of the same cluster: identical values
            out[r.ravel()] = res.reshape(-1, n * n)

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
