"""The shadow-field parts of a frame: rigid and deformable fields per receiver row.

Shadow fields (Tamura et al.) are not sphere sets: each is looked up per receiver
and combined with the other blockers' log sum in log space (one exp) or in product
space (truncated SH products after the exp), as ``settings.field_space`` says.
This module gathers a frame's fields (:func:`part_blockers`), cuts them to the rows
of one part (:meth:`PartBlockers.take`) and evaluates a part (:func:`combine_parts`),
in this process or a worker's.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from shtools.runtime.deformable import DeformableBlocker
from shtools.runtime.fields import FieldBlocker, field_log_visibility, field_product_visibility
from shtools.sh import product as sh_product

#: Blockers evaluated per part of a frame (in the worker processes too) and
#: combined as ``settings.field_space`` says: rigid and deformable shadow fields.
PART_BLOCKERS = (FieldBlocker, DeformableBlocker)
#: A deformable field at one receiver (lookup, scaling, exp) costs about as much CPU
#: as this many sphere-receiver pairs; it weighs receivers when a frame is split
#: (``MIN_PARALLEL_PAIRS``, cluster costs): the CPU of one deformable receiver over
#: that of one sphere-receiver pair, exp included (order 4, acc 6, either field space).
DEFORMABLE_RECEIVER_PAIRS = 64


def part_blockers(settings, blockers, skip: dict | None, n_vertices: int
                  ) -> PartBlockers | None:
    """The frame's shadow fields (rigid, deformable) for :func:`combine_parts`, or None.

    ``skip``: position in ``blockers`` -> bool mask ``(V,)`` of the rows a
    deformable field is not evaluated on (its object's own rows).  The
    deformable samples are turned into their axis frames here, once, before
    the parts go to the workers.
    """
    s = settings
    space = s.resolved_field_space("deformable")
    fields, deformables = [], []
    for k, b in enumerate(blockers):
        if isinstance(b, FieldBlocker):
            mask = None
            if b.skip_rows is not None:
                mask = np.zeros(n_vertices, dtype=bool)
                mask[np.asarray(b.skip_rows, dtype=np.int64)] = True
            fields.append((b, mask))
        elif isinstance(b, DeformableBlocker):
            b.prepare(log=space == "log")
            deformables.append((b, None if not skip else skip.get(k)))
    if not (fields or deformables):
        return None
    return PartBlockers(s.resolved_field_space("rigid"), space, fields, deformables)


def combine_parts(blocks: PartBlockers, pts, nrm, f, order: int, acc_order: int,
                  exponentiate) -> np.ndarray:
    """Visibility ``(V', n*n)`` float32 of receivers with the other blockers' log sum
    ``f (V', n_acc^2)`` (or None) and the shadow fields ``blocks``.

    Fields combined in ``"log"`` space add their logs to ``f`` and one exp
    follows; those in ``"product"`` space are then multiplied in with
    truncated SH products at the accumulation order -- deformable fields
    first, then rigid ones (nearest first) -- and the result is truncated to
    the shading order ``order``.  ``exponentiate``: the runtime's exp at
    ``acc_order``, truncated to ``order`` (``ShadowRuntime.exponentiate``).
    """
    m = acc_order
    if f is not None and not f.any():
        f = None  # nothing else blocks these receivers: no exp of zeros
    fields = [fb for fb, _ in blocks.fields]
    log_fields = fields if blocks.rigid_space == "log" else []
    log_deformables = blocks.deformable_space == "log" and bool(blocks.deformables)
    if log_fields or log_deformables:
        f = (np.zeros((pts.shape[0], m * m), dtype=np.float32) if f is None
             else np.array(f, dtype=np.float32))
        if log_fields:
            field_log_visibility(pts, nrm, log_fields, order, m, out=f)
        if log_deformables:
            for d, rows in deformable_rows(blocks, pts.shape[0]):
                f[rows] += d.log_visibility(pts[rows], nrm[rows], m)
    base = None if f is None else exponentiate(f)
    if blocks.deformables and not log_deformables:
        g = np.zeros((pts.shape[0], m * m))
        if base is None:
            g[:, 0] = math.sqrt(4.0 * math.pi)
        else:
            g[:, :base.shape[1]] = base
        for d, rows in deformable_rows(blocks, pts.shape[0]):
            g[rows] = sh_product(g[rows], d.visibility(pts[rows], nrm[rows], m), m)
        base = g
    if fields and not log_fields:
        return field_product_visibility(pts, nrm, fields, order, m,
                                        base=base).astype(np.float32)
    if base is None:  # nothing blocks these receivers
        base = np.zeros((pts.shape[0], order * order), dtype=np.float32)
        base[:, 0] = math.sqrt(4.0 * math.pi)
    return np.ascontiguousarray(base[:, :order * order], dtype=np.float32)


class NoField:
    """Stands in for a shadow field in ``ShadowRuntime.log_visibility`` when the
    fields are evaluated separately (keeps the other blockers' indices)."""

    def log_visibility(self, points, normals, order):
        return np.zeros((np.asarray(points).shape[0], order * order), dtype=np.float32)


@dataclass
class PartBlockers:
    """The shadow fields of a frame (or of one part's rows), as the parts evaluate them.

    Attributes
    ----------
    rigid_space, deformable_space : {"log", "product"}
        How each kind combines (``settings.resolved_field_space``).
    fields : list of (FieldBlocker, ndarray of bool (V,) or None)
        Rigid fields and the rows each skips (its own object's).
    deformables : list of (DeformableBlocker, ndarray of bool (V,) or None)
        Deformable fields and the rows each skips (its object's own rows, which
        a self-visibility covers).
    """

    rigid_space: str
    deformable_space: str
    fields: list
    deformables: list

    def take(self, rows: np.ndarray) -> PartBlockers:
        """The same blockers for receiver rows ``rows`` (masks cut, skip rows renumbered)."""
        fields = [(dataclasses.replace(fb, skip_rows=None if mask is None
                                       else np.flatnonzero(mask[rows])),
                   None if mask is None else mask[rows]) for fb, mask in self.fields]
        deformables = [(d, None if mask is None else mask[rows])
                       for d, mask in self.deformables]
        return PartBlockers(self.rigid_space, self.deformable_space, fields, deformables)


def deformable_rows(blocks: PartBlockers, n_rows: int):
    """``(blocker, rows)`` of each deformable field, rows it is evaluated on (not skipped)."""
    for d, mask in blocks.deformables:
        rows = np.arange(n_rows) if mask is None else np.flatnonzero(~mask)
        if rows.size:
            yield d, rows


def own_rows(self_visibility, n_vertices: int, blockers: list) -> dict | None:
    """Position of each deformable field a self-visibility names -> bool mask ``(V,)``
    of its object's rows (the field skips them)."""
    skip = {}
    for sv in self_visibility or ():
        for k in sv.skipped:
            if 0 <= k < len(blockers) and isinstance(blockers[k], DeformableBlocker):
                mask = skip.setdefault(k, np.zeros(n_vertices, dtype=bool))
                mask[np.arange(n_vertices)[sv.rows]] = True
    return skip or None
