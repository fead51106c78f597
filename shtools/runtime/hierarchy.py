r"""Sphere hierarchies over receiver clusters (SHEXP Sec. 6.3).

Every frame:

1. the inner spheres of each blocker tree are refit bottom-up from the moved
   leaves (:func:`shtools.runtime.spheres.refit_tree`);
2. per receiver cluster (bounding sphere :math:`(p_R, r_R)`) a *cut* is taken:
   a node is used when it passes eq. 36,
   :math:`r_i < \sin\theta_{max}\,(\|P_i - p_R\| - r_R)`, and no ancestor
   does; otherwise the search recurses to its children (a leaf that fails is
   used as is);
3. for each inner node of a cut, the ratio vector of eq. 37 rescales, per
   band, the node's log vector at the cluster centre :math:`p^* = p_R` to the
   least-squares best match of the sum of its leaves' log vectors there (leaves
   subtending less than :math:`\theta_{min}` at :math:`p^*` are skipped).

The per-vertex accumulation (eq. 38) then runs over the cut with these weights.
Several blockers form a forest: their trees are concatenated, and a blocker
without a tree contributes its spheres as single-node trees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shtools.runtime.blockers import SphereBlocker
from shtools.runtime.log_table import CapLogTable
from shtools.runtime.spheres import refit_tree

#: |f*_l(theta)| below this (relative to the band's largest value) leaves w_l = 1:
#: the bounding sphere has no content in that band to rescale.
RATIO_DENOMINATOR_FLOOR = 1e-9


@dataclass
class Forest:
    """All blocker spheres of a frame as one forest.

    Attributes
    ----------
    centers, radii : ndarray, shapes (M, 3), (M,)
        Node spheres (inner nodes refit this frame).
    parent : ndarray of int, shape (M,)
        Parent node (-1 for roots).
    leaf : ndarray of int, shape (M,)
        Index into the concatenated leaf spheres, -1 for inner nodes.
    levels : list of ndarray
        Node indices by depth, roots first.
    leaf_nodes : ndarray of int, shape (N,)
        Node of each leaf sphere.
    blocker : ndarray of int, shape (M,)
        Index of the blocker (in the list given to :func:`build_forest`) of each node.
    """

    centers: np.ndarray
    radii: np.ndarray
    parent: np.ndarray
    leaf: np.ndarray
    levels: list
    leaf_nodes: np.ndarray
    blocker: np.ndarray

    @property
    def n_nodes(self) -> int:
        return int(self.parent.shape[0])

    @property
    def is_leaf(self) -> np.ndarray:
        return self.leaf >= 0


def leaf_spheres(blockers: list[SphereBlocker]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated leaf spheres of all blockers: ``(N, 3)``, ``(N,)``."""
    if not blockers:
        return np.zeros((0, 3)), np.zeros(0)
    return (np.concatenate([b.centers for b in blockers]),
            np.concatenate([b.radii for b in blockers]))


def build_forest(blockers: list[SphereBlocker]) -> Forest:
    """Concatenate the blockers' trees (refitting inner spheres) into one forest."""
    centers, radii, parents, leaves, owners = [], [], [], [], []
    node_off = leaf_off = 0
    for k, b in enumerate(blockers):
        n = b.n_spheres
        if b.parent is None:
            centers.append(b.centers)
            radii.append(b.radii)
            parents.append(np.full(n, -1, dtype=np.int64))
            leaves.append(np.arange(n, dtype=np.int64) + leaf_off)
            m = n
        else:
            c, r = refit_tree(b.parent, b.leaf, b.centers, b.radii)
            centers.append(np.asarray(c, dtype=np.float64))
            radii.append(np.asarray(r, dtype=np.float64))
            parents.append(np.where(b.parent >= 0, b.parent + node_off, -1))
            leaves.append(np.where(b.leaf >= 0, b.leaf + leaf_off, -1))
            m = b.parent.shape[0]
        owners.append(np.full(m, k, dtype=np.int64))
        node_off += m
        leaf_off += n
    if not centers:
        empty = np.zeros(0, dtype=np.int64)
        return Forest(np.zeros((0, 3)), np.zeros(0), empty, empty, [], empty, empty)
    parent = np.concatenate(parents)
    leaf = np.concatenate(leaves)
    depth = np.zeros(parent.shape[0], dtype=np.int64)
    anc = parent.copy()
    while (anc >= 0).any():
        up = anc >= 0
        depth[up] += 1
        anc[up] = parent[anc[up]]
    levels = [np.flatnonzero(depth == k) for k in range(int(depth.max()) + 1)]
    leaf_nodes = np.empty(leaf_off, dtype=np.int64)
    is_leaf = leaf >= 0
    leaf_nodes[leaf[is_leaf]] = np.flatnonzero(is_leaf)
    return Forest(np.concatenate(centers), np.concatenate(radii), parent, leaf, levels,
                  leaf_nodes, np.concatenate(owners))


@dataclass
class Cuts:
    """Per-cluster cuts of a forest.

    Attributes
    ----------
    in_cut : ndarray of bool, shape (C, M)
        Node used for cluster ``c``.
    owner : ndarray of int, shape (C, N)
        Cut node standing for each leaf sphere in cluster ``c``.
    """

    in_cut: np.ndarray
    owner: np.ndarray


def tree_cuts(forest: Forest, cluster_centers, cluster_radii, theta_max: float) -> Cuts:
    """Eq. 36 cuts for every receiver cluster (vectorised over clusters and nodes).

    Parameters
    ----------
    forest : Forest
    cluster_centers : ndarray, shape (C, 3)
    cluster_radii : ndarray, shape (C,)
    theta_max : float
        Angular-radius threshold in radians.

    Returns
    -------
    Cuts
    """
    pc = np.asarray(cluster_centers, dtype=np.float64)
    rc = np.asarray(cluster_radii, dtype=np.float64)
    # node-major (M, C): each level's parent lookups gather contiguous rows; summed
    # component by component (x^2 + y^2 + z^2, the order of a sum over the last axis of
    # 3, without its strided (M, C, 3) temporaries)
    fc = forest.centers
    dist = np.subtract.outer(fc[:, 0], pc[:, 0])
    dist *= dist
    for k in (1, 2):
        dk = np.subtract.outer(fc[:, k], pc[:, k])
        dk *= dk
        dist += dk
    np.sqrt(dist, out=dist)  # (M, C)
    passes = forest.radii[:, None] < math.sin(theta_max) * (dist - rc[None, :])
    blocked = np.zeros_like(passes)
    owner_node = np.full(passes.shape, -1, dtype=np.int64)
    is_leaf = forest.is_leaf
    in_cut = np.zeros_like(passes)
    for k, nodes in enumerate(forest.levels):
        if k > 0:
            par = forest.parent[nodes]
            blocked[nodes] = blocked[par] | passes[par]
        in_cut[nodes] = ~blocked[nodes] & (passes[nodes] | is_leaf[nodes][:, None])
        inherited = owner_node[forest.parent[nodes]] if k > 0 else -1
        owner_node[nodes] = np.where(in_cut[nodes], nodes[:, None], inherited)
    return Cuts(np.ascontiguousarray(in_cut.T),
                np.ascontiguousarray(owner_node[forest.leaf_nodes].T))


def ratio_weights(forest: Forest, cuts: Cuts, cluster_centers, table: CapLogTable,
                  theta_min: float, skip: np.ndarray | None = None) -> np.ndarray:
    """Eq. 37 ratio vectors of the inner cut nodes.

    Parameters
    ----------
    forest : Forest
    cuts : Cuts
    cluster_centers : ndarray, shape (C, 3)
        The points ``p*`` where bounding and detailed logs are compared.
    table : CapLogTable
        Log table of the accumulation order ``n``.
    theta_min : float
        Leaves subtending less than this at ``p*`` are left out of the detailed sum.
    skip : ndarray of bool, shape (C, M), optional
        (cluster, node) pairs whose weights are not needed (left at ones): nodes
        the cluster's receivers skip.  The others do not depend on it.

    Returns
    -------
    weights : ndarray, shape (C, M, n)
        ``w_l`` for every (cluster, node); ones where not an inner cut node.
    """
    n = table.order
    pc = np.asarray(cluster_centers, dtype=np.float64)
    n_c = pc.shape[0]
    weights = np.ones((n_c, forest.n_nodes, n))
    c_idx, j_idx = np.nonzero(cuts.owner != forest.leaf_nodes[None, :])
    o_idx = cuts.owner[c_idx, j_idx]
    if skip is not None:
        kept = ~skip[c_idx, o_idx]
        c_idx, j_idx, o_idx = c_idx[kept], j_idx[kept], o_idx[kept]
    if c_idx.size == 0:
        return weights
    # By the addition theorem, sum_m y_lm(s_b) y_lm(s_j) = (2l+1)/(4 pi) P_l(s_b . s_j),
    # so the band-l projection of a leaf's log vector on the bounding direction is
    # f*_l(theta_j) P_l(cos gamma_j) (2l+1)/(4 pi): no n*n basis per pair is needed.
    # (np.take gathers rows several times faster than fancy indexing)
    leaf_j = np.take(forest.leaf_nodes, j_idx)
    leaf_c = np.take(forest.centers, leaf_j, axis=0)
    leaf_r = np.take(forest.radii, leaf_j)
    at = np.take(pc, c_idx, axis=0)
    s_leaf, zh_leaf, d_leaf = _cap(at, leaf_c, leaf_r, table)
    s_bound = _direction(at, np.take(forest.centers, o_idx, axis=0))[0]
    # leaves subtending less than theta_min at p* are left out of the detailed sum
    zh_leaf[leaf_r <= np.sin(theta_min) * d_leaf] = 0.0
    cos_gamma = np.clip(np.einsum("ij,ij->i", s_leaf, s_bound), -1.0, 1.0)
    legendre = _legendre(cos_gamma, n)  # (n, P)
    # sums per (cluster, node) by bincount over the flat key (in the pairs' order, as
    # a sort-based unique would give them, without the sort)
    key = c_idx * forest.n_nodes + o_idx
    size = n_c * forest.n_nodes
    uniq = np.flatnonzero(np.bincount(key, minlength=size))
    num = np.stack([np.bincount(key, weights=zh_leaf[:, l] * legendre[l], minlength=size)[uniq]
                    for l in range(n)], axis=1)
    uc, uo = uniq // forest.n_nodes, uniq % forest.n_nodes
    # bounding: w_l = (sum over leaves) / f*_l(theta_b)
    _, zh_b, _ = _cap(pc[uc], forest.centers[uo], forest.radii[uo], table)
    floor = RATIO_DENOMINATOR_FLOOR * np.abs(table.values64).max(axis=1)
    ok = np.abs(zh_b) > floor[None, :]
    w = np.where(ok, num / np.where(ok, zh_b, 1.0), 1.0)
    weights[uc, uo] = w
    return weights


def _legendre(x, order: int) -> np.ndarray:
    """Legendre polynomials ``P_0 .. P_{n-1}`` at ``x``, shape ``(n, ...)`` (band-major:
    each band's recurrence step runs on contiguous values)."""
    out = np.empty((order, *np.shape(x)))
    out[0] = 1.0
    if order > 1:
        out[1] = x
    for l in range(2, order):
        out[l] = ((2 * l - 1) * x * out[l - 1] - (l - 1) * out[l - 2]) / l
    return out


def _direction(points, centers):
    """Unit directions ``(P, 3)`` from points to centres and distances ``(P,)``."""
    delta = centers - points
    d = np.sqrt(np.einsum("ij,ij->i", delta, delta))
    d = np.maximum(d, 1e-300)
    return delta / d[:, None], d


def _cap(points, centers, radii, table: CapLogTable):
    """Direction ``(P, 3)``, zonal log ``f*_l`` ``(P, n)`` and distance ``(P,)`` of spheres."""
    s, d = _direction(points, centers)
    sin2 = np.minimum((radii / d) ** 2, 1.0)
    return s, table.lookup64_x(sin2 / (1.0 + np.sqrt(1.0 - sin2))), d  # 1 - cos(theta)
