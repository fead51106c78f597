"""Rigid objects' own spheres on their own receivers, kept in object space between frames.

A rigid object's spheres and the receiver rows that move with it keep their relative
pose, so the log sum of those pairs is the same function in the object's own frame
every frame; only its orientation in the world changes.  The sum is made once in that
frame by the same cuts and kernel as a frame and turned into the world per frame by an
SH rotation (block diagonal, one small matrix per band) instead of being accumulated
again.  The turned sum equals the world-space one to float32 rounding: the pair
geometry is rounded in another frame, which moves ``1 - cos(theta)`` by ulps (and the
piecewise-constant ratio table by at most one cell where it sits on a cell edge).

The object frame is read off the frame's own inputs alone: the origin is the mean of
the object's leaf centres and the axes their principal axes (signs fixed by the third
moment, right-handed).  Object-space inputs are snapped to a grid of
``2**-SNAP_BITS`` of the object's size, so that a turned copy of the same object gives
the same object-space inputs bit for bit; the kept sum is a function of those snapped
inputs only (compared, not trusted), so a frame's bytes never depend on earlier frames.
An object whose axes are ill defined (near-equal principal moments, a symmetric third
moment) only loses the reuse: its snapped inputs differ between frames and its sum is
made again, still in its object frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError
from shtools.runtime.blockers import SphereBlocker
from shtools.runtime.clusters import ReceiverClusters
from shtools.runtime.self_visibility import Skipped
from shtools.runtime.static_pairs import same_key
from shtools.sh import rotation_matrix

#: Object-space inputs are snapped to 2**-SNAP_BITS of the object's size (a power of
#: two): far finer than the float32 the kernel runs in (2**-24 relative), far coarser
#: than the ~1e-15 by which a turned copy's object-space coordinates differ.
SNAP_BITS = 22


@dataclass
class RigidObject:
    """One rigid object of a frame: its rows, its frame and its object-space inputs.

    Attributes
    ----------
    sphere : int
        Position of its blocker among the frame's sphere blockers.
    rows : ndarray of int, shape (R,)
        Receiver rows that move with it (and do not skip it).
    rotation : ndarray, shape (3, 3)
        Object axes in world coordinates (object -> world directions).
    key : tuple
        Object-space receivers, normals, spheres, tree and clusters (snapped).
    """

    sphere: int
    rows: np.ndarray
    rotation: np.ndarray
    key: tuple


def object_frame(centers: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Origin ``(3,)``, axes ``(3, 3)`` (columns, right-handed) and snap step of a sphere set.

    The axes are the principal axes of the centres; each axis' sign makes the third
    moment of the centres along it non-negative (the last follows from handedness).
    """
    origin = centers.mean(axis=0)
    rel = centers - origin
    _, axes = np.linalg.eigh(rel.T @ rel)
    proj = rel @ axes
    signs = np.where((proj ** 3).sum(axis=0) < 0, -1.0, 1.0)
    axes = axes * signs[None, :]
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    size = max(float(np.sqrt(np.einsum("ij,ij->i", rel, rel).max(initial=0.0))), 1e-30)
    step = 2.0 ** (np.floor(np.log2(size)) - SNAP_BITS)
    return origin, axes, step


def _snap(x: np.ndarray, step: float) -> np.ndarray:
    return np.rint(x / step) * step


def rigid_objects(pts, nrm, spheres: list[SphereBlocker], sphere_of: dict,
                  rigid_receivers, exclude: Skipped | None,
                  clusters: ReceiverClusters) -> list[RigidObject]:
    """The frame's rigid objects (none when no row is flagged).

    Parameters
    ----------
    pts, nrm : ndarray, shape (V, 3)
        Receivers (checked, unit normals).
    spheres : list of SphereBlocker
    sphere_of : dict
        Position in the frame's ``blockers`` -> position among ``spheres``.
    rigid_receivers : array_like of int, shape (V,)
        Position in ``blockers`` of the sphere blocker each row moves rigidly with,
        -1 for rows that move with none.
    exclude : Skipped or None
        Blockers the rows skip for their own reasons (self-visibility): a row that
        skips its object's spheres is left out.
    clusters : ReceiverClusters
        The frame's receiver clusters (each object keeps its rows' grouping).
    """
    flags = np.asarray(rigid_receivers)
    if flags.shape != (pts.shape[0],) or not np.issubdtype(flags.dtype, np.integer):
        raise InputError(f"rigid_receivers must be an int array of shape ({pts.shape[0]},) "
                         f"(a blocker index per row, -1 for none), got {flags.dtype} of "
                         f"shape {flags.shape}")
    objects = []
    for k in np.unique(flags[flags >= 0]):
        if int(k) not in sphere_of:
            raise InputError(f"rigid_receivers names blocker {int(k)}, which is not one of "
                             f"the sphere blockers given")
        j = sphere_of[int(k)]
        rows = np.flatnonzero(flags == k)
        if exclude is not None:
            rows = rows[~exclude.masks[exclude.labels[rows], j]]
        b = spheres[j]
        if rows.size == 0 or b.n_spheres == 0:
            continue
        origin, axes, step = object_frame(b.centers)
        local_pts = _snap((pts[rows] - origin) @ axes, step)
        local_nrm = _snap(nrm[rows] @ axes, 2.0 ** -SNAP_BITS)
        local_cen = _snap((b.centers - origin) @ axes, step)
        key = (local_pts, local_nrm, local_cen, b.radii,
               *((b.parent, b.leaf) if b.parent is not None else (None, None)),
               clusters.labels[rows])
        objects.append(RigidObject(sphere=j, rows=rows, rotation=axes, key=key))
    return objects


def frame_exclude(n_vertices: int, n_spheres: int, exclude: Skipped | None,
                  objects: list[RigidObject]) -> Skipped:
    """``exclude`` with each object's spheres skipped on its rows (the kept pairs)."""
    skipped = (np.zeros((n_vertices, n_spheres), dtype=bool) if exclude is None
               else exclude.masks[exclude.labels])
    for obj in objects:
        skipped[obj.rows, obj.sphere] = True
    return Skipped.of(skipped)


class RigidPairs:
    """The kept object-space log sums of a runtime's rigid objects (one per blocker slot)."""

    def __init__(self):
        self._kept: dict[int, tuple[tuple, np.ndarray]] = {}  # sphere -> (key, sum)
        self._exclude: tuple | None = None  # (inputs, Skipped) of the last frame
        # a writable copy of a read-only base (the kept static sum) with the last
        # frame's rows added, and those rows: rewriting them is cheaper than a copy
        self._base: np.ndarray | None = None
        self._combined: np.ndarray | None = None
        self._dirty: list = []

    def add_rows(self, total: np.ndarray | None, sums: list, n_vertices: int
                 ) -> np.ndarray | None:
        """``total`` ``(V, n*n)`` (None is zero) plus ``sums`` (``[(rows, values), ...]``
        of :meth:`frame`), in place when ``total`` is writable.

        A read-only ``total`` (the kept static sum, the same array while it holds) is
        copied once; later frames restore only the rows the previous frame changed.
        """
        if not sums:
            return total
        if total is None:
            total = np.zeros((n_vertices, sums[0][1].shape[1]), dtype=np.float32)
        elif not total.flags.writeable:
            if self._base is not total or self._combined is None:
                self._base, self._combined, self._dirty = total, total.copy(), []
            for rows in self._dirty:
                self._combined[rows] = total[rows]
            self._dirty = [rows for rows, _ in sums]
            total = self._combined
        for rows, values in sums:
            total[rows] += values
        return total

    def frame(self, pts, nrm, blockers: list, spheres: list[SphereBlocker], rigid_receivers,
              exclude: Skipped | None, clusters: ReceiverClusters, accumulate, order: int
              ) -> tuple[Skipped | None, list]:
        """This frame's exclusions (``exclude`` and the kept pairs) and kept log sums.

        ``accumulate(pts, nrm, blockers, clusters)``: the log sum ``(R, n_acc^2)`` of
        one object's pairs, by the frame's own cuts and kernel.  Returns the
        exclusions and ``[(rows (R,), world-space log sum (R, n_acc^2)), ...]`` (to
        add to the frame's rows: :meth:`add_rows`); ``(exclude, [])`` when no row is
        flagged.
        """
        sphere_of = {}
        for k, b in enumerate(blockers):
            if isinstance(b, SphereBlocker):
                sphere_of[k] = len(sphere_of)
        objects = rigid_objects(pts, nrm, spheres, sphere_of, rigid_receivers, exclude,
                                clusters)
        if not objects:
            return exclude, []

        def compute(obj):
            return accumulate(obj.key[0], obj.key[1], [object_blocker(obj, spheres[obj.sphere])],
                              ReceiverClusters.from_labels(obj.key[-1]))

        sums = self.log_sums(objects, compute, order)
        return self.exclusions(pts.shape[0], len(spheres), exclude, objects), sums

    def exclusions(self, n_vertices: int, n_spheres: int, exclude: Skipped | None,
                   objects: list[RigidObject]) -> Skipped:
        """:func:`frame_exclude`, reused while the rows and ``exclude`` are equal."""
        inputs = (tuple(o.rows for o in objects), np.array([o.sphere for o in objects]),
                  np.array([n_vertices, n_spheres]),
                  *((None, None) if exclude is None else (exclude.labels, exclude.masks)))
        if self._exclude is None or not same_key(self._exclude[0], inputs):
            result = frame_exclude(n_vertices, n_spheres, exclude, objects)
            self._exclude = (tuple(x if x is None or isinstance(x, tuple) else x.copy()
                                   for x in inputs), result)
        return self._exclude[1]

    def log_sums(self, objects: list[RigidObject], compute, order: int) -> list:
        """Each object's own pairs' log sum in world space: ``[(rows, (R, n*n)), ...]``.

        ``compute(obj)``: the object-space sum ``(R, n*n)`` of one object's pairs,
        made from ``obj.key`` alone.  Sums are kept while an object's key holds.
        """
        out = []
        kept = {}
        for obj in objects:
            entry = self._kept.get(obj.sphere)
            if entry is None or not same_key(entry[0], obj.key):
                local = compute(obj)
                local.setflags(write=False)
                entry = (tuple(None if x is None else x.copy() for x in obj.key), local)
            kept[obj.sphere] = entry
            # block diagonal: one product with the whole matrix is cheaper in BLAS than
            # one per band
            d = rotation_matrix(obj.rotation, order).astype(np.float32)
            out.append((obj.rows, entry[1] @ d.T))
        self._kept = kept
        return out


def object_blocker(obj: RigidObject, sphere: SphereBlocker) -> SphereBlocker:
    """The object's sphere blocker in its object frame (snapped centres)."""
    tree = None if sphere.parent is None else (sphere.parent, sphere.leaf)
    return SphereBlocker(obj.key[2], sphere.radii, tree=tree)
