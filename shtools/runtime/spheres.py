"""Per-frame sphere updates for the runtime: tree refit and skinned sphere centres.

NumPy only (the runtime's import rule).

- :func:`refit_tree` recomputes every inner node of a sphere hierarchy from its
  (moved) leaves, bottom-up, by merging children with the sphere-pair bound
  (SHEXP section 6.3, "Construction and Animation").  Vectorised per tree level:
  children of all nodes at one height are merged in ``ceil(log2(B))`` pairwise
  rounds (B the largest child count at that height), then each parent's radius
  is tightened to ``max_i |c - c_i| + r_i`` about the merged centre, which keeps
  the bound and never enlarges it; a few cheap centre-improvement steps follow
  (:data:`REFINE_STEPS`), each accepted only if it shrinks the radius, so the
  result is never worse than the plain pair merge.
- :func:`pose_bound_spheres` poses sphere centres bound to a skin
  (:mod:`shtools.geometry.binding`): ``P' = sum_k M_{j_k} q_k``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.data_formats.tree import node_heights

__all__ = ["RefitPlan", "plan_refit", "pose_bound_spheres", "refit_tree", "sphere_pair_bound"]


_TINY = 1e-300


def sphere_pair_bound(c1, r1, c2, r2) -> tuple[np.ndarray, np.ndarray]:
    """Smallest sphere enclosing two spheres (exact), batched.

    Parameters
    ----------
    c1, c2 : array_like, shape (..., 3)
    r1, r2 : array_like, shape (...)

    Returns
    -------
    center : ndarray, shape (..., 3)
    radius : ndarray, shape (...)
        If one sphere contains the other it is returned; otherwise the sphere
        with diameter from the far side of one to the far side of the other:
        ``r = (d + r1 + r2) / 2``, centre on the segment between the centres.
    """
    c1 = np.asarray(c1, dtype=np.float64)
    c2 = np.asarray(c2, dtype=np.float64)
    r1 = np.asarray(r1, dtype=np.float64)
    r2 = np.asarray(r2, dtype=np.float64)
    delta = c2 - c1
    d = np.sqrt(np.einsum("...i,...i->...", delta, delta))
    # max(.) covers containment: d + r2 <= r1 gives r1 (and t = 0 below),
    # d + r1 <= r2 gives r2 (and t >= 1, clipped: the centre is c2)
    radius = np.maximum(np.maximum(0.5 * (d + r1 + r2), r1), r2)
    t = np.clip((radius - r1) / np.maximum(d, _TINY), 0.0, 1.0)
    center = c1 + t[..., None] * delta
    return center, radius


@dataclass(frozen=True)
class RefitPlan:
    """Precomputed level structure of a tree for :func:`refit_tree`.

    Attributes
    ----------
    leaf_nodes : ndarray of int, shape (N,)
        Nodes that are leaves.
    leaf_sets : ndarray of int, shape (N,)
        Sphere-set index of each of ``leaf_nodes``.
    levels : tuple of (nodes (P,), children (P, B))
        Inner nodes per height, bottom-up; ``children`` padded with each row's
        first child (merging a sphere already included changes nothing).
    """

    leaf_nodes: np.ndarray
    leaf_sets: np.ndarray
    levels: tuple


#: Centre improvement steps per level after the pair merge.  Starting from the
#: merged centre, each step moves the centre 1/4, 1/8, ... of the way to the
#: farthest-reaching child and is kept only if the enclosing radius drops (rigidly
#: equivariant, unlike e.g. a bounding-box centre).  On a 250-leaf tree, 4 steps
#: bring inner radii from 1.065 (pair merge alone) to 1.015 times the optimal
#: bound on average (max 1.09 instead of 1.23), see benchmarks/bench_tree.py.
REFINE_STEPS = 4

_PLAN_CACHE: dict[bytes, RefitPlan] = {}
_PLAN_CACHE_SIZE = 32


def plan_refit(parent, leaf) -> RefitPlan:
    """Level structure of a tree (cached by the arrays' contents).

    Parameters
    ----------
    parent : array_like of int, shape (M,)
        Parent node, ``-1`` at the root.
    leaf : array_like of int, shape (M,)
        Sphere-set index for leaves, ``-1`` for inner nodes.

    Returns
    -------
    RefitPlan

    Raises
    ------
    ValueError
        If an inner node has no children or the parent array is not a tree.
    """
    parent = np.ascontiguousarray(parent, dtype=np.int64)
    leaf = np.ascontiguousarray(leaf, dtype=np.int64)
    key = parent.tobytes() + b"|" + leaf.tobytes()
    plan = _PLAN_CACHE.get(key)
    if plan is not None:
        return plan
    m = parent.shape[0]
    if leaf.shape != (m,):
        raise ValueError("parent and leaf must have the same length")
    counts = np.bincount(parent[parent >= 0], minlength=m)
    if np.any((counts == 0) & (leaf < 0)) or np.any((counts > 0) & (leaf >= 0)):
        raise ValueError("inner nodes need children and leaves must have none")
    height = node_heights(parent)
    levels = []
    nonroot = np.flatnonzero(parent >= 0)
    for h in range(1, int(height.max(initial=0)) + 1):
        nodes = np.flatnonzero(height == h)
        kids_all = nonroot[np.isin(parent[nonroot], nodes)]
        kids_all = kids_all[np.argsort(parent[kids_all], kind="stable")]
        row = np.searchsorted(nodes, parent[kids_all])
        n_kids = np.bincount(row, minlength=nodes.size)
        width = int(n_kids.max())
        start = np.zeros(nodes.size, dtype=np.int64)
        np.cumsum(n_kids[:-1], out=start[1:])
        col = np.arange(kids_all.size) - start[row]
        children = np.repeat(kids_all[start][:, None], width, axis=1)
        children[row, col] = kids_all
        levels.append((nodes, children))
    plan = RefitPlan(
        leaf_nodes=np.flatnonzero(leaf >= 0), leaf_sets=leaf[leaf >= 0], levels=tuple(levels)
    )
    if len(_PLAN_CACHE) >= _PLAN_CACHE_SIZE:
        _PLAN_CACHE.pop(next(iter(_PLAN_CACHE)))
    _PLAN_CACHE[key] = plan
    return plan


def _reach(kc: np.ndarray, kr: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``|c - c_b| + r_b`` per child, shape ``(P, B)``."""
    delta = kc - c[:, None, :]
    return np.sqrt(np.einsum("pbi,pbi->pb", delta, delta)) + kr


def _merge_children(kc: np.ndarray, kr: np.ndarray):
    """Sphere-pair bound merging of each row's children, as a pairwise reduction.

    Returns the merged centre ``(P, 3)``, the radius tightened about it
    (``max_b |c - c_b| + r_b``, never larger than the merged radius) and the
    per-child reach ``(P, B)`` about that centre.
    """
    c, r = kc, kr
    while c.shape[1] > 1:
        half = (c.shape[1] + 1) // 2
        tail = c.shape[1] - half
        mc, mr = sphere_pair_bound(c[:, :tail], r[:, :tail], c[:, half:], r[:, half:])
        c = np.concatenate([mc, c[:, tail:half]], axis=1)
        r = np.concatenate([mr, r[:, tail:half]], axis=1)
    c = c[:, 0]
    reach = _reach(kc, kr, c)
    return c, np.minimum(r[:, 0], reach.max(axis=1)), reach


def refit_tree(parent, leaf, leaf_centers, leaf_radii, *, plan: RefitPlan | None = None,
               refine_steps: int = REFINE_STEPS):
    """Recompute a sphere hierarchy's inner spheres bottom-up from its leaves.

    Parameters
    ----------
    parent : array_like of int, shape (M,)
        Parent node, ``-1`` at the root.
    leaf : array_like of int, shape (M,)
        Index into the sphere set for leaves, ``-1`` for inner nodes.
    leaf_centers : array_like, shape (N, 3)
        Current sphere-set centres.
    leaf_radii : array_like, shape (N,)
    plan : RefitPlan, optional
        From :func:`plan_refit`; looked up in a small cache when omitted.
    refine_steps : int
        Centre improvement steps after the pair merge (0: the paper's merge only).

    Returns
    -------
    centers : ndarray, shape (M, 3)
    radii : ndarray, shape (M,)
        Every child sphere lies inside its parent (up to rounding, ~1e-15
        relative).  A parent with two children is their exact minimal bound.
    """
    if plan is None:
        plan = plan_refit(parent, leaf)
    leaf_centers = np.asarray(leaf_centers, dtype=np.float64)
    leaf_radii = np.asarray(leaf_radii, dtype=np.float64)
    m = np.shape(parent)[0]
    centers = np.empty((m, 3))
    radii = np.empty(m)
    centers[plan.leaf_nodes] = leaf_centers[plan.leaf_sets]
    radii[plan.leaf_nodes] = leaf_radii[plan.leaf_sets]
    for nodes, children in plan.levels:
        kc = centers[children]  # (P, B, 3)
        kr = radii[children]  # (P, B)
        c, r, reach = _merge_children(kc, kr)
        rows = np.arange(kc.shape[0])
        step = 0.25
        for _ in range(refine_steps):
            # move part of the way toward the farthest-reaching child; keep if smaller
            far = np.argmax(reach, axis=1)
            candidate = c + step * (kc[rows, far] - c)
            cand_reach = _reach(kc, kr, candidate)
            cand_r = cand_reach.max(axis=1)
            better = cand_r < r
            c = np.where(better[:, None], candidate, c)
            r = np.where(better, cand_r, r)
            reach = np.where(better[:, None], cand_reach, reach)
            step *= 0.5
        centers[nodes] = c
        radii[nodes] = r
    return centers, radii


def pose_bound_spheres(bone_index, bone_vectors, joint_matrices) -> np.ndarray:
    """Posed sphere centres from a skin binding.

    Parameters
    ----------
    bone_index : array_like of int, shape (N, K)
    bone_vectors : array_like, shape (N, K, 4)
        Per-bone homogeneous vectors (``bound`` asset, or
        :class:`shtools.geometry.binding.SphereBinding`).
    joint_matrices : array_like, shape (..., J, 4, 4)
        Skinning matrices (world x inverse bind); leading axes (e.g. frames)
        are batched.

    Returns
    -------
    ndarray, shape (..., N, 3)
        ``sum_k (M[bone_index[n, k]] @ bone_vectors[n, k])[:3]``.
    """
    bone_index = np.asarray(bone_index)
    q = np.asarray(bone_vectors, dtype=np.float64)
    mats = np.asarray(joint_matrices, dtype=np.float64)
    picked = mats[..., bone_index, :3, :]  # (..., N, K, 3, 4)
    return np.einsum("...nkij,nkj->...ni", picked, q)
