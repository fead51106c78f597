"""Bounding-sphere hierarchies over sphere sets (SHEXP section 6.3).

Levels are built bottom-up, one at a time, by Lloyd clustering of the current
level's spheres: each sphere is assigned to the cluster whose bounding-sphere
centre is closest to its centre; each cluster's bounding sphere is then the
minimal sphere containing its members' SPHERES (centre initialised at the mean
of the member centres, then optimised, :func:`minimal_enclosing_sphere`).
Clusters become parents, their members children.  Each level has
``ceil(n / branching)`` clusters, so the average branching ratio is about
``branching`` (4 in the paper) up to a single root.

Node order: leaves first (node ``i`` is sphere ``i``), then each level, the root
last; ``parent[m] > m``.
"""

from __future__ import annotations

import numpy as np

from shtools.data_formats.tree import SphereTree, children_csr, node_heights
from shtools.geometry.bounding import minimal_enclosing_sphere

__all__ = ["SphereTree", "build_tree", "check_tree", "tree_statistics"]

#: Lloyd iterations per level; assignments usually settle in under ten.
MAX_LLOYD_ITERATIONS = 30
#: relative slack of the child-in-parent test (solver and rounding noise)
CONTAINMENT_RTOL = 1e-9


def _kmeans_pp(points: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k-means++ seeding: indices ``(k,)`` of distinct points."""
    n = points.shape[0]
    chosen = [int(rng.integers(n))]
    d2 = np.sum((points - points[chosen[0]]) ** 2, axis=1)
    for _ in range(1, k):
        total = d2.sum()
        if total <= 0:  # coincident points: take any not yet chosen
            rest = np.setdiff1d(np.arange(n), chosen)
            nxt = int(rest[0])
        else:
            nxt = int(rng.choice(n, p=d2 / total))
        chosen.append(nxt)
        d2 = np.minimum(d2, np.sum((points - points[nxt]) ** 2, axis=1))
    return np.asarray(chosen)


class _BoundCache:
    """Minimal bounding spheres of member sets, memoised across Lloyd iterations."""

    def __init__(self, centers: np.ndarray, radii: np.ndarray):
        self.centers = centers
        self.radii = radii
        self.memo: dict[bytes, tuple[np.ndarray, float]] = {}

    def __call__(self, members: np.ndarray) -> tuple[np.ndarray, float]:
        key = members.tobytes()
        hit = self.memo.get(key)
        if hit is None:
            c = self.centers[members]
            hit = minimal_enclosing_sphere(c, self.radii[members], initial_center=c.mean(axis=0))
            self.memo[key] = hit
        return hit


def _lloyd_level(centers, radii, k, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cluster one level's spheres into ``k`` bounding spheres.

    Returns
    -------
    labels : ndarray of int, shape (n,)
        Dense cluster index ``0..k'-1`` (``k' <= k``; empty clusters are dropped).
    cluster_centers : ndarray, shape (k', 3)
    cluster_radii : ndarray, shape (k',)
    """
    n = centers.shape[0]
    bound = _BoundCache(centers, radii)
    if k <= 1:
        c, r = bound(np.arange(n))
        return np.zeros(n, dtype=np.int64), c[None, :], np.array([r])
    cc = centers[_kmeans_pp(centers, k, rng)].copy()
    cr = np.zeros(k)
    labels = np.full(n, -1)
    seen: set[bytes] = set()
    for _ in range(MAX_LLOYD_ITERATIONS):
        d2 = np.sum((centers[:, None, :] - cc[None, :, :]) ** 2, axis=2)
        new = np.argmin(d2, axis=1)
        # refill empty clusters with the sphere reaching farthest out of its cluster
        counts = np.bincount(new, minlength=k)
        for empty in np.flatnonzero(counts == 0):
            reach = np.sqrt(d2[np.arange(n), new]) + radii
            reach[counts[new] <= 1] = -np.inf
            donor = int(np.argmax(reach))
            counts[new[donor]] -= 1
            new[donor] = empty
            counts[empty] = 1
        key = new.tobytes()
        if np.array_equal(new, labels) or key in seen:
            labels = new
            break
        seen.add(key)
        labels = new
        for j in range(k):
            cc[j], cr[j] = bound(np.flatnonzero(labels == j))
    for j in range(k):
        cc[j], cr[j] = bound(np.flatnonzero(labels == j))
    used = np.unique(labels)
    remap = np.full(k, -1)
    remap[used] = np.arange(used.size)
    return remap[labels], cc[used], cr[used]


def build_tree(centers, radii, branching: int = 4, seed: int = 0, progress=None) -> SphereTree:
    """Build a sphere hierarchy whose leaves are the given spheres.

    Parameters
    ----------
    centers : array_like, shape (N, 3)
    radii : array_like, shape (N,)
    branching : int
        Target average number of children per inner node (>= 2).
    seed : int
        Seed of the k-means++ initialisation; same seed -> identical tree.
    progress : callable, optional
        A progress factory (:mod:`shtools.progress`); counts spheres clustered
        over all levels (a level's Lloyd work grows with its sphere count).

    Returns
    -------
    SphereTree
        ``M`` nodes; nodes ``0..N-1`` are the leaves (``leaf[i] == i``), the root
        is node ``M-1``.  Every parent is the minimal sphere bounding its
        children's spheres.
    """
    centers = np.asarray(centers, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    if centers.ndim != 2 or centers.shape[1] != 3 or centers.shape[0] == 0:
        raise ValueError(f"centers must have shape (N, 3) with N >= 1, got {centers.shape}")
    if radii.shape != (centers.shape[0],):
        raise ValueError("radii must have shape (N,)")
    if not (np.all(np.isfinite(centers)) and np.all(np.isfinite(radii)) and np.all(radii >= 0)):
        raise ValueError("centers and radii must be finite, radii non-negative")
    if branching < 2:
        raise ValueError("branching must be at least 2")
    rng = np.random.default_rng(seed)
    n = centers.shape[0]
    all_c, all_r = [centers], [radii]
    parents = [np.full(n, -1, dtype=np.int64)]
    level_c, level_r, offset = centers, radii, 0
    sizes = [n]  # sphere count of every level that gets clustered, known up front
    while sizes[-1] > 1:
        sizes.append(int(np.ceil(sizes[-1] / branching)))
    from shtools.progress import silent

    bar = (progress or silent)(total=sum(sizes[:-1]), desc="tree", unit="spheres")
    while level_c.shape[0] > 1:
        count = level_c.shape[0]
        k = int(np.ceil(count / branching))
        labels, cc, cr = _lloyd_level(level_c, level_r, k, rng)
        bar.update(count)
        next_offset = offset + count
        parents[-1] = next_offset + labels
        all_c.append(cc)
        all_r.append(cr)
        parents.append(np.full(cc.shape[0], -1, dtype=np.int64))
        level_c, level_r, offset = cc, cr, next_offset
    bar.close()
    m = sum(p.size for p in parents)
    leaf = np.full(m, -1, dtype=np.int32)
    leaf[:n] = np.arange(n)
    return SphereTree(
        centers=np.concatenate(all_c),
        radii=np.concatenate(all_r),
        parent=np.concatenate(parents).astype(np.int32),
        leaf=leaf,
    )


def check_tree(tree: SphereTree, rtol: float = CONTAINMENT_RTOL) -> float:
    """Largest child-outside-parent excess, relative to the parent's radius.

    Returns
    -------
    float
        ``max (|c_p - c_c| + r_c - r_p) / r_p`` over child/parent pairs; ``<= rtol``
        means every child sphere lies inside its parent.
    """
    child = np.flatnonzero(tree.parent >= 0)
    p = tree.parent[child]
    excess = (np.linalg.norm(tree.centers[child] - tree.centers[p], axis=1)
              + tree.radii[child] - tree.radii[p])
    return float(np.max(excess / np.maximum(tree.radii[p], 1e-300), initial=-np.inf))


def tree_statistics(tree: SphereTree) -> dict:
    """Counts for reports: nodes, leaves, levels, average/max branching, containment."""
    offsets, _ = children_csr(tree.parent)
    kids = np.diff(offsets)
    inner = kids[kids > 0]
    return {
        "nodes": len(tree),
        "leaves": int(np.count_nonzero(tree.leaf >= 0)),
        "levels": int(node_heights(tree.parent).max(initial=0)) + 1,
        "average_branching": float(inner.mean()) if inner.size else 0.0,
        "max_branching": int(inner.max(initial=0)),
        "root_radius": float(tree.radii[tree.root]),
        "max_containment_excess": check_tree(tree),
    }
