"""Log sums of static spheres on static receivers, computed once and kept between frames.

A frame's log sum is a sum over (receiver, sphere) pairs, so it splits exactly into
the pairs whose receiver and blocker are both flagged static and the others.  The
static pairs' sum is made by the same cuts and kernel as a frame, from the static
inputs alone, and kept while those inputs are equal (compared, not trusted), so a
frame's bytes depend on the frame and the flags only: never on earlier frames or
on which frames a process evaluated.  The frame then accumulates the other pairs
(the static blockers are skipped on the static rows) and adds the kept sum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError
from shtools.runtime.blockers import SphereBlocker
from shtools.runtime.self_visibility import Skipped


@dataclass
class StaticSplit:
    """How one frame splits into kept static pairs and the pairs it accumulates.

    Attributes
    ----------
    frame_exclude : Skipped
        Sphere blockers each row skips this frame (its own skips, and the static
        blockers on static rows).
    static_exclude : Skipped
        Sphere blockers each row skips in the static sum (every blocker but the
        static ones, on static rows; all of them on the other rows).
    key : tuple
        The static inputs, compared to decide whether a kept sum still holds.
    exclusions : tuple
        What :func:`static_split` reuses in the next frame (its ``kept``).
    """

    frame_exclude: Skipped
    static_exclude: Skipped
    key: tuple
    exclusions: tuple


def static_split(pts, nrm, spheres: list[SphereBlocker], static_receivers, exclude,
                 clusters, kept: tuple | None = None) -> StaticSplit | None:
    """The frame's :class:`StaticSplit`, or None when no static pair exists.

    Parameters
    ----------
    pts, nrm : ndarray, shape (V, 3)
        Receivers (checked, unit normals).
    spheres : list of SphereBlocker
        The frame's sphere blockers (``static`` flags).
    static_receivers : array_like of bool, shape (V,)
        Rows whose position and normal do not change between frames.
    exclude : Skipped or None
        Blockers the rows skip for their own reasons (self-visibility).
    clusters : ReceiverClusters
        The frame's receiver clusters.
    kept : tuple, optional
        ``(inputs, frame_exclude, static_exclude)`` of an earlier frame: its
        exclusions are reused when the flags and ``exclude`` are equal.
    """
    rows = np.asarray(static_receivers)
    if rows.dtype != np.bool_ or rows.shape != (pts.shape[0],):
        raise InputError(f"static_receivers must be a bool mask of shape ({pts.shape[0]},), "
                         f"got {rows.dtype} of shape {rows.shape}")
    fixed = np.array([bool(b.static) for b in spheres], dtype=bool)
    if not rows.any() or not fixed.any():
        return None
    inputs = (rows, fixed) + ((None, None) if exclude is None else
                              (exclude.labels, exclude.masks))
    if kept is not None and same_key(kept[0][:4], inputs):
        _, frame_exclude, static_exclude = kept
        skipped_rows = kept[0][4]
    else:
        skipped = (np.zeros((pts.shape[0], len(spheres)), dtype=bool) if exclude is None
                   else exclude.masks[exclude.labels])
        pairs = rows[:, None] & fixed[None, :]
        frame_exclude = Skipped.of(skipped | pairs)
        static_exclude = Skipped.of(skipped | ~pairs)
        # the static sum depends on the static blockers' skips on static rows only
        # (a moving caster's traced shadow changes the others every frame)
        skipped_rows = skipped[rows][:, fixed]
        kept = (_copied((*inputs, skipped_rows)), frame_exclude, static_exclude)
    key = (rows.copy(), pts[rows], nrm[rows], skipped_rows,
           clusters.order, clusters.offsets,
           tuple((b.centers, b.radii, b.parent, b.leaf)
                 for b, f in zip(spheres, fixed, strict=True) if f))
    return StaticSplit(frame_exclude=frame_exclude, static_exclude=static_exclude, key=key,
                       exclusions=kept)


def same_key(a: tuple, b: tuple) -> bool:
    """Whether two :attr:`StaticSplit.key` hold equal inputs."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if isinstance(x, tuple):
            if not isinstance(y, tuple) or not same_key(x, y):
                return False
        elif x is None or y is None:
            if x is not y:
                return False
        elif not (x.shape == y.shape and np.array_equal(x, y)):
            return False
    return True


class StaticPairs:
    """The kept static-pair log sum of a runtime (one entry: the last static inputs)."""

    def __init__(self):
        self._key: tuple | None = None
        self._sum: np.ndarray | None = None
        self._exclusions: tuple | None = None

    def split(self, pts, nrm, spheres, static_receivers, exclude, clusters
              ) -> StaticSplit | None:
        """:func:`static_split` of this frame, reusing the last frame's exclusions."""
        split = static_split(pts, nrm, spheres, static_receivers, exclude, clusters,
                             self._exclusions)
        if split is not None:
            self._exclusions = split.exclusions
        return split

    def log_sum(self, split: StaticSplit, compute) -> np.ndarray:
        """The static pairs' log sum ``(V, n_acc^2)``: kept, or ``compute(exclude)``."""
        if self._key is None or not same_key(self._key, split.key):
            total = compute(split.static_exclude)
            total.setflags(write=False)
            # the key's arrays are copied: the caller may change its own in place
            self._key = _copied(split.key)
            self._sum = total
        return self._sum


def _copied(key):
    """A deep copy of a :attr:`StaticSplit.key` (arrays copied, None kept)."""
    if isinstance(key, tuple):
        return tuple(_copied(x) for x in key)
    return None if key is None else key.copy()
