r"""Receivers blended over neighbouring clusters: tree cuts without seams.

Each receiver cluster takes its own cut of the blocker trees and its own ratio
vectors (SHEXP Sec. 6.3, eqs. 36-37, :mod:`shtools.runtime.hierarchy`), so two
receivers on either side of a cluster boundary are evaluated with different
approximations of the same blockers: the visibility steps along the boundary, a
network of polygonal seams on a ground.  Here a receiver near a boundary is
evaluated with every nearby cluster's cut and the results are blended with
weights that vary continuously over the surface (a partition of unity).

With :math:`d_c(p)` the distance from receiver :math:`p` to the centre of cluster
:math:`c`, :math:`d_{min}(p) = \min_c d_c(p)` and :math:`h_c` cluster :math:`c`'s
band (``band`` times its radius), the raw weight of cluster :math:`c` is

.. math::

    \rho_c(p) = 1 - S\big((d_c(p) - d_{min}(p)) / h_c\big),\quad
    S(t) = t^2 (3 - 2t) \text{ on } [0, 1],

1 for the nearest centre, 0 for clusters more than :math:`h_c` farther, and
:math:`\phi_c = \rho_c / \sum_k \rho_k`.  Every term is a continuous function of
the position alone (not of the cluster a receiver belongs to), so the blend is
continuous wherever each cluster's evaluation is; only clusters of one object
group and one label (the blockers their receivers skip) are blended.  A cluster's
cut must hold for every receiver it evaluates, so its bounding radius grows to
cover them.

What is blended is what the evaluation returns: visibility vectors after the exp
for :meth:`~shtools.runtime.ShadowRuntime.visibility` (a frame's parts
exponentiate their own entries, and a receiver's entries may lie in different
parts), log vectors for a log result (``log_visibility``, the kept log sums of
static pairs).  Either way the blend is a convex combination of continuous
functions of the position.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.blend import smoothstep
from shtools.runtime.clusters import ReceiverClusters


@dataclass
class BlendEntries:
    """Receivers as (receiver, cluster) entries with blend weights.

    Attributes
    ----------
    order : ndarray of int, shape (E,)
        Receiver row of each entry, sorted by cluster (a receiver appears once per
        cluster it is blended over).
    offsets : ndarray of int, shape (C + 1,)
        Cluster ``c`` evaluates entries ``offsets[c]:offsets[c+1]``.
    weights : ndarray, shape (E,) float64
        Blend weight of each entry; a receiver's weights sum to 1.
    radii : ndarray, shape (C,)
        Each cluster's bounding radius about its centre, covering its entries.
    """

    order: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray
    radii: np.ndarray


def blend_entries(points, clusters: ReceiverClusters, centers, radii, labels,
                  band: float) -> BlendEntries:
    """The (receiver, cluster) entries of a blend over clusters of band ``band``.

    Parameters
    ----------
    points : array_like, shape (V, 3)
    clusters : ReceiverClusters
    centers, radii : ndarray, shapes (C, 3), (C,)
        The clusters' bounding spheres (:meth:`ReceiverClusters.bounds`).
    labels : ndarray of int, shape (C,)
        Each cluster's label: only clusters of equal labels are blended.
    band : float
        Blend band as a fraction of a cluster's radius (> 0).
    """
    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(centers, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    lab = np.asarray(labels)
    h = np.maximum(band * r, 1e-12)  # (C,) each cluster's band
    # Candidates of cluster a's receivers: every same-label cluster whose centre is
    # within 2 r_a + h_c of a's.  A receiver of a has d_a <= r_a, so the nearest
    # centre (d <= d_a) and every centre within d_min + h_c of it pass: the blend
    # below is the one over all clusters, whatever cluster the receiver is in.
    sq = np.einsum("cx,cx->c", c, c)
    gap = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * (c @ c.T), 0.0))  # (C, C)
    cand = (gap <= 2.0 * r[:, None] + h[None, :]) & (lab[:, None] == lab[None, :])
    k = int(cand.sum(axis=1).max())
    cand_idx = np.argsort(~cand, axis=1, kind="stable")[:, :k]  # (C, K)
    cand_ok = np.take_along_axis(cand, cand_idx, axis=1)
    own = clusters.labels
    # candidate-major (K, V): the reductions over candidates run along rows
    idx = np.take(np.ascontiguousarray(cand_idx.T), own, axis=1)
    # distances by coordinate, relative to the points' mean, in float32 (a blend
    # weight needs no more; it stays continuous): 1-D gathers, no (V, K, 3) array
    o = p.mean(axis=0)
    d2 = np.zeros(idx.shape, dtype=np.float32)
    for axis in range(3):
        delta = np.take((c[:, axis] - o[axis]).astype(np.float32), idx)
        delta -= (p[:, axis] - o[axis]).astype(np.float32)
        delta *= delta
        d2 += delta
    d = np.sqrt(d2)
    d[~np.take(np.ascontiguousarray(cand_ok.T), own, axis=1)] = np.inf
    t = d - d.min(axis=0)
    t /= np.take(h.astype(np.float32), idx)
    ki, vi = np.nonzero(t < 1.0)  # (inf where not a candidate)
    s = t[ki, vi]
    raw = 1.0 - smoothstep(s)
    entry_cluster = idx[ki, vi]
    # by cluster, receivers ascending within (a tile's receivers are neighbours)
    by_cluster = np.argsort(entry_cluster * p.shape[0] + vi)
    entry_cluster = entry_cluster[by_cluster]
    order = vi[by_cluster]
    # normalised in float64: a receiver's weights sum to 1 to rounding
    weights = raw.astype(np.float64)
    weights /= np.bincount(vi, weights=weights, minlength=p.shape[0])[vi]
    weights = weights[by_cluster]
    counts = np.bincount(entry_cluster, minlength=c.shape[0])
    offsets = np.concatenate([[0], np.cumsum(counts)])
    reach = np.zeros(c.shape[0], dtype=np.float32)
    np.maximum.at(reach, entry_cluster, d[ki, vi][by_cluster])
    return BlendEntries(order, offsets, weights, np.maximum(reach.astype(np.float64), r))


def blend_rows(values, order, weights, n_rows: int) -> np.ndarray:
    """``out[v] = sum_e weights[e] values[e]`` over the entries ``e`` of receiver ``v``.

    Parameters
    ----------
    values : ndarray, shape (E, K)
        One row per entry.
    order : ndarray of int, shape (E,)
        Receiver row of each entry (every row in ``0..n_rows-1`` at least once).
    weights : ndarray, shape (E,)
    n_rows : int

    Returns
    -------
    ndarray, shape (n_rows, K), the dtype of ``values``
        Summed in the entries' order within each receiver (the same bytes however
        the entries were computed).
    """
    by_row = np.argsort(order, kind="stable")
    rows = order[by_row]
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    if starts.size != n_rows:
        raise ValueError(f"entries cover {starts.size} of {n_rows} receivers")
    scaled = np.take(values, by_row, axis=0) * weights[by_row, None].astype(values.dtype)
    return np.add.reduceat(scaled, starts, axis=0)
