"""Self-transfer of a mesh on its own vertices: its ray-traced visibility and the log
the runtime adds (the ``transfer`` asset, ``shtools transfer``, the bake's rigid
self-visibility).

Two estimators over the ray-traced SH visibility of :mod:`shtools.geometry.visibility`
(its conventions: directions below the tangent plane are visible, rays start
``RAY_OFFSET`` x the diagonal off the surface): :func:`mesh_transfer`, the full-sphere
product rule of :func:`~shtools.geometry.visibility.self_visibility`, and
:func:`hemisphere_transfer`, rays over each vertex's own hemisphere only.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from shtools.geometry.visibility import (
    DEFAULT_DIRECTIONS,
    LOG_FLOOR,
    RAY_OFFSET,
    RAYS_PER_STEP,
    SQRT_4PI,
    direction_quadrature,
    hemisphere_directions,
    receivers,
    self_visibility,
    self_visibility_log,
    tangent_frames,
)
from shtools.sh import basis, sphere_quadrature


def mesh_transfer(mesh, order: int, *, n_dirs: int = DEFAULT_DIRECTIONS,
                  floor: float = LOG_FLOOR, normals=None, max_distance: float | None = None,
                  progress: Callable[[int, int], None] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, dict]:
    """Self-visibility and its log on a mesh's own vertices by the full-sphere product
    rule (the ``transfer`` asset of ``shtools transfer --estimator product``).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The object's real mesh, in its own frame.
    order : int
        SH order (the accumulation order the runtime adds it at).
    n_dirs, floor, max_distance, progress
        As in :func:`self_visibility` and :func:`self_visibility_log`.
    normals : array_like, shape (V, 3), optional
        Receiver normals (default ``mesh.vertex_normals``, what the baker shades with).

    Returns
    -------
    visibility, log_visibility : ndarray, shape (V, n*n)
    parameters : dict
        What was used (``order``, ``n_dirs`` actual node count, ``estimator``
        (``"product"``), ``floor``, ``offset``, ``max_distance``), for the asset's
        provenance.
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    nrm = np.asarray(mesh.vertex_normals if normals is None else normals, dtype=np.float64)
    g = self_visibility(v, nrm, mesh, order, n_dirs=n_dirs, progress=progress,
                        max_distance=max_distance)
    f = self_visibility_log(g, floor=floor)
    params = {"order": int(order), "n_dirs": int(direction_quadrature(n_dirs)[0].shape[0]),
              "estimator": "product", "floor": float(floor), "offset": RAY_OFFSET,
              "offset_relative_to": "diagonal", "max_distance": max_distance}
    return g, f, params


#: Directions per vertex of :func:`hemisphere_transfer`, the exact self-transfer of rigid
#: objects in bakes: the dense set its two passes refine to (:func:`refined_transfer_visibility`).
#: With :data:`FIRST_DIRECTIONS` it casts ~675 rays a vertex on the dragon and the
#: armadillo, at a lower error against a 51,200-direction product rule than one pass
#: of 1,280 rays (coefficients 0.69 / 0.62 % against 0.74 / 0.68 %, shading 0.31 / 0.20 %
#: against 0.32 / 0.24 %; ``benchmarks/bench_transfer.py``).
TRANSFER_DIRECTIONS = 1600
#: Rays every vertex casts first (:func:`refined_transfer_visibility`); the directions
#: where they disagree with a neighbouring one are refined to the dense set.
FIRST_DIRECTIONS = 256


def spatial_order(points) -> np.ndarray:
    """Permutation ``(P,)`` visiting points along a Morton (Z-order) curve of their box.

    Consecutive rays then start near each other and walk the same BVH nodes, which
    stay in cache: the same rays cost less CPU than in a scattered vertex order (a
    mesh file's order may be any).
    Ties keep their input order (a stable sort), so the order is deterministic.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo = p.min(axis=0)
    span = float(np.ptp(p, axis=0).max()) or 1.0
    q = np.minimum(((p - lo) / span * 1024.0).astype(np.int64), 1023)
    code = np.zeros(p.shape[0], dtype=np.int64)
    for bit in range(10):  # interleave the 10 bits of x, y and z
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def _world_projector(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes ``(K, 3)`` of a product rule of degree ``2(n - 1)`` and their projection
    ``(K, n*n)``: :func:`_to_world`'s quadrature (exact for products of two order-``n``
    functions)."""
    nodes, weights = sphere_quadrature(2 * (order - 1))
    return nodes, basis(nodes, order) * weights[:, None]


def _to_world(frames, b_local, nodes, node_proj, order: int) -> np.ndarray:
    """Tangent-frame SH vectors ``b_local (v, n*n)`` in the world frame, ``(v, n*n)``.

    ``b(F_v s)`` sampled at the world nodes ``s`` (``frames (v, 3, 3)``, rows t1, t2, N:
    a world node's local coordinates are ``F_v s``) and projected.
    """
    at_nodes = basis(np.einsum("vij,kj->vki", frames, nodes), order)  # (v, K, n*n)
    return np.einsum("vkj,vj->vk", at_nodes, b_local) @ node_proj


def hemisphere_transfer_visibility(points, normals, caster, order: int, *,
                                   n_dirs: int = TRANSFER_DIRECTIONS,
                                   offset: float | None = None) -> np.ndarray:
    r""":func:`hemisphere_visibility`'s estimator, projected in each vertex's tangent frame.

    The same rays and the same estimate as :func:`hemisphere_visibility` (to
    rounding), for the many rays per vertex of the exact self-transfer.  Every
    vertex casts the same local set, so its blocked rays project with one matrix
    product, ``b = B Y w`` (``B (V, Q)`` the blocked flags, ``Y (Q, n^2)`` the basis
    at the local directions), instead of one basis evaluation per blocked ray; the
    local vector ``b`` is then turned into the world frame by sampling
    ``b(F_v s)`` at the nodes of a product rule of degree ``2(n - 1)``, exact for
    the products of two order-``n`` functions (as
    :func:`shtools.scene.transfer.posed_local_log` rotates logs).  Vertices are
    traced in :func:`spatial_order`.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals (world space).
    caster : RayCaster
        The blocking geometry.
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Rays per vertex.
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` x the caster's
        diagonal).

    Returns
    -------
    ndarray, shape (V, n*n) float64
    """
    p, nrm = receivers(points, normals)
    n = int(n_dirs)
    local64 = hemisphere_directions(n)
    local = local64.astype(np.float32)
    yw = basis(local64, order) * (2.0 * math.pi / n)  # (Q, n*n)
    nodes, node_proj = _world_projector(order)
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    ordered = spatial_order(p)
    step = max(1, RAYS_PER_STEP // 16 // n)  # ~32 MB of float32 rays
    for start in range(0, ordered.size, step):
        rows = ordered[start:start + step]
        t1, t2 = tangent_frames(nrm[rows])
        frames = np.stack([t1, t2, nrm[rows]], axis=1)  # (v, 3, 3): rows t1, t2, N
        dirs = np.matmul(local[None], frames.astype(np.float32))  # (v, Q, 3) world
        origins = caster.embree_points(p[rows] + offset * nrm[rows])
        blocked = caster.occluded_embree(np.repeat(origins, n, axis=0),
                                         np.ascontiguousarray(dirs.reshape(-1, 3)))
        b_local = blocked.reshape(rows.size, n).astype(np.float64) @ yw  # (v, n*n)
        g[rows] -= _to_world(frames, b_local, nodes, node_proj, order)
    return g


@functools.lru_cache(maxsize=4)
def refinement_cells(n_first: int, n_dirs: int):
    """The first pass's directions, their neighbours and the dense directions of each one's cell.

    Both sets are :func:`hemisphere_directions` (local frame, ``z`` the normal).  A
    first direction's **cell** holds the dense directions nearer to it than to any
    other first direction; its **neighbours** are those it shares an edge with in the
    spherical Delaunay triangulation of the first set (the convex hull of the set and
    the pole ``-z``, the pole left out).

    Returns
    -------
    first : ndarray, shape (N, 3)
    neighbours : ndarray of int, shape (N, K)
        Padded with the direction itself (it never disagrees with itself).
    cell : ndarray of int, shape (M,)
        The first direction whose cell holds each dense direction.
    members : ndarray of int, shape (M,)
        Dense directions sorted by cell; cell ``q``'s are
        ``members[starts[q]:starts[q] + counts[q]]``.
    starts, counts : ndarray of int, shape (N,)
    """
    from scipy.spatial import ConvexHull

    first = hemisphere_directions(int(n_first))
    dense = hemisphere_directions(int(n_dirs))
    n = first.shape[0]
    simplices = ConvexHull(np.vstack([first, [[0.0, 0.0, -1.0]]])).simplices
    pairs = np.concatenate([simplices[:, [a, b]] for a in range(3) for b in range(3) if a != b])
    pairs = np.unique(pairs[(pairs < n).all(axis=1)], axis=0)  # sorted: deterministic
    counts = np.bincount(pairs[:, 0], minlength=n)
    neighbours = np.repeat(np.arange(n)[:, None], max(1, int(counts.max())), axis=1)
    slot = np.arange(len(pairs)) - np.repeat(np.cumsum(counts) - counts, counts)
    neighbours[pairs[:, 0], slot] = pairs[:, 1]
    cell = np.argmax(dense @ first.T, axis=1)  # nearest: largest cosine (first of ties)
    members = np.argsort(cell, kind="stable")
    sizes = np.bincount(cell, minlength=n)
    return first, neighbours, cell, members, np.cumsum(sizes) - sizes, sizes


def refined_transfer_visibility(points, normals, caster, order: int, *,
                                n_dirs: int = TRANSFER_DIRECTIONS,
                                n_first: int = FIRST_DIRECTIONS,
                                offset: float | None = None) -> np.ndarray:
    r""":func:`hemisphere_transfer_visibility`'s estimate at ``n_dirs`` rays, from fewer rays.

    Two passes over each vertex's hemisphere (in its tangent frame, as
    :func:`hemisphere_transfer_visibility`):

    1. every vertex casts the ``n_first`` directions of the first set;
    2. in the cell (:func:`refinement_cells`) of every first direction whose result
       differs from one of its neighbours' -- where a shadow boundary crosses --
       the vertex casts the cell's directions of the dense set of ``n_dirs``.

    The estimate is the dense one, ``g = sqrt(4 pi) delta_i0 - (2 pi / n_dirs)
    sum_{d blocked} y(s_d)``, with every dense direction of a cell that was not refined
    taking its first direction's result: exact wherever no shadow boundary passes
    between first directions that agree, which a blocker narrower than their spacing
    (~9 degrees at 256) can.  On the dragon and the armadillo about a quarter of the
    cells are refined (~420 dense rays a vertex at 1,600).  The blocked flags are
    projected in the tangent frame and turned into the world frame by an exact
    product rule, as in
    :func:`hemisphere_transfer_visibility`; vertices are traced in
    :func:`spatial_order`.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals (world space).
    caster : RayCaster
        The blocking geometry.
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Directions of the dense set.
    n_first : int
        Directions of the first pass (fewer than ``n_dirs``).
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` x the caster's
        diagonal).

    Returns
    -------
    ndarray, shape (V, n*n) float64
    """
    import scipy.sparse as sp

    p, nrm = receivers(points, normals)
    first64, neighbours, cell, members, starts, counts = refinement_cells(n_first, n_dirs)
    first = first64.astype(np.float32)
    dense = hemisphere_directions(int(n_dirs))
    dense32 = dense.astype(np.float32)
    y_dense = basis(dense, order) * (2.0 * math.pi / dense.shape[0])  # (M, n*n)
    y_cell = np.zeros((first.shape[0], order * order))
    np.add.at(y_cell, cell, y_dense)  # each first direction stands for its cell
    nodes, node_proj = _world_projector(order)
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    ordered = spatial_order(p)
    step = max(1, RAYS_PER_STEP // 16 // dense.shape[0])  # <= ~32 MB of float32 rays
    for start in range(0, ordered.size, step):
        rows = ordered[start:start + step]
        t1, t2 = tangent_frames(nrm[rows])
        frames = np.stack([t1, t2, nrm[rows]], axis=1)  # (v, 3, 3): rows t1, t2, N
        f32 = frames.astype(np.float32)
        origins = caster.embree_points(p[rows] + offset * nrm[rows])
        dirs = np.matmul(first[None], f32)  # (v, N, 3) world
        hit = caster.occluded_embree(np.repeat(origins, first.shape[0], axis=0),
                                     np.ascontiguousarray(dirs.reshape(-1, 3)))
        hit = hit.reshape(rows.size, first.shape[0])
        edge = np.zeros_like(hit)  # (v, N): differs from a neighbour (one gather per slot)
        for k in range(neighbours.shape[1]):
            edge |= hit != hit[:, neighbours[:, k]]
        vi, qi = np.nonzero(edge)
        n_rays = counts[qi]
        rv = np.repeat(vi, n_rays)
        di = members[np.repeat(starts[qi], n_rays) + np.arange(rv.size)
                     - np.repeat(np.cumsum(n_rays) - n_rays, n_rays)]
        # world direction l_x t1 + l_y t2 + l_z N, gathered by rows (no (R, 3, 3) gather)
        local = dense32.take(di, axis=0)
        world = np.ascontiguousarray(f32[:, 0]).take(rv, axis=0)
        world *= local[:, :1]
        for k in (1, 2):
            part = np.ascontiguousarray(f32[:, k]).take(rv, axis=0)
            part *= local[:, k:k + 1]
            world += part
        refined = caster.occluded_embree(origins.take(rv, axis=0), world)
        b_local = hit.astype(np.float64) @ y_cell  # (v, n*n): every cell at its first result
        change = refined != hit[rv, cell[di]]
        if change.any():  # the refined cells' dense results replace their first one's
            sign = np.where(refined[change], 1.0, -1.0)
            b_local += sp.csr_matrix((sign, (rv[change], di[change])),
                                     shape=(rows.size, dense.shape[0])) @ y_dense
        g[rows] -= _to_world(frames, b_local, nodes, node_proj, order)
    return g


def hemisphere_transfer(mesh, order: int, *, n_dirs: int = TRANSFER_DIRECTIONS,
                        n_first: int | None = FIRST_DIRECTIONS,
                        floor: float = LOG_FLOOR, normals=None, with_log: bool = True,
                        progress: Callable[[int, int], None] | None = None
                        ) -> tuple[np.ndarray, np.ndarray | None, dict]:
    """Self-visibility and its log on a mesh's own vertices, from hemisphere rays.

    What :func:`mesh_transfer` computes, with another estimator: every vertex
    samples ``n_dirs`` directions of the :func:`hemisphere_directions` set turned into
    its tangent frame, in two passes that cast ``n_first`` of them and refine where
    the shadow boundaries are (:func:`refined_transfer_visibility`), or all in one pass
    (``n_first`` None: :func:`hemisphere_transfer_visibility`), so no ray is spent below the
    tangent plane (where the visibility is 1 by the module's convention and the
    product rule of :func:`self_visibility` spends half of its directions), and
    only the blocked rays carry quadrature error (the constant 1 projects
    exactly).  A vertex with a degenerate normal (length below 0.5) is
    unblocked, as in :func:`self_visibility`, where no direction lies above its plane.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The object's real mesh, in its own frame.
    order : int
        SH order (a ``transfer`` asset's: the accumulation order the runtime adds it
        at; a bake's or a field's O_v: the shading order).
    n_dirs : int
        Directions per vertex (the dense set).
    n_first : int or None
        Rays of the first pass; None: every vertex casts all ``n_dirs``.
    floor : float
        As in :func:`self_visibility_log`.
    normals : array_like, shape (V, 3), optional
        Receiver normals (default ``mesh.vertex_normals``).
    with_log : bool
        Compute the log too (a bake multiplies the visibility in and needs none).
    progress : callable, optional
        Called as ``progress(vertices_done, vertices_total)`` after every chunk.

    Returns
    -------
    visibility : ndarray, shape (V, n*n) float64
    log_visibility : ndarray, shape (V, n*n) float64, or None without ``with_log``
    parameters : dict
        ``order``, ``n_dirs``, ``n_first``, ``estimator`` (``"hemisphere"``), ``floor``,
        ``offset``.
    """
    from shtools.geometry.raycast import RayCaster

    v = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(mesh.vertex_normals if normals is None else normals,
                     dtype=np.float64).reshape(-1, 3)
    if nrm.shape != v.shape:
        raise ValueError(f"vertices {v.shape} and normals {nrm.shape} must have the same shape")
    g = np.zeros((v.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    good = np.flatnonzero(np.einsum("ij,ij->i", nrm, nrm) >= 0.25)
    good = good[spatial_order(v[good])]  # chunks of neighbouring vertices
    # Embree's faster non-robust traversal: the same bits as the robust one on 1,000-vertex
    # subsets of the bunny and the dragon at 1,280 rays, 10-20 % less CPU
    caster = RayCaster(v, np.asarray(mesh.faces), robust=False) if good.size else None
    unit = nrm[good] / np.linalg.norm(nrm[good], axis=1, keepdims=True)
    step = max(1, RAYS_PER_STEP // max(1, int(n_dirs)))
    skipped = v.shape[0] - good.size
    for start in range(0, good.size, step):
        rows = good[start:start + step]
        if n_first is None:
            g[rows] = hemisphere_transfer_visibility(v[rows], unit[start:start + step],
                                                     caster, order, n_dirs=n_dirs)
        else:
            g[rows] = refined_transfer_visibility(v[rows], unit[start:start + step], caster,
                                                  order, n_dirs=n_dirs, n_first=n_first)
        if progress is not None:
            progress(skipped + start + rows.size, v.shape[0])
    if progress is not None and not good.size:
        progress(v.shape[0], v.shape[0])
    f = self_visibility_log(g, floor=floor) if with_log else None
    params = {"order": int(order), "n_dirs": int(n_dirs),
              "n_first": None if n_first is None else int(n_first), "estimator": "hemisphere",
              "floor": float(floor), "offset": RAY_OFFSET, "offset_relative_to": "diagonal"}
    return g, f, params


#: What a field asset records (in ``parameters``) of an O_v by
#: :func:`field_self_visibility`; a bake uses the O_v as stored only when these match.
FIELD_ESTIMATE = {"self_estimator": "hemisphere", "self_n_dirs": TRANSFER_DIRECTIONS,
                  "self_n_first": FIRST_DIRECTIONS}


def field_self_visibility(vertices, normals, meshes, order: int) -> np.ndarray:
    """The O_v a shadow-field asset stores: :func:`hemisphere_transfer`'s estimate.

    The estimate of the bake's traced self-transfer of a rigid object, so a field's
    O_v shades its object's own vertices as the bake would trace them (the product
    rule of :func:`~shtools.geometry.visibility.self_visibility` spends half its
    directions below the tangent planes).  Called as
    :func:`shtools.fields.build.sample_field` calls its ``self_visibility``, on the
    object's own mesh only (``meshes`` its mesh, ``vertices`` that mesh's vertices).

    Parameters
    ----------
    vertices, normals : array_like, shape (V, 3)
        The mesh's own vertices and unit normals.
    meshes : list of trimesh.Trimesh
        The object's mesh alone (its vertices are ``vertices``).
    order : int
        SH order ``m`` of the result.

    Returns
    -------
    ndarray, shape (V, m*m) float64
    """
    if len(meshes) != 1 or not np.array_equal(np.asarray(meshes[0].vertices, dtype=np.float64),
                                              np.asarray(vertices, dtype=np.float64)):
        raise ValueError("field_self_visibility traces one mesh on its own vertices")
    mesh = meshes[0]
    g, _, _ = hemisphere_transfer(mesh, order, normals=normals, with_log=False)
    return g


__all__ = ["FIELD_ESTIMATE", "FIRST_DIRECTIONS", "TRANSFER_DIRECTIONS", "field_self_visibility",
           "hemisphere_transfer", "hemisphere_transfer_visibility", "mesh_transfer",
           "refined_transfer_visibility", "refinement_cells", "spatial_order"]
