"""Inputs of the runtime: blockers, spherical lights, and the checks of a frame's inputs.

Two kinds of blocker reach :meth:`shtools.runtime.ShadowRuntime.visibility`:

* :class:`SphereBlocker` — a sphere set, optionally with a tree; accumulated by
  the runtime's own cap-log kernels (hierarchy, tiles, worker processes);
* any :class:`LogBlocker` — an object with ``log_visibility(points, normals,
  order)`` that returns its own SH log visibility at the receivers (a shadow
  field lookup, a deformable field, exact self-visibility).  The runtime adds
  these to the spheres' log sum before the one exp, so all blockers combine in
  log space.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from shtools.errors import InputError


@dataclass
class SphereBlocker:
    """One blocker: a sphere set, optionally organised in a sphere tree.

    Parameters
    ----------
    centers : array_like, shape (N, 3)
        Leaf sphere centres in scene coordinates for the current frame.
    radii : array_like, shape (N,)
        Leaf sphere radii (>= 0).
    tree : tuple (parent (M,), leaf (M,)) or object with ``parent``/``leaf``, optional
        Hierarchy over the leaves: ``parent`` is -1 at the root, ``leaf`` the
        sphere-set index of leaf nodes and -1 for inner nodes.  Only the topology
        is used: the inner spheres are refit from the leaves every frame
        (:func:`shtools.runtime.spheres.refit_tree`).
    static : bool
        The spheres do not move between frames: with receiver rows flagged
        static too (``static_receivers`` of
        :meth:`~shtools.runtime.ShadowRuntime.visibility`), their pairs' log sum
        is kept between frames (:mod:`shtools.runtime.static_pairs`).
    """

    centers: Any
    radii: Any
    tree: Any = None
    static: bool = False
    parent: np.ndarray | None = field(init=False, default=None, repr=False)
    leaf: np.ndarray | None = field(init=False, default=None, repr=False)

    def __post_init__(self):
        self.centers = np.asarray(self.centers, dtype=np.float64)
        self.radii = np.asarray(self.radii, dtype=np.float64)
        if self.centers.ndim != 2 or self.centers.shape[1] != 3:
            raise InputError(f"blocker centers must have shape (N, 3), got {self.centers.shape}")
        if self.radii.shape != (self.centers.shape[0],):
            raise InputError(
                f"blocker radii must have shape ({self.centers.shape[0]},), got {self.radii.shape}"
            )
        if not (np.isfinite(self.centers).all() and np.isfinite(self.radii).all()):
            raise InputError("blocker spheres contain NaN or infinite values")
        if (self.radii < 0).any():
            raise InputError("blocker sphere radii must be >= 0")
        if self.tree is not None:
            if isinstance(self.tree, tuple | list):
                parent, leaf = self.tree
            else:
                parent, leaf = self.tree.parent, self.tree.leaf
            parent = np.asarray(parent, dtype=np.int64)
            leaf = np.asarray(leaf, dtype=np.int64)
            n = self.centers.shape[0]
            if parent.ndim != 1 or leaf.shape != parent.shape:
                raise InputError("blocker tree parent and leaf must be 1-D arrays of equal length")
            leaves = np.sort(leaf[leaf >= 0])
            if leaves.shape[0] != n or not np.array_equal(leaves, np.arange(n)):
                raise InputError(
                    f"blocker tree must have each of the {n} spheres as exactly one leaf; "
                    "rebuild it with `shtools spheres tree`"
                )
            if ((parent < -1) | (parent >= parent.shape[0])).any() or (parent == -1).sum() != 1:
                raise InputError(
                    "blocker tree parent array must name one root (-1) and valid nodes")
            self.parent, self.leaf = parent, leaf

    @property
    def n_spheres(self) -> int:
        """Number of leaf spheres ``N``."""
        return int(self.centers.shape[0])


@runtime_checkable
class LogBlocker(Protocol):
    """A blocker that gives its own log visibility (the runtime's blocker protocol).

    Implement ``log_visibility``; the runtime calls it once per frame in the
    calling process and adds the result to the log sum of the sphere blockers.
    """

    def log_visibility(self, points: np.ndarray, normals: np.ndarray,
                       order: int) -> np.ndarray:
        """SH log visibility at the receivers.

        Parameters
        ----------
        points, normals : ndarray, shape (V, 3)
            Receivers this frame (world space; unit normals).
        order : int
            The accumulation order ``n_acc``.

        Returns
        -------
        ndarray, shape (V, order*order)
            Log visibility (zero rows where the blocker casts no shadow).
        """
        ...


@dataclass
class SphereLight:
    """A spherical light of uniform radiance.

    Parameters
    ----------
    position : array_like, shape (3,)
        Centre in scene coordinates.
    radius : float
        Radius (> 0); with the distance it sets the per-vertex angular radius.
    color : array_like, shape (3,)
        Linear RGB radiance of the light's surface.
    """

    position: Any
    radius: float
    color: Any

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        self.color = np.asarray(self.color, dtype=np.float64).reshape(3)
        self.radius = float(self.radius)
        if not self.radius > 0 or not np.isfinite(self.position).all():
            raise InputError("a sphere light needs a finite position and a radius > 0")
        if not np.isfinite(self.color).all() or (self.color < 0).any():
            raise InputError("a sphere light colour must be finite and >= 0")


@dataclass
class SelfVisibility:
    """An object's self-visibility on its own receiver vertices, from its real mesh
    (or, given as a visibility, its real mesh's shadow traced on other receivers' rows).

    Given as a **log** (``log``), the runtime adds it (rotated by ``rotation``)
    to the accumulated log of the receiver rows ``rows`` before the exp (a rigid
    object's precomputed ``transfer``); given as a **visibility** (``visibility``),
    it multiplies the rows' visibility after the exp (a skinned object's posed
    mesh, ray traced this frame: no log to take per frame, see
    :mod:`shtools.scene.transfer`).  Either way the runtime skips the object's own
    blocker ``blocker`` on those rows: it then shadows only the other receivers
    (exact self-shadowing, combined with every other blocker).

    Parameters
    ----------
    log : array_like, shape (R, n_acc*n_acc), or None
        Log visibility at the runtime's accumulation order, in the object's own
        frame (from a ``transfer`` asset).
    rows : array_like of int, shape (R,), or slice
        The receiver rows of the frame it belongs to.
    rotation : array_like, shape (3, 3), optional
        The object's rotation this frame (own frame -> world); None: identity.
    blocker : int or tuple of int, optional
        Index, in the ``blockers`` list of the same call, of the object's own
        blocker, skipped on ``rows``: a sphere set, or a log blocker (a
        deformable field), which is then not evaluated on those rows.  Several
        for a visibility traced jointly against several objects' meshes.
    visibility : array_like, shape (R, m*m), optional
        Instead of ``log``: world-space visibility vectors (any order ``m``;
        truncated or zero-padded to the shading order), multiplied in by the
        exact truncated SH product at the shading order (no ``rotation``).
    """

    log: Any
    rows: Any
    rotation: Any = None
    blocker: int | tuple[int, ...] | None = None
    visibility: Any = None

    @property
    def skipped(self) -> tuple[int, ...]:
        """The blockers skipped on ``rows`` (``blocker`` as a tuple)."""
        if self.blocker is None:
            return ()
        if isinstance(self.blocker, tuple | list | np.ndarray):
            return tuple(int(k) for k in self.blocker)
        return (int(self.blocker),)

    def __post_init__(self):
        if (self.log is None) == (self.visibility is None):
            raise InputError("self-visibility needs exactly one of a log and a visibility")
        if self.log is not None:
            self.log = _checked("log", self.log)
        else:
            self.visibility = _checked("visibility", self.visibility)
        if self.rotation is not None:
            r = np.asarray(self.rotation, dtype=np.float64)
            if r.shape != (3, 3):
                raise InputError(f"self-visibility rotation must be (3, 3), got {r.shape}")
            self.rotation = r
            if self.visibility is not None:
                raise InputError("a self-visibility given as visibility is in world space; "
                                 "it takes no rotation")


def _checked(name: str, value) -> np.ndarray:
    """A self-visibility array as float32 ``(R, k)``, finite."""
    value = np.asarray(value, dtype=np.float32)
    if value.ndim != 2:
        raise InputError(f"self-visibility {name} must have shape (R, n*n), got {value.shape}")
    if not np.isfinite(value).all():
        raise InputError(f"self-visibility {name} contains NaN or infinite values")
    return value


def check_receivers(vertices, normals) -> tuple[np.ndarray, np.ndarray]:
    """Receivers of a frame as float64 ``(V, 3)`` arrays, normals made unit length."""
    pts = np.asarray(vertices, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or nrm.shape != pts.shape:
        raise InputError(
            f"vertices and normals must both have shape (V, 3), got {pts.shape} and {nrm.shape}"
        )
    if not (np.isfinite(pts).all() and np.isfinite(nrm).all()):
        raise InputError("receiver vertices or normals contain NaN or infinite values")
    # mesh normals are often only nearly unit; a zero normal (unreferenced vertex)
    # stays zero and shades black
    square = np.einsum("vi,vi->v", nrm, nrm)
    # np.allclose(|n|, 1, atol=1e-6)'s test, on |n|^2 in one pass: |n| - 1 ~ (|n|^2 - 1) / 2
    if not (np.abs(square - 1.0) <= 2.0 * (1e-6 + 1e-5)).all():
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = nrm / np.where(length > 0, length, 1.0)
    return pts, nrm


def check_blockers(blockers) -> tuple[list[SphereBlocker], list[LogBlocker]]:
    """Split blockers into sphere sets and blockers with their own log visibility."""
    spheres, others = [], []
    for b in blockers:
        if isinstance(b, SphereBlocker):
            spheres.append(b)
        elif isinstance(b, LogBlocker):
            others.append(b)
        else:
            raise InputError(f"blockers must be SphereBlocker objects or have "
                             f"log_visibility(points, normals, order), got {type(b).__name__}")
    return spheres, others
