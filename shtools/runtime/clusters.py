"""Receiver clustering (Sec. 6.3): Lloyd (k-means) on receiver positions.

Clusters are computed once (on the first frame's positions) and reused across
frames; their bounding spheres are recomputed from the current positions every
frame (:meth:`ReceiverClusters.bounds`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError

#: Lloyd iterations; assignments on receiver meshes settle within a few.
LLOYD_ITERATIONS = 8
#: Points per distance block in the assignment step (bounds memory).
_ASSIGN_BLOCK = 1 << 16


@dataclass(frozen=True)
class ReceiverClusters:
    """A partition of the receiver vertices into clusters.

    Attributes
    ----------
    labels : ndarray of int, shape (V,)
        Cluster of each vertex, ``0..C-1``.
    order : ndarray of int, shape (V,)
        Vertex indices sorted by cluster.
    offsets : ndarray of int, shape (C + 1,)
        Cluster ``c`` holds ``order[offsets[c]:offsets[c+1]]``.
    groups : ndarray of int, shape (C,) or None
        The object group of each cluster (``groups`` of :func:`lloyd_clusters`);
        None: unknown (one group).
    """

    labels: np.ndarray
    order: np.ndarray
    offsets: np.ndarray
    groups: np.ndarray | None = None

    @property
    def n_clusters(self) -> int:
        """Number of clusters ``C``."""
        return int(self.offsets.shape[0] - 1)

    @property
    def n_vertices(self) -> int:
        """Number of receiver vertices ``V``."""
        return int(self.labels.shape[0])

    @classmethod
    def from_labels(cls, labels, groups=None) -> ReceiverClusters:
        """Build from per-vertex labels (relabelled to ``0..C-1``, empty clusters dropped).

        ``groups``: the object group of each label value (indexed by the labels as
        given, e.g. the ``groups`` of the clusters the labels come from), or None.
        """
        labels = np.asarray(labels)
        kept, dense = np.unique(labels, return_inverse=True)
        dense = dense.astype(np.int64)
        order = np.argsort(dense, kind="stable")
        counts = np.bincount(dense)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        return cls(dense, order, offsets,
                   None if groups is None else np.asarray(groups)[kept])

    def split(self, labels) -> ReceiverClusters:
        """These clusters split so that each holds vertices of one label only (self when
        they already do).  Labels ``(V,)`` of int, e.g. the blockers each vertex skips:
        a traced shadow that covers only part of a cluster."""
        labels = np.asarray(labels)
        counts = np.diff(self.offsets)
        first = labels[self.order[self.offsets[:-1]]]
        if np.array_equal(labels[self.order], np.repeat(first, counts)):
            return self
        # one int64 key per (cluster, label) pair, ordered as the pairs are
        # lexicographically (a 1-D unique: many times faster than unique rows)
        lab = labels.astype(np.int64) - int(labels.min())
        out = ReceiverClusters.from_labels(self.labels * (int(lab.max()) + 1) + lab)
        if self.groups is None:
            return out
        first = out.order[out.offsets[:-1]]  # a vertex of each new cluster
        return ReceiverClusters(out.labels, out.order, out.offsets,
                                self.groups[self.labels[first]])

    def bounds(self, vertices) -> tuple[np.ndarray, np.ndarray]:
        """Bounding sphere of every cluster at the given positions.

        Parameters
        ----------
        vertices : array_like, shape (V, 3)

        Returns
        -------
        centers : ndarray, shape (C, 3)
            Cluster centroids (``p_R`` of eq. 36, also the ratio-vector point ``p*``).
        radii : ndarray, shape (C,)
            Largest distance of a cluster vertex from its centroid (``r_R``).
        """
        v = np.asarray(vertices, dtype=np.float64)
        if v.shape != (self.n_vertices, 3):
            raise InputError(
                f"receiver clusters were built for {self.n_vertices} vertices, got {v.shape[0]}"
            )
        counts = np.diff(self.offsets)
        sums = np.stack([np.bincount(self.labels, v[:, k], minlength=counts.size)
                         for k in range(3)], axis=1)
        centers = sums / counts[:, None]
        rel = v - np.take(centers, self.labels, axis=0)  # (a gather faster than [labels])
        dist = np.sqrt(rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1] + rel[:, 2] * rel[:, 2])
        radii = np.maximum.reduceat(dist[self.order], self.offsets[:-1])
        return centers, radii


def lloyd_clusters(vertices, vertices_per_cluster: int = 400, *, groups=None,
                   iterations: int = LLOYD_ITERATIONS, seed: int = 0) -> ReceiverClusters:
    """Cluster receiver vertices with Lloyd's algorithm.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
        Receiver positions (e.g. the first frame).
    vertices_per_cluster : int
        Average cluster size; ``C = ceil(V / vertices_per_cluster)`` per group.
    groups : array_like of int, shape (V,), optional
        Object id per vertex; clusters never mix groups (a cluster spanning a
        moving character and the ground would get a needlessly large bound).
    iterations : int
        Lloyd iterations.
    seed : int
        Seed of the initial centre choice (deterministic).

    Returns
    -------
    ReceiverClusters
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise InputError("receiver vertices must be a finite (V, 3) array")
    if groups is None:
        groups = np.zeros(v.shape[0], dtype=np.int64)
    groups = np.asarray(groups)
    if groups.shape != (v.shape[0],):
        raise InputError(f"groups must have shape ({v.shape[0]},), got {groups.shape}")
    labels = np.zeros(v.shape[0], dtype=np.int64)
    next_label = 0
    rng = np.random.default_rng(seed)
    cluster_groups = []
    for k_group, g in enumerate(np.unique(groups)):
        idx = np.flatnonzero(groups == g)
        k = max(1, int(np.ceil(idx.size / vertices_per_cluster)))
        local = _kmeans(v[idx], k, iterations, rng)
        labels[idx] = local + next_label
        next_label += k
        cluster_groups.append(np.full(k, k_group, dtype=np.int64))
    # (from_labels drops empty clusters and keeps the group of each one left)
    return ReceiverClusters.from_labels(
        labels, np.concatenate(cluster_groups) if cluster_groups else None)


def _kmeans(points: np.ndarray, k: int, iterations: int, rng) -> np.ndarray:
    """Lloyd iterations from a random (seeded) choice of ``k`` distinct points.

    After the first assignment, only the points that may change centre are compared
    with the centres again (G. Hamerly, "Making k-means even faster", SIAM SDM 2010):
    a point provably keeps its centre when an upper bound on the distance to it is
    below both a lower bound on the distance to every other centre and half the
    distance from its centre to the nearest other one, the bounds moved by how far
    the centres move.  The labels are Lloyd's, as if every point were compared with
    every centre.
    """
    if k == 1:
        return np.zeros(points.shape[0], dtype=np.int64)
    centers = points[rng.choice(points.shape[0], size=k, replace=False)].copy()
    # a slack far above the rounding of the distances (|p|^2 + |c|^2 - 2 p.c loses
    # ~1e-16 |p|^2 to cancellation) and far below any gap the bounds decide on
    slack = _SLACK * (float(np.abs(points).max()) + 1e-300)
    labels, upper, lower = _assign(points, centers)
    for _ in range(iterations):
        counts = np.bincount(labels, minlength=k)
        sums = np.stack([np.bincount(labels, points[:, j], minlength=k) for j in range(3)], 1)
        nonempty = counts > 0
        moved_to = centers.copy()
        moved_to[nonempty] = sums[nonempty] / counts[nonempty, None]
        moved = np.sqrt(((moved_to - centers) ** 2).sum(axis=1))
        centers = moved_to
        upper += moved[labels]
        fastest = int(np.argmax(moved))
        lower -= np.where(labels == fastest, np.max(np.delete(moved, fastest)), moved[fastest])
        gap = np.sqrt(((centers[:, None, :] - centers[None, :, :]) ** 2).sum(axis=2))
        np.fill_diagonal(gap, np.inf)
        bound = np.maximum(0.5 * gap.min(axis=1)[labels], lower) - slack
        doubt = np.flatnonzero(upper > bound)
        if doubt.size:  # the exact distance to the own centre first
            rel = points[doubt] - centers[labels[doubt]]
            upper[doubt] = np.sqrt((rel * rel).sum(axis=1))
            doubt = doubt[upper[doubt] > bound[doubt]]
        if not doubt.size:
            break
        old = labels[doubt]
        labels[doubt], upper[doubt], lower[doubt] = _assign(points[doubt], centers)
        if np.array_equal(labels[doubt], old):
            break
    return labels


#: Slack of :func:`_kmeans`'s bounds, relative to the largest coordinate.
_SLACK = 1e-9


def _assign(points: np.ndarray, centers: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest centre per point, in blocks, and the distances to it and to the second
    nearest (``(P,)`` each; with one centre, the second is infinitely far)."""
    out = np.empty(points.shape[0], dtype=np.int64)
    first = np.empty(points.shape[0])
    second = np.full(points.shape[0], np.inf)
    c2 = np.einsum("ij,ij->i", centers, centers)
    step = max(1, _ASSIGN_BLOCK // centers.shape[0])
    for s in range(0, points.shape[0], step):
        p = points[s : s + step]
        d = c2[None, :] - 2.0 * (p @ centers.T)
        at = np.argmin(d, axis=1)
        out[s : s + step] = at
        rel = p - centers[at]
        first[s : s + step] = np.sqrt((rel * rel).sum(axis=1))
        if centers.shape[0] > 1:
            p2 = np.einsum("ij,ij->i", p, p)
            d[np.arange(len(at)), at] = np.inf
            second[s : s + step] = np.sqrt(np.maximum(p2 + d.min(axis=1), 0.0))
    return out, first, second
