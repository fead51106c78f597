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
    """Self-visibility and its log on a mesh's own vertices (the ``transfer`` asset).

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
        What was used (``order``, ``n_dirs`` actual node count, ``floor``,
        ``offset``, ``max_distance``), for the asset's provenance.
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    nrm = np.asarray(mesh.vertex_normals if normals is None else normals, dtype=np.float64)
    g = self_visibility(v, nrm, mesh, order, n_dirs=n_dirs, progress=progress,
                        max_distance=max_distance)
    f = self_visibility_log(g, floor=floor)
    params = {"order": int(order), "n_dirs": int(direction_quadrature(n_dirs)[0].shape[0]),
              "floor": float(floor), "offset": RAY_OFFSET, "offset_relative_to": "diagonal",
              "max_distance": max_distance}
    return g, f, params


#: Directions per vertex of :func:`hemisphere_transfer`, the exact self-transfer of rigid
#: objects in bakes: the fewest whose error against a 51,200-direction product rule is
#: no worse than :func:`mesh_transfer`'s at :data:`DEFAULT_DIRECTIONS` on the bunny,
#: the armadillo and the dragon (``benchmarks/bench_transfer.py``).
TRANSFER_DIRECTIONS = 1280


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
    nodes, weights = sphere_quadrature(2 * (order - 1))
    node_proj = basis(nodes, order) * weights[:, None]  # (K, n*n)
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
        # world node s has local coordinates F_v s (rows of F_v: t1, t2, N)
        at_nodes = basis(np.einsum("vij,kj->vki", frames, nodes), order)  # (v, K, n*n)
        g[rows] -= np.einsum("vkj,vj->vk", at_nodes, b_local) @ node_proj
    return g


def hemisphere_transfer(mesh, order: int, *, n_dirs: int = TRANSFER_DIRECTIONS,
                        floor: float = LOG_FLOOR, normals=None,
                        progress: Callable[[int, int], None] | None = None
                        ) -> tuple[np.ndarray, np.ndarray, dict]:
    """Self-visibility and its log on a mesh's own vertices, from hemisphere rays.

    What :func:`mesh_transfer` computes, with another estimator: every vertex
    casts ``n_dirs`` rays of the :func:`hemisphere_directions` set turned into its
    tangent frame (:func:`hemisphere_transfer_visibility`), so no ray is spent below the
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
        SH order (the accumulation order the runtime adds it at).
    n_dirs : int
        Rays per vertex.
    floor : float
        As in :func:`self_visibility_log`.
    normals : array_like, shape (V, 3), optional
        Receiver normals (default ``mesh.vertex_normals``).
    progress : callable, optional
        Called as ``progress(vertices_done, vertices_total)`` after every chunk.

    Returns
    -------
    visibility, log_visibility : ndarray, shape (V, n*n) float64
    parameters : dict
        ``order``, ``n_dirs``, ``estimator`` (``"hemisphere"``), ``floor``, ``offset``.
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
        g[rows] = hemisphere_transfer_visibility(v[rows], unit[start:start + step], caster,
                                                 order, n_dirs=n_dirs)
        if progress is not None:
            progress(skipped + start + rows.size, v.shape[0])
    if progress is not None and not good.size:
        progress(v.shape[0], v.shape[0])
    f = self_visibility_log(g, floor=floor)
    params = {"order": int(order), "n_dirs": int(n_dirs), "estimator": "hemisphere",
              "floor": float(floor), "offset": RAY_OFFSET, "offset_relative_to": "diagonal"}
    return g, f, params


__all__ = ["TRANSFER_DIRECTIONS", "hemisphere_transfer", "hemisphere_transfer_visibility",
           "mesh_transfer", "spatial_order"]
