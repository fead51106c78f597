"""Exact self-shadowing of rigid objects in a bake (``self_visibility`` scene key).

A rigid object that both receives and casts (``role = "both"``, no skin) is
shadowed on its own vertices by its **real mesh**: its self-visibility is ray
traced once in its own frame (:func:`shtools.geometry.transfer.hemisphere_transfer`,
or read from a ``transfer`` asset), and every frame the runtime adds its log,
rotated with the object, to the log of every *other* blocker
(:class:`shtools.runtime.SelfVisibility`).  The object's own spheres then shadow
only the other receivers, so the sphere self-shadow rules no longer apply to its
own vertices.

A convex mesh cannot shadow itself: its log is zero and nothing is traced.
Scaling (uniform) does not change visibility; a non-uniform scale does, and is
approximated by the rotation part of the transform.

Skinned objects deform, so nothing can be precomputed: every frame their
**posed** real mesh is ray traced on their own vertices
(:func:`traced_self_visibility`,
:data:`~shtools.scene.skinned_visibility.SKINNED_DIRECTIONS` directions over the
hemisphere of each vertex it shadows, a few elsewhere); the runtime multiplies that
visibility into the vertices' visibility from every other blocker, the object's own blocker skipped
on its rows.  The same per-frame Embree scene traces the object's shadow on the
receiver-only objects (the ground, ``traced_shadows``;
:mod:`shtools.scene.traced_shadows`: rays only inside the cone of its bounding
sphere, handed over to its blocker far from it), whose rows then skip its
blocker too.  The older
alternative, kept behind ``local_visibility`` for objects that do not trace: the
paper's *local* visibility ``g_p`` (Ren et al. 2006 Sec. 7), the rest-pose
self-visibility of fine detail, rays limited to :data:`LOCAL_DISTANCE` times the
mesh's bounding-box diagonal, rotated per vertex with the rotation part of its
blended skinning matrix and added in log space to the posed spheres.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from shtools.errors import AssetError

#: Vertices of the stored transfer may differ from the scene mesh's by this much
#: (relative to the mesh's bounding-box diagonal) and still be the same mesh.
VERTEX_MATCH_RTOL = 1e-6


def uses_self_visibility(obj, default: bool = True) -> bool:
    """Whether an object gets exact self-shadowing: rigid, receives and casts, not off."""
    choice = getattr(obj.spec, "self_visibility", None)
    if choice is None:
        choice = default
    return bool(choice) and obj.spec.receives and obj.spec.blocks and obj.motion is None


#: Algorithm version of the cached self-visibility (:mod:`shtools.cache`): raise it
#: when :func:`object_self_log`'s traced result changes, even by rounding (a bake is the
#: same bytes with or without the cache).
SELF_LOG_VERSION = 5


def object_self_log(obj, acc_order: int, order: int | None = None, *,
                    log: Callable[[str], None] | None = None,
                    cache=None) -> tuple[np.ndarray | None, np.ndarray | None, Path | None]:
    """The object's self-visibility in its own frame: a log ``(V, acc_order^2)`` float32
    (added before the exp) or the visibility itself (multiplied in after it), or both.

    From the first source that applies: the ``transfer`` asset the scene names
    (``self_visibility = "x.transfer.h5"``: both); the O_v stored in the object's
    shadow-field asset (``blocker = { field = ... }``, :mod:`shtools.scene.field_blocker`)
    when it is the estimate traced here (``parameters.self_estimator``, ``self_n_dirs``,
    ``self_n_first``) of at least the shading order (a visibility); a zero log for a
    convex mesh;
    the visibility ray traced now, at the shading ``order`` (the runtime multiplies it
    in at that order, and needs no log of it).  A field's O_v and a traced visibility
    are visibilities only.

    Parameters
    ----------
    obj : PreparedObject
        With ``vertices``, ``normals``, ``faces`` (own frame) and ``spec``.
    acc_order : int
        The runtime's accumulation order.
    order : int, optional
        The shading order a traced visibility is projected to (default ``acc_order``).
    log : callable, optional
        Progress messages.
    cache : shtools.cache.SetupCache, optional
        Where the traced visibility (and whether the mesh is convex) is read from
        when its mesh, normals and order were traced before, and stored otherwise.

    Returns
    -------
    log : ndarray, shape (V, acc_order^2) float32, or None
        A transfer asset's log, a convex mesh's zero; None otherwise.
    visibility : ndarray, shape (V, m*m) float32, or None
        The projected visibility of a transfer asset (``m`` its order), of a field's
        O_v or of the tracing (``m = order``; the runtime multiplies it in exactly:
        the eigen-log's exp does not give it back where the mesh shadows itself
        deeply); None for a convex mesh.
    path : Path or None
        The ``transfer`` asset read (for the bake's inputs), None otherwise.
    """
    source = getattr(obj.spec, "self_visibility", None)
    if isinstance(source, str | Path):
        return *_from_asset(obj, Path(source), acc_order), Path(source)
    order = acc_order if order is None else int(order)
    stored = getattr(obj.blocker_data, "self_visibility", None)
    from shtools.geometry.transfer import FIELD_ESTIMATE

    if (stored is not None and getattr(obj.blocker_data, "self_order", 0) >= order
            and getattr(obj.blocker_data, "self_estimate", None) == FIELD_ESTIMATE):
        # the O_v of the object's field asset (already an input), multiplied in after
        # the exp at the shading order as a transfer asset's visibility is: the round
        # trip through its eigen-log and the exp does not give it back.  Truncated to the
        # shading order (rotations keep bands apart), it is what tracing here would give
        # (field sample stores the same estimate: geometry.transfer.field_self_visibility;
        # an older field's product-rule O_v, 4x further off a dense rule, is traced below)
        return None, np.ascontiguousarray(stored[:, :order * order], dtype=np.float32), None
    zero = np.zeros((len(obj.vertices), acc_order * acc_order), dtype=np.float32)
    if cache is None:
        g = _traced_self_visibility(obj, order, log)
        return (zero, None, None) if g is None else (None, g, None)
    from shtools.geometry.transfer import FIRST_DIRECTIONS, TRANSFER_DIRECTIONS

    parts = {"vertices": np.asarray(obj.vertices), "normals": np.asarray(obj.normals),
             "faces": np.asarray(obj.faces), "order": order, "estimator": "hemisphere",
             "n_dirs": TRANSFER_DIRECTIONS, "n_first": FIRST_DIRECTIONS}

    def compute():
        g = _traced_self_visibility(obj, order, log)
        # a convex mesh's "no visibility" is stored as an empty array
        return {"visibility": np.zeros((0, order * order), np.float32) if g is None else g}

    g = cache.fetch("self_log", SELF_LOG_VERSION, parts, compute)["visibility"]
    return (None, g, None) if len(g) else (zero, None, None)


def _traced_self_visibility(obj, order: int, log) -> np.ndarray | None:
    """The self-visibility ``(V, order^2)`` float32 ray traced now (None if convex)."""
    import trimesh

    if is_convex(obj.vertices, obj.faces):
        return None
    from shtools.geometry.transfer import hemisphere_transfer

    mesh = trimesh.Trimesh(obj.vertices, obj.faces, process=False)
    if log:
        log(f"ray tracing the self-visibility of {obj.spec.name} ({len(obj.vertices)} vertices; "
            "the set-up cache keeps it for the next bake)")
    # rays over each vertex's own hemisphere only, refined where its shadow boundaries
    # are: fewer than the product rule of `shtools transfer` casts, at no larger error
    # (geometry.transfer.TRANSFER_DIRECTIONS)
    g, _, _ = hemisphere_transfer(mesh, order, normals=obj.normals, with_log=False)
    return g.astype(np.float32)


#: A closed mesh whose volume is within this fraction of its convex hull's is convex.
CONVEX_RTOL = 1e-6


def is_convex(vertices, faces) -> bool:
    """Whether a mesh is the boundary of a convex solid (it cannot shadow itself).

    Closed (after merging duplicate vertices: primitives with flat normals split
    their edges) and with the volume of its convex hull.  ``trimesh``'s own
    ``is_convex`` calls three overlapping boxes (an arch) convex.
    """
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=True)
    if not mesh.is_watertight or not mesh.is_winding_consistent:
        return False
    hull = mesh.convex_hull.volume
    return hull > 0 and abs(hull - mesh.volume) <= CONVEX_RTOL * hull


def _from_asset(obj, path: Path, acc_order: int) -> tuple[np.ndarray, np.ndarray]:
    from shtools.data_formats.transfer import read_transfer
    from shtools.geometry.visibility import self_visibility_log_at

    t = read_transfer(path)
    name = obj.spec.name
    if t.vertices.shape != obj.vertices.shape:
        raise AssetError(f"has {len(t.vertices)} vertices but object '{name}' has "
                         f"{len(obj.vertices)}; rebuild it with 'shtools transfer' on that mesh",
                         path)
    diagonal = float(np.linalg.norm(np.ptp(obj.vertices, axis=0))) or 1.0
    if np.abs(t.vertices - obj.vertices).max() > VERTEX_MATCH_RTOL * diagonal:
        raise AssetError(f"was computed for another mesh than object '{name}''s; rebuild it "
                         "with 'shtools transfer'", path)
    if t.order < acc_order:
        raise AssetError(f"is SH order {t.order} but the scene accumulates at order "
                         f"{acc_order}; rebuild it with 'shtools transfer --order {acc_order}'",
                         path)
    if t.order == acc_order:
        return t.log_visibility, t.visibility
    return self_visibility_log_at(t.visibility, acc_order,
                                  floor=float(t.parameters.get("floor", 0.0))), t.visibility


#: Ray length of the local visibility of skinned objects, relative to the rest mesh's
#: bounding-box diagonal (``bench_fidelity``, CesiumMan and Fox).
LOCAL_DISTANCE = 0.02
#: Bands of the local log that are rotated and added (the default shading order): fine
#: detail lives in the low bands at this distance, and rotating order 6 per vertex every
#: frame cost 2-3x the frame (``bench_fidelity``).
LOCAL_ORDER = 4


def _skinned_both(obj) -> bool:
    """Whether ``obj`` is skinned and both receives and blocks (it shadows itself)."""
    return obj.spec.receives and obj.spec.blocks and obj.motion is not None


def uses_traced_visibility(obj, default: bool = True) -> bool:
    """Whether a skinned role-"both" object ray traces its posed mesh every frame."""
    choice = getattr(obj.spec, "self_visibility", None)
    if choice is None:
        choice = default
    return bool(choice) and _skinned_both(obj)


def uses_local_visibility(obj, default: bool) -> bool:
    """Whether a skinned role-"both" object adds its local visibility ``g_p``.

    Only objects that do not trace their posed mesh (the caller checks
    :func:`uses_traced_visibility` first) and whose own ``self_visibility`` is not false.
    """
    if getattr(obj.spec, "self_visibility", None) is False:
        return False
    return bool(default) and _skinned_both(obj)


def posed_caster(vertices, faces, *, deferred: bool = False):
    """The per-frame Embree scene of a posed mesh (:class:`~shtools.geometry.raycast.RayCaster`;
    with ``deferred``, built on its first query)."""
    from shtools.geometry.raycast import RayCaster

    # not robust: ~20 % faster; see RayCaster
    if deferred:
        return RayCaster.deferred(vertices, faces, robust=False)
    return RayCaster(vertices, faces, robust=False)


def traced_self_visibility(vertices, normals, faces, order: int, n_dirs: int, *,
                           caster=None) -> np.ndarray:
    """Self-visibility ``(V, order^2)`` float32 of a posed mesh on its own vertices.

    Binary visibility of the mesh over each vertex's hemisphere, ``n_dirs`` rays
    where the mesh shadows the vertex and a first few elsewhere
    (:func:`shtools.scene.skinned_visibility.adaptive_self_visibility`), projected to
    the shading order.  The runtime multiplies it into the vertices' visibility after
    the exp (no per-frame log: the eigen log of CesiumMan's vertices cost more than
    the rest of its frame, ``bench_fidelity --skinned``).

    Parameters
    ----------
    vertices, normals : array_like, shape (V, 3)
        The posed mesh (world space) and its unit vertex normals.
    faces : array_like, shape (F, 3)
    order : int
        Shading order.
    n_dirs : int
        Rays per self-shadowed vertex.
    caster : RayCaster, optional
        The posed mesh's Embree scene (:func:`posed_caster`), when already built.
    """
    from shtools.scene.skinned_visibility import adaptive_self_visibility

    caster = caster if caster is not None else posed_caster(vertices, faces)
    return adaptive_self_visibility(vertices, normals, faces, caster, order,
                                    n_dirs).astype(np.float32)


#: Algorithm version of the cached local visibility log (:mod:`shtools.cache`).
LOCAL_LOG_VERSION = 1


def object_local_log(obj, acc_order: int, distance: float = LOCAL_DISTANCE, *,
                     cache=None) -> np.ndarray:
    """Rest-pose local visibility log ``(V, acc_order^2)`` float32 of a skinned object.

    ``cache`` (:class:`shtools.cache.SetupCache`): read from it when the same rest
    mesh was traced at this order and distance before, stored in it otherwise.
    """
    if cache is None:
        return _traced_local_log(obj, acc_order, distance)
    parts = {"vertices": np.asarray(obj.vertices), "normals": np.asarray(obj.normals),
             "faces": np.asarray(obj.faces), "order": int(acc_order),
             "distance": float(distance)}
    return cache.fetch("local_log", LOCAL_LOG_VERSION, parts,
                       lambda: {"log": _traced_local_log(obj, acc_order, distance)})["log"]


def _traced_local_log(obj, acc_order: int, distance: float) -> np.ndarray:
    import trimesh

    from shtools.geometry.visibility import self_visibility, self_visibility_log

    mesh = trimesh.Trimesh(obj.vertices, obj.faces, process=False)
    diagonal = float(np.linalg.norm(np.ptp(obj.vertices, axis=0)))
    g = self_visibility(obj.vertices, obj.normals, mesh, acc_order,
                        max_distance=distance * diagonal)
    return self_visibility_log(g).astype(np.float32)


def posed_local_log(local_log: np.ndarray, blend: np.ndarray, world: np.ndarray) -> np.ndarray:
    """The rest-pose local log rotated with each vertex, ``(V, n*n)`` float32.

    Only the first :data:`LOCAL_ORDER` bands are rotated (the others are zero).

    ``blend (V, 4, 4)``: blended skinning matrices; ``world (4, 4)``: the object's
    transform.  Each vertex turns by the rotation part of ``world @ blend``.
    """
    from shtools.sh import basis, sphere_quadrature

    linear = np.einsum("ij,vjk->vik", np.asarray(world)[:3, :3], blend[:, :3, :3])
    u, _, vt = np.linalg.svd(linear)
    r = u @ vt
    flip = np.linalg.det(r) < 0  # degenerate blends: take the nearest proper rotation
    if flip.any():
        u[flip, :, -1] *= -1
        r[flip] = u[flip] @ vt[flip]
    size = local_log.shape[1]
    order = min(math.isqrt(size), LOCAL_ORDER)
    # (R f)(s) = f(R^T s), projected exactly by a rule of degree 2(n - 1): evaluate the
    # rest-pose log at R_v^T s_q (one basis per vertex and node), project with the
    # shared y(s_q) -- no (V, n^2, n^2) rotation matrices
    dirs, w = sphere_quadrature(2 * (order - 1))
    back = np.einsum("vji,qj->vqi", r, dirs).astype(np.float32)  # R_v^T s_q
    values = np.einsum("vqj,vj->vq", basis(back, order),
                       local_log[:, :order * order].astype(np.float32))
    out = np.zeros((local_log.shape[0], size), dtype=np.float32)
    out[:, :order * order] = values @ (w[:, None] * basis(dirs, order)).astype(np.float32)
    return out


def world_transfer(visibility: np.ndarray, rotation: np.ndarray, order: int) -> np.ndarray:
    """An object's self-visibility ``(V, m*m)`` (own frame) turned to world, ``(V, order^2)``.

    Truncated to the shading ``order`` first: the runtime multiplies it in at that
    order (:class:`shtools.runtime.SelfVisibility`), and rotation keeps each band.
    """
    from shtools.sh import rotation_matrix

    m = min(math.isqrt(visibility.shape[1]), order)
    d = rotation_matrix(rotation, m).astype(np.float32)
    return np.ascontiguousarray(visibility[:, :m * m] @ d.T, dtype=np.float32)


def rotation_of(matrix: np.ndarray) -> np.ndarray | None:
    """The rotation part ``(3, 3)`` of a transform's linear part (polar decomposition).

    None for a mirroring transform (no proper rotation carries the visibility).
    """
    u, _, vt = np.linalg.svd(np.asarray(matrix, dtype=np.float64)[:3, :3])
    r = u @ vt
    if np.linalg.det(r) < 0:
        return None
    return r
