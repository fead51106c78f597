r"""Per-vertex self-visibility of a mesh, ray traced once and projected to SH.

The visibility of receiver ``p`` (unit normal ``N``) in direction ``s`` is 0
when a ray from ``p`` along ``s`` hits the mesh and 1 otherwise.  Directions
below the tangent plane (``s . N <= 0``) count as **visible**: the convention
of the ray-traced reference (:mod:`shtools.reference.raytrace`) and of the
SHEXP self-shadow rules, and harmless for diffuse shading since ``H(N)``
weighs them by 0.  Keeping the same convention lets a precomputed
self-visibility replace an object's spheres on its own vertices and still be
compared one to one with the reference.

Quadrature.  The binary function is sampled on the smallest Gauss–Legendre
(in ``z``) x uniform (in φ) product rule of :func:`shtools.sh.sphere_quadrature`
with at least ``n_dirs`` nodes and projected to order ``n`` with its weights,
``g_i = Σ_q w_q V(s_q) y_i(s_q)``.  The rule is exact for polynomials of degree
``d`` (``(d/2 + 1)(d + 1) >= n_dirs``), not for the discontinuous visibility,
so ``n_dirs`` sets the accuracy: shadow boundaries cut the rule's cells.
On a closed form (a cone of half-angle 45° about +y plus a half space,
``tests/geometry``): single coefficients within 4.6e-2 at 2,000 nodes,
2e-2 at 8,000 and 3.7e-3 at 20,000 (``g_0 = 3.54`` for reference).  The
ray-traced reference uses the same family of rules, so at equal ``n_dirs``
both carry the same quadrature error.

The log (:func:`self_visibility_log`) goes through :func:`shtools.sh.log`
(eigen-inversion, Ren et al. 2006 eqs. 30-32).  A vertex whose whole upper
hemisphere is blocked (deep in a crevice) has a visibility that vanishes on a
hemisphere, whose log is -inf there; ``floor`` lifts the binary function to
``max(V, floor)`` before the log (for binary ``V`` that is exactly
``floor + (1 - floor) g``), so the log stays finite and ``exp`` of it gives
back at least ``floor`` everywhere.

This module must not import :mod:`shtools.reference`: the reference ray
tracer stays an independent check of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from shtools.sh import basis, sphere_quadrature
from shtools.sh import log as sh_log
from shtools.sh.basis import SQRT_4PI

#: Default number of quadrature directions (the issue's reference uses >= 3,200).
DEFAULT_DIRECTIONS = 3200
#: Ray origin offset along the normal, relative to the mesh's bounding-box diagonal
#: (against self-hits of the receiver's own triangles; the reference uses the same).
RAY_OFFSET = 1e-5
#: A shadow ray towards a point of a light stops this fraction of its length short of
#: it, so the light's own surface does not block it.
END_FRACTION = 1e-4
#: Rays cast per progress step (bounds the (V', Q) boolean block to ~16 MB).
RAYS_PER_STEP = 1 << 24
#: Default visibility floor of :func:`self_visibility_log`.
LOG_FLOOR = 0.01


def receivers(points, normals) -> tuple[np.ndarray, np.ndarray]:
    """Receivers and their normals as float64 arrays ``(V, 3)``, checked to agree."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if nrm.shape != p.shape:
        raise ValueError(f"points {p.shape} and normals {nrm.shape} must have the same shape")
    return p, nrm


def direction_quadrature(n_dirs: int) -> tuple[np.ndarray, np.ndarray]:
    """Smallest Gauss–Legendre x uniform product rule with at least ``n_dirs`` nodes.

    Returns
    -------
    dirs : ndarray, shape (Q, 3)
        Unit directions.
    weights : ndarray, shape (Q,)
        Quadrature weights (sum ``4π``).
    """
    if n_dirs < 1:
        raise ValueError(f"n_dirs must be >= 1, got {n_dirs}")
    degree = 2
    while (degree // 2 + 1) * (degree + 1) < n_dirs:
        degree += 1
    return sphere_quadrature(degree)


def self_visibility(vertices, normals, meshes, order: int, *, n_dirs: int = DEFAULT_DIRECTIONS,
                    offset: float | None = None,
                    progress: Callable[[int, int], None] | None = None,
                    max_distance: float | None = None, binary: bool = False) -> np.ndarray:
    """Binary visibility of triangle meshes at each vertex, projected to SH.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
        Receiver points (usually the mesh's own vertices).
    normals : array_like, shape (V, 3)
        Unit receiver normals (directions with ``s . N <= 0`` count as visible).
    meshes : trimesh.Trimesh or list of trimesh.Trimesh
        Geometry that blocks (the object's real mesh).
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Minimum number of quadrature directions (:func:`direction_quadrature`).
    offset : float, optional
        Ray origin offset along the normal (world units); default
        ``RAY_OFFSET`` x the meshes' bounding-box diagonal.
    progress : callable, optional
        Called as ``progress(vertices_done, vertices_total)`` after every
        chunk of vertices.
    max_distance : float, optional
        Only geometry closer than this (world units) occludes: the *local*
        visibility of fine detail (Ren et al. 2006 Sec. 7's ``g_p``, used for
        skinned objects whose large-scale self-shadowing changes with the pose).
    binary : bool
        Also return the binary samples and the quadrature (for tests and
        diagnostics; memory ``V x Q`` bytes).

    Returns
    -------
    ndarray, shape (V, n*n) float64
        Visibility vectors ``g``; with ``binary=True`` the tuple
        ``(g, vis (V, Q) bool, dirs (Q, 3), weights (Q,))``.
    """
    from shtools.geometry.raycast import RayCaster

    p = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if nrm.shape != p.shape:
        raise ValueError(f"vertices {p.shape} and normals {nrm.shape} must have the same shape")
    dirs, w = direction_quadrature(int(n_dirs))
    caster = RayCaster.from_meshes(meshes if isinstance(meshes, list | tuple) else [meshes])
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    # projection matrix: g = vis @ (w * y(s)) (one BLAS product per chunk)
    proj = basis(dirs, order) * w[:, None]  # (Q, n*n)
    out = np.empty((p.shape[0], order * order))
    keep = np.empty((p.shape[0], dirs.shape[0]), dtype=bool) if binary else None
    step = max(1, RAYS_PER_STEP // max(1, dirs.shape[0]))
    total = p.shape[0]
    for start in range(0, total, step):
        stop = min(total, start + step)
        vis = caster.visibility(p[start:stop], dirs, normals=nrm[start:stop], offset=offset,
                                t_far=max_distance)
        out[start:stop] = vis.astype(np.float64) @ proj
        if keep is not None:
            keep[start:stop] = vis
        if progress is not None:
            progress(stop, total)
    if binary:
        return out, keep, dirs, w
    return out


#: Directions per vertex of :func:`hemisphere_visibility` (skinned objects traced every
#: frame): the fewest that keep the radiance error against the real mesh under 5 % with
#: about a point to spare; what each count costs and buys is in docs/scenes.md
#: (``benchmarks/bench_fidelity.py --skinned``).
HEMISPHERE_DIRECTIONS = 32
#: Blocked (vertex, direction) pairs whose basis is evaluated at once (~16 MB at order 6).
BLOCKED_PER_STEP = 1 << 17


def hemisphere_directions(n_dirs: int) -> np.ndarray:
    """Spherical Fibonacci directions on the hemisphere ``z > 0``, shape ``(n_dirs, 3)``.

    Point ``i`` sits at height ``z_i = 1 - (i + 1/2) / n`` (the midpoints of ``n``
    equal-area bands: the hemisphere's area is uniform in ``z``) and azimuth
    ``i`` times the golden angle, so every point stands for the same solid angle
    ``2π / n`` and the set has no preferred azimuth.
    """
    if n_dirs < 1:
        raise ValueError(f"n_dirs must be >= 1, got {n_dirs}")
    i = np.arange(n_dirs) + 0.5
    z = 1.0 - i / n_dirs
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def cut_into_strata(directions, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A direction set cut into strata about every ``stride``-th direction.

    A direction's **stratum** is the nearest of those (largest cosine, first of ties);
    two strata **touch** where a direction of one has the other's point second nearest.
    Rays cast first on the strata's points, then only in the strata (and those
    touching them) where a first ray was blocked, sample the whole set where a
    shadow may be (skinned self-visibility, contact shadows).

    Parameters
    ----------
    directions : ndarray, shape (n, 3)
        Unit directions.
    stride : int
        Every this-th direction is a stratum's point.

    Returns
    -------
    first : ndarray of int, shape (K,)
        The strata's points (indices into ``directions``).
    cell : ndarray of int, shape (n,)
        The stratum of each direction.
    touching : ndarray, shape (K, K) float32
        1 where two strata touch or are the same.
    """
    first = np.arange(0, len(directions), int(stride))
    near = np.argsort(-(directions @ directions[first].T), axis=1, kind="stable")
    cell = near[:, 0].copy()
    touching = np.eye(len(first), dtype=np.float32)
    if len(first) > 1:
        touching[cell, near[:, 1]] = touching[near[:, 1], cell] = 1.0
    return first, cell, touching


def tangent_frames(normals) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents ``(V, 3)`` each completing unit normals to a right-handed frame.

    The branchless construction of Duff et al. 2017 ("Building an orthonormal basis,
    revisited"): continuous except where the normal crosses ``z = 0`` from below.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t1 = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    t2 = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t1, t2


def hemisphere_visibility(points, normals, caster, order: int, *,
                          n_dirs: int = HEMISPHERE_DIRECTIONS,
                          offset: float | None = None) -> np.ndarray:
    r"""Binary visibility over each vertex's own hemisphere of directions, projected to SH.

    For a mesh that changes every frame (a skinned character): each vertex casts
    the :func:`hemisphere_directions` set turned into its tangent frame
    (:func:`tangent_frames`), so all ``n_dirs`` rays sample where the visibility
    can be 0.  Directions below the tangent plane count as visible (the module's
    convention), and the constant 1 projects exactly to ``(sqrt(4π), 0, ...)``,
    so only the blocked directions carry quadrature error:

    .. math::

        g_v = \sqrt{4\pi}\,\delta_{i0} - \frac{2\pi}{n} \sum_{q\ \mathrm{blocked}} y(s_{vq}).

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals (world space).
    caster : RayCaster
        The blocking geometry (:class:`shtools.geometry.raycast.RayCaster`).
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Directions per vertex.
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` x the
        caster's diagonal).

    Returns
    -------
    ndarray, shape (V, n*n) float64
        Visibility vectors ``g``.
    """
    p, nrm = receivers(points, normals)
    local = hemisphere_directions(int(n_dirs)).astype(np.float32)
    t1, t2 = tangent_frames(nrm)
    frames = np.stack([t1, t2, nrm], axis=1).astype(np.float32)  # (V, 3, 3): rows t1, t2, N
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    origins = caster.embree_points(p + offset * nrm)
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    step = max(1, RAYS_PER_STEP // 16 // local.shape[0])  # ~32 MB of float32 rays
    for start in range(0, p.shape[0], step):
        stop = min(p.shape[0], start + step)
        dirs = np.matmul(local[None], frames[start:stop])  # (v, Q, 3) world
        o = np.repeat(origins[start:stop], local.shape[0], axis=0)
        blocked = caster.occluded_embree(o, np.ascontiguousarray(dirs.reshape(-1, 3)))
        vi, qi = np.divmod(np.flatnonzero(blocked), local.shape[0])
        _subtract_blocked(g, start + vi, dirs[vi, qi], 2.0 * math.pi / local.shape[0], order)
    return g


def _subtract_blocked(g, vertex, dirs, weight, order: int) -> None:
    """``g[v] -= w_v Σ y(s)`` over the blocked rays ``s`` of each vertex, in place.

    The SH basis is evaluated only on blocked rays, in chunks of ``BLOCKED_PER_STEP``,
    and summed per vertex by segments (no Python loop over vertices).

    Parameters
    ----------
    g : ndarray, shape (V, n*n)
        Visibility vectors, changed in place.
    vertex : ndarray of int, shape (B,)
        Vertex of each blocked ray, sorted (one run per vertex).
    dirs : ndarray, shape (B, 3)
        The blocked rays' unit directions.
    weight : float or ndarray, shape (V,)
        Solid angle each ray of a vertex stands for.
    order : int
        SH order ``n``.
    """
    for b in range(0, vertex.size, BLOCKED_PER_STEP):
        v = vertex[b:b + BLOCKED_PER_STEP]
        rows, first = np.unique(v, return_index=True)
        w = weight if np.ndim(weight) == 0 else weight[rows, None]
        g[rows] -= w * np.add.reduceat(basis(dirs[b:b + BLOCKED_PER_STEP], order), first,
                                       axis=0)


#: Rays a receiver casts toward a traced object whose bounding sphere fills its whole
#: hemisphere (:func:`cone_visibility`); a smaller cone gets fewer in proportion to its
#: solid angle.  The fewest that keep the ground's radiance error against the real mesh
#: under 3 % on the dragon + armadillo ground under the Mondello sun and, with margin, on
#: CesiumMan and the Fox (``benchmarks/bench_fidelity.py``, ``--skinned``).
CONE_DIRECTIONS = 96
#: Fewest rays per receiver of :func:`cone_visibility` (distant receivers, small cones).
CONE_MIN_RAYS = 4
#: The golden angle (radians): the azimuth step of the spiral direction sets.
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def bounding_cones(points, normals, center, radius) -> tuple[np.ndarray, np.ndarray]:
    """Cone of directions from each receiver that holds a sphere, clipped to its hemisphere.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals.
    center : array_like, shape (3,)
    radius : float
        A sphere that holds the blocking geometry.

    Returns
    -------
    axis : ndarray, shape (V, 3)
        Unit cone axis (towards the centre; the normal for receivers inside the sphere,
        whose cone is their whole hemisphere).
    cos_half : ndarray, shape (V,)
        Cosine of the half-angle; 1 (an empty cone) where the whole sphere lies below
        the receiver's tangent plane, so nothing there can shadow it.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(center, dtype=np.float64)[None] - p
    dist = np.sqrt(np.einsum("vk,vk->v", d, d))
    inside = dist <= radius
    axis = np.where(inside[:, None], nrm, d / np.where(inside, 1.0, dist)[:, None])
    cos_half = np.where(inside, 0.0, np.sqrt(np.maximum(
        0.0, 1.0 - (radius / np.where(inside, 1.0, dist)) ** 2)))
    # the sphere's lowest direction above the plane: elevation of the axis + half-angle
    sin_elev = np.einsum("vk,vk->v", axis, nrm)
    below = ~inside & (sin_elev <= -np.sqrt(1.0 - cos_half ** 2))
    return axis, np.where(below, 1.0, cos_half)


def cone_visibility(points, normals, caster, center, radius, order: int, *,
                    n_dirs: int = CONE_DIRECTIONS, min_rays: int = CONE_MIN_RAYS,
                    offset: float | None = None) -> np.ndarray:
    r"""Binary visibility of a mesh held by a sphere, traced only inside the sphere's cone.

    For receivers *outside* a skinned object (the ground under a character): every
    direction outside the cone the bounding sphere subtends (:func:`bounding_cones`)
    is exactly unblocked, so only the cone is sampled -- a spherical Fibonacci set on
    the cap (equal-area bands in ``cos``, golden-angle azimuths), each ray standing
    for the same solid angle :math:`\Omega_v / k_v`.  The ray count follows the
    cap's solid angle, ``k_v = max(min_rays, ceil(n_dirs Ω_v / 2π))`` (an even
    density: the cones near the object, which carry the dark contact shadows, get
    the rays), and, as in :func:`hemisphere_visibility`, the constant is exact and
    only blocked directions carry quadrature error:

    .. math::

        g_v = \sqrt{4\pi}\,\delta_{i0} - \frac{\Omega_v}{k_v}
              \sum_{q\ \mathrm{blocked}} y(s_{vq}).

    Directions below the tangent plane count as visible (the module's convention).

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals (world space).
    caster : RayCaster
        The blocking mesh (:class:`shtools.geometry.raycast.RayCaster`).
    center : array_like, shape (3,)
    radius : float
        A sphere holding the caster's mesh.
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Rays of a receiver whose cone is its whole hemisphere.
    min_rays : int
        Fewest rays of a receiver with a non-empty cone.
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` x the caster's
        diagonal).

    Returns
    -------
    ndarray, shape (V, n*n) float64
    """
    p, nrm = receivers(points, normals)
    axis, cos_half = bounding_cones(p, nrm, center, radius)
    solid = 2.0 * math.pi * (1.0 - cos_half)  # (V,)
    counts = np.where(solid > 0, np.maximum(int(min_rays), np.ceil(
        solid * (int(n_dirs) / (2.0 * math.pi)) - 1e-9)), 0).astype(np.int64)
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    origins = caster.embree_points(p + offset * nrm)
    t1, t2 = tangent_frames(axis)
    frame = [np.ascontiguousarray(a, dtype=np.float32) for a in (t1, t2, axis)]
    up = [np.einsum("vk,vk->v", a, nrm).astype(np.float32) for a in (t1, t2, axis)]
    depth = (1.0 - cos_half).astype(np.float32)
    inv_count = (1.0 / np.maximum(counts, 1)).astype(np.float32)
    weight = solid / np.maximum(counts, 1)
    ends = np.cumsum(counts)
    step = RAYS_PER_STEP // 16  # rays per chunk (~32 MB of float32 rays)
    v0 = 0
    while v0 < p.shape[0]:  # chunks of whole receivers
        v1 = int(np.searchsorted(ends, (ends[v0 - 1] if v0 else 0) + step, side="right"))
        v1 = min(max(v1, v0 + 1), p.shape[0])
        n = counts[v0:v1]
        v_of = np.repeat(np.arange(v0, v1), n)
        if v_of.size:
            # ray i of its receiver's cap: equal-area band i, golden-angle azimuth
            i = (np.arange(v_of.size) - np.repeat(np.cumsum(n) - n, n)).astype(np.float32)
            i += np.float32(0.5)
            z = 1.0 - depth[v_of] * (i * inv_count[v_of])
            r = np.sqrt(np.maximum(np.float32(0.0), 1.0 - z * z))
            phi = i * np.float32(GOLDEN_ANGLE)
            x, y = r * np.cos(phi), r * np.sin(phi)
            # world direction x t1 + y t2 + z axis (gathers of (V, 3) rows: no (R, 3, 3))
            dirs = frame[0].take(v_of, axis=0)
            dirs *= x[:, None]
            for c, a in ((y, frame[1]), (z, frame[2])):
                part = a.take(v_of, axis=0)
                part *= c[:, None]
                dirs += part
            blocked = caster.occluded_embree(origins.take(v_of, axis=0), dirs)
            # only directions above the tangent plane can be blocked (module convention)
            blocked &= (x * up[0].take(v_of) + y * up[1].take(v_of) + z * up[2].take(v_of)) > 0
            hit = np.flatnonzero(blocked)
            _subtract_blocked(g, v_of[hit], dirs[hit], weight, order)
        v0 = v1
    return g


def self_visibility_log(g, *, floor: float = LOG_FLOOR, eps: float | None = None) -> np.ndarray:
    """SH log of binary visibility vectors by eigen-inversion, with a visibility floor.

    Parameters
    ----------
    g : array_like, shape (V, n*n)
        Projected binary visibility (:func:`self_visibility`).
    floor : float
        Visibility floor in [0, 1): the log is taken of ``floor + (1 - floor) g``,
        the projection of ``max(V, floor)`` for binary ``V``, so fully blocked
        directions get ``log(floor)`` rather than -inf.
    eps : float, optional
        Eigenvalue floor of :func:`shtools.sh.log` (default its ``LOG_EPS``).

    Returns
    -------
    ndarray, shape (V, n*n) float64
        ``f`` with ``exp(f) ~= floor + (1 - floor) g`` at order ``n``.
    """
    if not 0.0 <= floor < 1.0:
        raise ValueError(f"floor must be in [0, 1), got {floor!r}")
    g = np.asarray(g, dtype=np.float64)
    lifted = (1.0 - floor) * g
    lifted[..., 0] += floor * SQRT_4PI
    kwargs = {} if eps is None else {"eps": eps}
    return sh_log(lifted, "eigen", **kwargs)


def self_visibility_log_at(g, order: int, *, floor: float = LOG_FLOOR) -> np.ndarray:
    """The log of stored visibility at another SH order, shape ``(V, order*order)`` float32.

    A log is order-specific (a truncated order-8 log is not the order-6 log), so a
    visibility stored at a higher order is truncated *before* the log; one stored
    at a lower order is logged at its own order and zero above.

    Parameters
    ----------
    g : array_like, shape (V, m*m)
        Projected visibility at order ``m``.
    order : int
        The order of the result (the accumulation order).
    floor : float
        See :func:`self_visibility_log`.
    """
    g = np.asarray(g, dtype=np.float64)
    m = math.isqrt(g.shape[-1])
    k = min(m, order) ** 2
    out = np.zeros((g.shape[0], order * order), dtype=np.float32)
    out[:, :k] = self_visibility_log(g[:, :k], floor=floor)
    return out


__all__ = ["CONE_DIRECTIONS", "CONE_MIN_RAYS", "DEFAULT_DIRECTIONS", "HEMISPHERE_DIRECTIONS",
           "LOG_FLOOR", "bounding_cones", "cone_visibility", "direction_quadrature",
           "hemisphere_directions", "hemisphere_visibility", "receivers", "self_visibility",
           "self_visibility_log", "tangent_frames"]
