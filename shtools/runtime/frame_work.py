"""What one frame accumulates, and its split into parts of about equal work.

The tree cuts (SHEXP eq. 36) and ratio weights (eq. 37) per receiver cluster give
each cluster its list of spheres (:func:`frame_work`); :meth:`FrameWork.split` deals
the clusters whole into a fixed number of parts, so a part's bytes do not depend on
the process that evaluates it.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError
from shtools.runtime.cluster_blend import blend_entries, blend_rows
from shtools.runtime.clusters import ReceiverClusters
from shtools.runtime.hierarchy import build_forest, leaf_spheres, ratio_weights, tree_cuts
from shtools.runtime.log_table import CapLogTable
from shtools.runtime.parallel import split_clusters
from shtools.runtime.self_visibility import excluded_nodes


@dataclass
class FrameWork:
    """What one frame accumulates: per-cluster sphere lists, or one list for all.

    Attributes
    ----------
    centers : ndarray, shape (C, S, 3) or (S, 3)
        Cut spheres of each cluster (padded), or the leaf spheres (no hierarchy).
    radii : ndarray, shape (C, S) or (S,)
    order, offsets : ndarray of int, shapes (V,), (C + 1,) or None
        Receivers sorted by cluster and the cluster boundaries.
    sizes : ndarray of int, shape (C,) or None
        Valid spheres per cluster.
    weights : ndarray, shape (C, S, n_acc) or None
        Ratio weights (eq. 37) where inner tree nodes are used.
    blend : ndarray, shape (E,) or None
        With a blend over clusters (:mod:`shtools.runtime.cluster_blend`), ``order``
        holds ``E`` entries (a receiver once per cluster it is blended over) and
        these are their weights; None: each receiver once, in its own cluster.
    """

    centers: np.ndarray
    radii: np.ndarray
    order: np.ndarray | None = None
    offsets: np.ndarray | None = None
    sizes: np.ndarray | None = None
    weights: np.ndarray | None = None
    blend: np.ndarray | None = None

    def task(self, pts, nrm) -> tuple:
        """The whole frame as one task for :meth:`ShadowRuntime.run_part` (its result
        has a row per receiver, or per entry of a blend: :meth:`combine`)."""
        if self.order is None:
            return ("spheres", pts, nrm, self.centers, self.radii)
        if self.blend is not None:
            return ("clusters", np.take(pts, self.order, axis=0),
                    np.take(nrm, self.order, axis=0), np.arange(self.order.size),
                    self.offsets, self.centers, self.radii, self.weights, self.sizes)
        return ("clusters", pts, nrm, self.order, self.offsets, self.centers, self.radii,
                self.weights, self.sizes)

    def combine(self, values: np.ndarray, n_rows: int) -> np.ndarray:
        """A :meth:`task`'s result ``(V or E, K)`` as one row per receiver ``(V, K)``."""
        if self.blend is None or self.order is None:
            return values
        return blend_rows(values, self.order, self.blend, n_rows)

    def assemble(self, split: list, results: list, n_rows: int, n_cols: int) -> np.ndarray:
        """The results ``(R_k, n_cols)`` of :meth:`split`'s parts (in its order) as one
        row per receiver ``(n_rows, n_cols)``: placed, or blended over clusters."""
        if self.blend is not None and results:
            return blend_rows(np.concatenate(results), np.concatenate([r for r, _, _ in split]),
                              np.concatenate([w for _, w, _ in split]), n_rows)
        out = np.empty((n_rows, n_cols), dtype=results[0].dtype if results else np.float32)
        for (rows, _, _), values in zip(split, results, strict=True):
            out[rows] = values
        return out

    def split(self, pts, nrm, parts: int, receiver_cost: float = 0.0
              ) -> list[tuple[np.ndarray, np.ndarray | None, tuple]]:
        """``parts`` tasks of about equal work, with the receiver rows each covers
        and their blend weights (None without a blend over clusters).

        Clusters are dealt whole (:func:`split_clusters`, cost = receivers x
        (cut size + ``receiver_cost``, the per-receiver work of other blockers));
        without a hierarchy the receivers are cut into equal ranges.  Empty parts
        are dropped.
        """
        pts32 = np.asarray(pts, dtype=np.float32)
        nrm32 = np.asarray(nrm, dtype=np.float32)
        if self.order is None:
            bounds = np.linspace(0, pts.shape[0], parts + 1).astype(np.int64)
            return [(np.arange(a, b), None, ("spheres", pts32[a:b], nrm32[a:b], self.centers,
                                             self.radii))
                    for a, b in itertools.pairwise(bounds) if b > a]
        counts = np.diff(self.offsets)
        groups = split_clusters(counts * (self.sizes + receiver_cost), parts)
        cluster_of = np.repeat(np.arange(counts.size), counts)  # cluster of each order slot
        part_of = np.empty(counts.size, dtype=np.int64)
        for k, group in enumerate(groups):
            part_of[group] = k
        slot_part = part_of[cluster_of]
        out = []
        for k, group in enumerate(groups):
            # cluster by cluster, ascending (np.compress: faster than a boolean index)
            rows = np.compress(slot_part == k, self.order)
            if rows.size == 0:
                continue
            offsets = np.concatenate([[0], np.cumsum(counts[group])])
            blend = None if self.blend is None else np.compress(slot_part == k, self.blend)
            out.append((rows, blend, ("clusters", np.take(pts32, rows, axis=0),
                               np.take(nrm32, rows, axis=0), np.arange(rows.size),
                               offsets, self.centers[group], self.radii[group],
                               None if self.weights is None else self.weights[group],
                               self.sizes[group])))
        return out


def frame_work(settings, table: CapLogTable, pts, blockers, clusters, exclude,
               clusters_for) -> tuple[FrameWork, dict]:
    """Cuts, ratio weights and per-cluster sphere lists of a frame (this process).

    ``exclude`` (:class:`~shtools.runtime.self_visibility.Skipped`): the sphere
    blockers each receiver skips.  ``clusters_for(pts, labels)``: the receiver
    clusters when none are given (the runtime's, kept between frames).  Returns the
    work and the frame's stats (``pairs``, ``clusters``, ``seconds["cuts"]``, ...).
    """
    s = settings
    acc_order = table.order
    stats = {"pairs": 0, "pairs_evaluated": 0, "clusters": 0, "seconds": {},
             "processes": 1}
    t0 = time.process_time()
    if exclude is not None and exclude.masks.shape == (1, len(blockers)) and \
            exclude.masks.all():
        # every receiver skips every sphere set (their objects' real meshes were
        # traced on all of them): nothing to accumulate, no cuts to make
        stats["seconds"]["cuts"] = time.process_time() - t0
        stats["spheres_per_vertex"] = 0.0
        return FrameWork(centers=np.zeros((0, 3)), radii=np.zeros(0)), stats
    if not s.hierarchy and exclude is None:
        centers, radii = leaf_spheres(blockers)
        stats["seconds"]["cuts"] = time.process_time() - t0
        stats["pairs"] = stats["pairs_evaluated"] = pts.shape[0] * centers.shape[0]
        stats["spheres_per_vertex"] = float(centers.shape[0])
        return FrameWork(centers=centers, radii=radii), stats
    forest = build_forest(blockers)
    entries = None
    if not s.hierarchy:
        # every leaf everywhere, but per exclusion group: one "cluster" per group
        clusters = ReceiverClusters.from_labels(exclude.labels)
        in_cut = np.broadcast_to(forest.is_leaf, (clusters.n_clusters, forest.n_nodes))
        weights = np.ones((clusters.n_clusters, forest.n_nodes, acc_order))
    else:
        if clusters is None:
            clusters = clusters_for(
                pts, None if exclude is None else exclude.labels)
        if clusters.n_vertices != pts.shape[0]:
            raise InputError(
                f"clusters were built for {clusters.n_vertices} vertices but "
                f"{pts.shape[0]} were given; call clusters() on this receiver set"
            )
        if exclude is not None:  # a cluster's receivers must skip the same blockers
            clusters = clusters.split(exclude.labels)
        cl_centers, cl_radii = clusters.bounds(pts)
        if s.cluster_blend > 0 and clusters.n_clusters > 1:
            # blended only within an object group, among receivers skipping the same
            first = clusters.order[clusters.offsets[:-1]]
            skips = (np.zeros(first.size, dtype=np.int64) if exclude is None
                     else exclude.labels[first].astype(np.int64))
            groups = np.zeros_like(skips) if clusters.groups is None else clusters.groups
            entries = blend_entries(pts, clusters, cl_centers, cl_radii,
                                    groups * (int(skips.max()) + 1) + skips, s.cluster_blend)
            cl_radii = entries.radii  # eq. 36 holds for every receiver a cut evaluates
        cuts = tree_cuts(forest, cl_centers, cl_radii, s.theta_max)
        skipped = None if exclude is None else excluded_nodes(clusters, exclude,
                                                              forest.blocker)
        weights = ratio_weights(forest, cuts, cl_centers, table,
                                s.resolved_theta_min(), skipped)
        in_cut = cuts.in_cut if skipped is None else cuts.in_cut & ~skipped
    if exclude is not None and not s.hierarchy:
        in_cut = in_cut & ~excluded_nodes(clusters, exclude, forest.blocker)
    order, offsets, blend = clusters.order, clusters.offsets, None
    if entries is not None:
        order, offsets, blend = entries.order, entries.offsets, entries.weights
    sizes = in_cut.sum(axis=1)
    s_max = max(1, int(sizes.max(initial=0)))
    # each cluster's cut nodes first (stable), padded with radius 0
    node_idx = np.argsort(~in_cut, axis=1, kind="stable")[:, :s_max]
    valid = np.arange(s_max)[None, :] < sizes[:, None]
    any_inner = bool((in_cut & ~forest.is_leaf[None, :]).any())
    work = FrameWork(
        order=order, offsets=offsets, sizes=sizes, blend=blend,
        centers=forest.centers[node_idx],
        radii=np.where(valid, forest.radii[node_idx], 0.0),
        weights=(np.take_along_axis(weights, node_idx[:, :, None], axis=1)
                 if any_inner else None))
    stats["seconds"]["cuts"] = time.process_time() - t0
    stats["pairs"] = int((np.diff(offsets) * sizes).sum())
    stats["clusters"] = clusters.n_clusters
    stats["spheres_per_vertex"] = stats["pairs"] / max(1, pts.shape[0])
    return work, stats
