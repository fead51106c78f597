"""Objects' exact self-visibility in the frame: the rows it covers and the blockers it skips.

A traced ``transfer`` gives an object's own receiver rows their visibility of its
real mesh, as an SH log (added before the exp, turned with the object) or as a
visibility (multiplied in after the exp).  On those rows the object's own sphere
set or deformable field is skipped.  :class:`SelfTerms` makes both per frame and
keeps the rotated logs of objects that do not turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError
from shtools.runtime.blockers import LogBlocker, SelfVisibility, SphereBlocker
from shtools.runtime.clusters import ReceiverClusters
from shtools.runtime.fast_exp import QuadratureProducts
from shtools.sh import rotation_matrix


def self_rows(sv: SelfVisibility, n_vertices: int, covered: int) -> np.ndarray:
    """Indices ``(R,)`` of the rows ``sv.rows`` selects among ``n_vertices``; they must
    number ``covered``, the vertices its log or visibility holds."""
    rows = np.arange(n_vertices)[sv.rows]
    if rows.shape[0] != covered:
        raise InputError(f"self-visibility covers {covered} vertices but its rows select "
                         f"{rows.shape[0]}")
    return rows


class SelfTerms:
    """The self-visibility terms of a runtime's frames, with their caches.

    Parameters
    ----------
    order, acc_order : int
        Shading and accumulation SH orders of the runtime.
    """

    def __init__(self, order: int, acc_order: int):
        self.order = order
        self.acc_order = acc_order
        self.rotated_logs: dict = {}  # id(log) -> (log, rotation, rotated log), last frame
        self.products: QuadratureProducts | None = None  # built on the first visibility

    def terms(self, self_visibility, n_vertices: int, blockers: list):
        """Rotated self-visibility logs ``(V, n_acc^2)`` and the own blocker each row skips.

        Returns ``(None, None, None)`` without self-visibility; ``exclude``
        (:class:`Skipped`) says which *sphere* blockers each row skips (several on a
        row that several traced objects shadow, e.g. the ground); ``skip`` maps the position of a
        log blocker (e.g. a deformable field) named by a self-visibility to the
        bool mask ``(V,)`` of the rows it skips.  A rotated log is kept while its
        object's rotation does not change (static objects).
        """
        if not self_visibility:
            self.rotated_logs = {}
            return None, None, None
        size = self.acc_order * self.acc_order
        sphere_index = {}  # position in `blockers` -> position among the sphere blockers
        for k, b in enumerate(blockers):
            if isinstance(b, SphereBlocker):
                sphere_index[k] = len(sphere_index)
        extra = np.zeros((n_vertices, size), dtype=np.float32)
        skipped = np.zeros((n_vertices, len(sphere_index)), dtype=bool)
        skip = {}
        kept = {}
        for sv in self_visibility:
            if not isinstance(sv, SelfVisibility):
                raise InputError(f"self_visibility must hold SelfVisibility objects, got "
                                 f"{type(sv).__name__}")
            if sv.log is not None and sv.log.shape[1] != size:
                raise InputError(
                    f"self-visibility log has {sv.log.shape[1]} coefficients but the runtime "
                    f"accumulates at order {self.acc_order} ({size}); rebuild the transfer "
                    f"with --order {self.acc_order}")
            given = sv.log if sv.log is not None else sv.visibility
            rows = self_rows(sv, n_vertices, given.shape[0])
            if sv.log is not None:  # a visibility is multiplied in after the exp
                extra[rows] += self._rotated_log(sv, kept)
            for k in sv.skipped:
                if k in sphere_index:
                    skipped[rows, sphere_index[k]] = True
                elif 0 <= k < len(blockers) and isinstance(blockers[k], LogBlocker):
                    skip.setdefault(k, np.zeros(n_vertices, dtype=bool))[rows] = True
                else:
                    raise InputError(f"self-visibility names blocker {k}, which is not "
                                     f"one of the {len(blockers)} blockers given")
        self.rotated_logs = kept
        if all(sv.log is None for sv in self_visibility):
            extra = None  # visibilities only: nothing to add before the exp
        return extra, (Skipped.of(skipped) if skipped.any() else None), (skip or None)

    def _rotated_log(self, sv: SelfVisibility, kept: dict) -> np.ndarray:
        """``sv.log (R, n_acc*n_acc)`` turned with its object; remembered in ``kept``
        while the rotation holds (static objects pay the rotation once)."""
        if sv.rotation is None or np.allclose(sv.rotation, np.eye(3), atol=1e-12):
            return sv.log
        cached = self.rotated_logs.get(id(sv.log))
        # the entry holds the source array itself: an id alone can be reused by a
        # new array once the old one is freed
        if cached is not None and cached[0] is sv.log and np.array_equal(cached[1], sv.rotation):
            log = cached[2]
        else:
            d = rotation_matrix(sv.rotation, self.acc_order).astype(np.float32)
            log = sv.log @ d.T
        kept[id(sv.log)] = (sv.log, sv.rotation.copy(), log)
        return log

    def multiply(self, g: np.ndarray, self_visibility) -> np.ndarray:
        """``g`` with the self-visibilities given as visibility multiplied into their rows.

        The exact truncated SH product at the shading order (quadrature); on rows
        where ``g`` is a constant (no other blocker reaches them: ``exp(0)``) the
        product is the given visibility times that constant, and on rows where the
        given visibility is exactly 1 (a traced shadow none of whose rays was blocked:
        most of a ground) it is ``g`` itself, with no quadrature.
        """
        given = [sv for sv in self_visibility or () if sv.visibility is not None]
        if not given:
            return g
        size = self.order * self.order
        if self.products is None:
            self.products = QuadratureProducts(self.order, np.float32)
        for sv in given:
            values = sv.visibility
            rows = self_rows(sv, g.shape[0], values.shape[0])
            k = values.shape[1]
            if math.isqrt(k) ** 2 != k:
                raise InputError(f"self-visibility has {k} coefficients, not an SH order's n*n")
            vis = np.zeros((rows.shape[0], size), dtype=np.float32)
            vis[:, :min(k, size)] = values[:, :size]
            sub = g[rows]
            flat = ~sub[:, 1:].any(axis=1)  # constant: c Y_00 = c / sqrt(4 pi) everywhere
            out = vis * (sub[:, :1] * np.float32(1.0 / math.sqrt(4.0 * math.pi)))
            one = ~vis[:, 1:].any(axis=1) & (vis[:, 0] == np.float32(math.sqrt(4.0 * math.pi)))
            out[one] = sub[one]
            full = ~flat & ~one
            if full.any():
                out[full] = self.products.product(sub[full], vis[full])
            g[rows] = out
        return g


@dataclass
class Skipped:
    """The sphere blockers each receiver row skips, as a label per row and one mask per label.

    Attributes
    ----------
    labels : ndarray of int, shape (V,)
        ``0..L-1``; rows with the same label skip the same blockers.  Ordered as the
        sets' bitmasks would be (nothing skipped first, then by highest blocker), so a
        scene whose rows skip at most one blocker each keeps its clusters.
    masks : ndarray of bool, shape (L, S)
        Sphere blockers (positions among the sphere blockers) each label skips.
    """

    labels: np.ndarray
    masks: np.ndarray

    @classmethod
    def of(cls, skipped: np.ndarray) -> Skipped:
        """From a ``(V, S)`` bool matrix of skipped sphere blockers."""
        n_sets = skipped.shape[1]
        if n_sets > 62:  # rows as bit codes need S < 63; the row-wise unique is slower
            masks, labels = np.unique(skipped[:, ::-1], axis=0, return_inverse=True)
            return cls(labels.reshape(-1).astype(np.int64), masks[:, ::-1])
        # a row's code has bit s for blocker s: sorting codes sorts the rows by their
        # highest skipped blocker first, the order documented above
        bits = np.left_shift(np.int64(1), np.arange(n_sets, dtype=np.int64))
        codes, labels = np.unique(skipped.astype(np.int64) @ bits, return_inverse=True)
        return cls(labels.reshape(-1).astype(np.int64), (codes[:, None] & bits) != 0)


def excluded_nodes(clusters: ReceiverClusters, exclude: Skipped,
                    node_blocker: np.ndarray) -> np.ndarray:
    """``(C, M)`` bool: forest nodes of the blockers each cluster's receivers skip.

    Raises InputError when a cluster mixes receivers that skip different blockers.
    """
    labels = exclude.labels
    counts = np.diff(clusters.offsets)
    first = labels[clusters.order[clusters.offsets[:-1]]]
    if not np.array_equal(labels[clusters.order], np.repeat(first, counts)):
        raise InputError("receiver clusters mix vertices of different self-visibility "
                         "objects; build the clusters with groups = object id per vertex")
    return exclude.masks[first][:, node_blocker]
