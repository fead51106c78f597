r"""A traced object's shadow on the receiver-only objects, continuous over the surface.

The ground under a traced object (a skinned character's posed mesh, a rigid
sphere-set blocker's real mesh; ``traced_shadows``) is shadowed by the object's
real mesh near it and by its spheres far from it.  Three things keep that
shadow free of seams, rings and per-vertex noise:

**One direction set for every receiver.**  A spherical Fibonacci set of
``2 n_dirs`` world directions (:func:`world_directions`) is shared by all
receivers and frames; a receiver traces the directions of the set that fall in
the cone it sees the object's bounding sphere in (everything outside that cone
is exactly unblocked) and above its tangent plane, each standing for the same
solid angle ``4π / 2 n_dirs``:

.. math::

    g_v = \sqrt{4\pi}\,\delta_{i0} - \frac{4\pi}{2 n}\sum_{q\ \mathrm{blocked}} y(s_q).

A receiver whose cone fills its hemisphere gets ``n_dirs`` rays, a smaller
cone fewer in proportion: the count follows the cone with no steps, since a
direction enters the cone where it grazes the bounding sphere, unblocked, and
neighbouring receivers sample the same directions, so their estimates differ
only as the mesh's silhouette crosses them (no per-vertex pattern, no frame
that flips over the ground).  The basis is evaluated once per set, not per ray.

**A surface filter of the traced visibility** (:func:`surface_filter`).  A
silhouette crossing a direction is still a step of ``4π / 2n`` in the
estimate.  The steps come every ``d α`` of receiver motion, ``d`` the distance
to the nearest point of the mesh and ``α`` the set's angular spacing; the
true visibility projected to order ``n`` changes on the scale ``d π / n``.
A Gaussian of width ``d α / 2`` over the neighbouring receivers (same facing)
smooths the steps and leaves the order-``n`` visibility: where the mesh touches
the receiver (``d -> 0``) nothing is filtered, so contact shadows stay sharp.
The filter is linear in the SH vector, so it holds for any light.

**A per-vertex hand-over to the spheres** (:func:`handover_weights`).  The
cone's expected ray count ``k = n_dirs (1 - cos θ)`` decides: beyond
``HANDOVER_RAYS[0]`` rays (about 3.5 bounding radii) the object's spheres
shadow the receiver, within ``HANDOVER_RAYS[1]`` (about 2 radii) its traced
mesh, and in between the blend ``w T + (1 - w) S`` of the traced visibility
``T`` and the spheres' ``S``, ``w`` a smoothstep of ``k``.  The blend is in SH
visibility, not log: ``T`` is a visibility whose per-frame log (eigen) would
cost more than the frame, and where the blend happens the object is far and
faint (both visibilities near 1), where a visibility blend and a log blend
agree to first order in the log.  The runtime skips an object's spheres for
whole receiver clusters, so a cluster with any receiver of weight above 0 is
handed ``S`` on its rows of weight 0: the same as the spheres next door (up to
the truncated product with the other blockers' visibility).
"""

from __future__ import annotations

import functools
import math

import numpy as np

#: Ray counts (at the hemisphere density ``n_dirs``) of a receiver's cone where the
#: hand-over from the object's spheres to its traced mesh starts and ends: 4 keeps
#: the traced reach of the former per-cluster rule (about 3.5 bounding radii), 12
#: (about 2 radii) leaves the shadow proper to the real mesh.
HANDOVER_RAYS = (4.0, 12.0)
#: Width of the surface filter, in the set's angular spacing times the distance to
#: the nearest point of the mesh (half the spacing: the steps smoothed, the
#: order-n visibility kept).
FILTER_SPACING = 0.5
#: Receivers whose normals differ by more than this cosine are not filtered together.
FILTER_MIN_COS = 0.9
#: Ray origin offset along the normal, relative to the caster's bounding-box diagonal.
RAY_OFFSET = 1e-5
#: Rays per Embree call (bounds the (v, Q) blocks).
RAYS_PER_STEP = 1 << 20

SQRT_4PI = math.sqrt(4.0 * math.pi)


@functools.lru_cache(maxsize=8)
def world_directions(n: int) -> np.ndarray:
    """Spherical Fibonacci set of ``n`` unit directions over the sphere, ``(n, 3)``.

    Point ``i`` sits at height ``z_i = 1 - 2 (i + 1/2) / n`` (equal-area bands) and
    azimuth ``i`` golden angles; every point stands for ``4π / n``.  Read-only
    (cached).
    """
    i = np.arange(int(n)) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    d.setflags(write=False)
    return d


def cone_rays(cos_half, n_dirs: int) -> np.ndarray:
    """Expected rays ``n_dirs (1 - cos θ)`` of each receiver's cone, ``(V,)``."""
    return int(n_dirs) * (1.0 - np.asarray(cos_half, dtype=np.float64))


def handover_weights(rays) -> np.ndarray:
    """Weight ``(V,)`` of the traced mesh against the spheres: a smoothstep of the rays.

    0 at or below ``HANDOVER_RAYS[0]``, 1 at or above ``HANDOVER_RAYS[1]``, ``C^1``
    between (``3t² - 2t³``).
    """
    lo, hi = HANDOVER_RAYS
    t = np.clip((np.asarray(rays, dtype=np.float64) - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def set_visibility(points, normals, caster, axis, cos_half, order: int, n_dirs: int,
                   offset: float | None = None) -> np.ndarray:
    """Binary visibility of the caster on the shared set's directions in each cone, in SH.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals (world space).
    caster : RayCaster
        The object's real mesh.
    axis, cos_half : ndarray, shapes (V, 3) and (V,)
        The cones of its bounding sphere
        (:func:`~shtools.fields.self_visibility.bounding_cones`).
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Rays of a receiver whose cone fills its hemisphere (the set has ``2 n_dirs``).

    Returns
    -------
    ndarray, shape (V, n*n) float64
    """
    from shtools.sh import basis

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    dirs = world_directions(2 * int(n_dirs))
    proj = basis(dirs, order) * (4.0 * math.pi / dirs.shape[0])  # (Q, n*n)
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    origins = caster.embree_points(p + offset * nrm)
    dirs32 = dirs.astype(np.float32)
    step = max(1, RAYS_PER_STEP // dirs.shape[0])
    for start in range(0, p.shape[0], step):
        stop = min(p.shape[0], start + step)
        # directions of the set inside the cone and above the tangent plane
        take = ((axis[start:stop] @ dirs.T >= cos_half[start:stop, None])
                & (nrm[start:stop] @ dirs.T > 0.0))
        vi, qi = np.nonzero(take)
        if not vi.size:
            continue
        blocked = caster.occluded_embree(np.ascontiguousarray(origins[start + vi]),
                                         np.ascontiguousarray(dirs32[qi]))
        hits = np.zeros(take.shape, dtype=np.float64)
        hits[vi[blocked], qi[blocked]] = 1.0
        g[start:stop] -= hits @ proj
    return g


def nearest_distance(points, mesh_vertices, faces) -> np.ndarray:
    """Distance ``(V,)`` from each point to the nearest vertex or face centroid of a mesh.

    A cheap stand-in for the distance to the surface: exact enough for the
    filter's width, which only needs its scale.
    """
    from scipy.spatial import cKDTree

    v = np.asarray(mesh_vertices, dtype=np.float64)
    sites = np.concatenate([v, v[np.asarray(faces)].mean(axis=1)])
    d, _ = cKDTree(sites).query(np.asarray(points, dtype=np.float64), k=1)
    return d


def surface_filter(points, normals, values, width) -> np.ndarray:
    """Gaussian filter of per-vertex values over neighbouring receivers, ``(V, K)``.

    Each receiver ``v`` averages the values of the receivers within ``2 width_v``
    whose normals are within ``FILTER_MIN_COS`` of its own, weighted by
    ``exp(-|p_u - p_v|^2 / 2 width_v^2)``.  A receiver with ``width_v = 0`` keeps its
    value.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
    values : array_like, shape (V, K)
    width : array_like, shape (V,)
        Standard deviation of each receiver's Gaussian (world units).
    """
    from scipy import sparse
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    x = np.asarray(values, dtype=np.float64)
    sigma = np.asarray(width, dtype=np.float64).reshape(-1)
    lists = cKDTree(p).query_ball_point(p, r=2.0 * sigma, return_sorted=False)
    counts = np.fromiter((len(a) for a in lists), dtype=np.int64, count=len(lists))
    cols = np.fromiter((j for a in lists for j in a), dtype=np.int64, count=int(counts.sum()))
    rows = np.repeat(np.arange(len(p)), counts)
    d2 = ((p[rows] - p[cols]) ** 2).sum(axis=1)
    s2 = np.maximum(sigma[rows], 1e-300) ** 2
    w = np.exp(-0.5 * d2 / s2)
    w[rows == cols] = 1.0  # a receiver of width 0 keeps its own value
    w *= np.einsum("ik,ik->i", nrm[rows], nrm[cols]) >= FILTER_MIN_COS
    m = sparse.csr_matrix((w, (rows, cols)), shape=(len(p), len(p)))
    total = np.asarray(m.sum(axis=1)).reshape(-1)
    return (m @ x) / total[:, None]


def traced_ground(points, normals, vertices, faces, caster, order: int, n_dirs: int,
                  labels=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The traced part of an object's shadow on receivers, and each one's hand-over weight.

    Parameters
    ----------
    points, normals : array_like, shape (R, 3)
        The receivers (world space) and their unit normals.
    vertices, faces : array_like, shapes (V, 3) and (F, 3)
        The posed mesh (its bounding sphere: the box centre and the farthest vertex).
    caster : RayCaster
        Its Embree scene.
    order : int
        Shading order.
    n_dirs : int
        Rays of a receiver whose cone fills its hemisphere.
    labels : array_like of int, shape (R,), optional
        Group of each receiver (its runtime cluster); a group is handed over when any
        receiver of it has a weight above 0.  None: every receiver.

    Returns
    -------
    rows : ndarray of int, shape (T,)
        Indices into ``points`` of the receivers whose groups are handed over.
    weight : ndarray, shape (T,)
        Their weights of the traced mesh (the rest is the spheres').
    visibility : ndarray, shape (T, order^2) float64
        The filtered traced visibility (the constant 1 where the weight is 0: not traced).
    """
    from shtools.fields.self_visibility import bounding_cones

    v = np.asarray(vertices, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    center = 0.5 * (v.min(axis=0) + v.max(axis=0))
    radius = float(np.sqrt(((v - center) ** 2).sum(axis=1).max()))
    axis, cos_half = bounding_cones(p, nrm, center, radius)
    weight = handover_weights(cone_rays(cos_half, n_dirs))
    if labels is None:
        rows = np.arange(len(p))
    else:
        labels = np.asarray(labels)
        rows = np.flatnonzero(np.isin(labels, labels[weight > 0]))
    weight = weight[rows]
    g = np.zeros((len(rows), order * order))
    g[:, 0] = SQRT_4PI
    live = np.flatnonzero(weight > 0)
    if live.size:
        at = rows[live]
        traced = set_visibility(p[at], nrm[at], caster, axis[at], cos_half[at], order, n_dirs)
        spacing = math.sqrt(4.0 * math.pi / (2 * int(n_dirs)))
        width = FILTER_SPACING * spacing * nearest_distance(p[at], v, faces)
        g[live] = surface_filter(p[at], nrm[at], traced, width)
    return rows, weight, g
