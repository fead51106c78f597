r"""A skinned object's self-visibility, ray traced on its posed mesh every frame.

A posed character is traced on its own vertices over each vertex's hemisphere.
The error of a vertex's estimate is that of its binary samples, and it sits
exactly where the character shadows itself (between the legs, under the arms),
and there only in the directions the mesh fills: the shadowed vertices need
several times the rays a fully visible one does, and only towards the mesh.
So the rays go where the shadows are, in two passes of one set
(:func:`adaptive_self_visibility`):

1. each vertex's set (a spherical Fibonacci set of ``n`` directions in its tangent
   frame) is cut into **strata**, the directions nearest each of every
   :data:`FIRST_STRIDE`-th point of the set; every vertex casts those points first;
2. the vertices that any of them finds blocked, and their mesh neighbours (a
   faint shadow the first rays missed sits next to a stronger one they found),
   cast the rest of the set in the strata where the mesh may be: those whose first
   ray was blocked, on the vertex or on a neighbour (that ray's direction in the
   vertex's frame), and the strata next to them (:data:`STRATUM_RINGS`).

Every ray of a vertex stands for ``2π / n``: a vertex of the second pass sums
the blocked rays of both, over the whole set where the mesh may be (the nested
passes are one Fibonacci set, not two sets that overlap); a stratum that casts
only its first ray, unblocked, and a vertex of the first pass alone, none of
whose rays was blocked and none of whose neighbours', count as unblocked (the
exact constant 1 on a vertex the mesh does not shadow).  Each vertex's set is
turned about its normal by its own angle (``v`` golden angles for vertex ``v``),
so neighbouring vertices do not repeat one pattern's error.

The rays are not shared between neighbours, and the visibility is not filtered over
the surface: on a character's mesh neighbouring vertices' visibilities differ far
more than the rays' error does (a one-ring filter, or a one-ring pool of rays, was
less accurate at every count than the vertex's own rays; ``bench_look``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from shtools.geometry.visibility import GOLDEN_ANGLE
from shtools.sh.basis import SQRT_4PI

#: Rays per vertex of a skinned object's posed mesh where it shadows itself in every
#: direction (the ``self_visibility_directions`` default; a vertex casts those of the
#: strata the mesh may be in): the error over CesiumMan's own shadowed vertices is
#: 3.3 % (``benchmarks/bench_look.py``).
SKINNED_DIRECTIONS = 120
#: Every this-th point of a vertex's set is cast first, one per stratum (14 of 120; at
#: least :data:`FIRST_MIN` points, when the set has that many).
FIRST_STRIDE = 9
FIRST_MIN = 4
#: Mesh rings around the vertices the first rays find blocked that cast the rest too.
DILATE_RINGS = 1
#: Rings of strata around the blocked ones whose rest a vertex of the second pass casts.
STRATUM_RINGS = 1


def turned_frames(normals) -> np.ndarray:
    """Tangent frames ``(V, 3, 3)`` (rows t1, t2, N), each turned about its normal by
    ``v`` golden angles (vertex ``v``)."""
    from shtools.geometry.visibility import tangent_frames

    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    t1, t2 = tangent_frames(n)
    phi = (np.arange(len(n)) * GOLDEN_ANGLE)[:, None]
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([c * t1 + s * t2, c * t2 - s * t1, n], axis=1)


def first_stride(n_dirs: int) -> int:
    """Stride of the points a set of ``n_dirs`` casts first (1: one pass, all first)."""
    return max(1, min(FIRST_STRIDE, int(n_dirs) // FIRST_MIN))


@functools.lru_cache(maxsize=8)
def strata(n_dirs: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A set of ``n_dirs`` hemisphere directions cut into strata.

    Returns
    -------
    local : ndarray, shape (n, 3) float32
        The set (:func:`~shtools.geometry.visibility.hemisphere_directions`).
    first : ndarray of int, shape (K,)
        Its points cast first (every :func:`first_stride`-th), one per stratum.
    cell : ndarray of int, shape (n,)
        The stratum of each point (its nearest first point).
    touching : ndarray, shape (K, K) float32
        1 where two strata touch (a point of one has the other's first point second
        nearest) or are the same.
    """
    from shtools.geometry.visibility import cut_into_strata, hemisphere_directions

    local = hemisphere_directions(int(n_dirs))
    first, cell, touching = cut_into_strata(local, first_stride(n_dirs))
    out = (local.astype(np.float32), first, cell, touching)
    for a in out:
        a.setflags(write=False)
    return out


#: The last meshes' vertex adjacency, per process: (faces array, vertex count, CSR).
_ADJACENCY: list = []


def _adjacency(faces, n_vertices: int):
    """Vertex adjacency ``(V, V)`` CSR of a mesh, kept while the same faces array comes
    back (a skinned mesh's topology never changes)."""
    from shtools.reference.look import mesh_adjacency

    for f, n, adj in _ADJACENCY:
        if f is faces and n == n_vertices:
            return adj
    adj = mesh_adjacency(faces, n_vertices)
    _ADJACENCY[:] = [(faces, n_vertices, adj), *_ADJACENCY[:3]]
    return adj


def _blocked(caster, origins, frames, local) -> tuple[np.ndarray, np.ndarray]:
    """World directions ``(V, Q, 3)`` of the set ``local`` in each frame, and whether
    each is blocked ``(V, Q)``."""
    dirs = np.matmul(local[None], frames)
    o = np.repeat(origins, local.shape[0], axis=0)
    hit = caster.occluded_embree(o, np.ascontiguousarray(dirs.reshape(-1, 3)))
    return dirs, hit.reshape(len(origins), local.shape[0])


def _neighbour_strata(hit, dirs, frames, first_local, adj) -> np.ndarray:
    """Bool ``(V, K)``: the strata of each vertex's frame holding a blocked first ray of
    one of its mesh neighbours (that ray's world direction, above the tangent plane)."""
    out = np.zeros(hit.shape, dtype=bool)
    holders = np.flatnonzero(hit.any(axis=1))
    if not holders.size:
        return out
    edges = adj[holders].tocoo()  # (neighbour that has blocked rays, vertex): symmetric
    e, k = np.divmod(np.flatnonzero(hit[holders[edges.row]]), hit.shape[1])
    v = edges.col[e]
    # the neighbour's blocked direction in the vertex's frame (rows t1, t2, N); np.take
    # gathers rows several times faster than fancy indexing
    w = np.take(dirs.reshape(-1, 3), holders[edges.row[e]] * hit.shape[1] + k, axis=0)
    local = np.einsum("eij,ej->ei", np.take(frames, v, axis=0), w)
    above = local[:, 2] > 0
    out[v[above], np.argmax(local[above] @ first_local.T, axis=1)] = True
    return out


def adaptive_self_visibility(points, normals, faces, caster, order: int,
                             n_dirs: int = SKINNED_DIRECTIONS, *,
                             offset: float | None = None) -> np.ndarray:
    r"""Self-visibility ``(V, order^2)`` float64 of a posed mesh on its own vertices.

    With ``n = n_dirs`` and ``s_q`` the blocked rays of a vertex (of both passes):

    .. math::

        g_v = \sqrt{4\pi}\,\delta_{i0} - \frac{2\pi}{n} \sum_{q\ \mathrm{blocked}} y(s_q).

    Directions below the tangent plane count as visible.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        The posed mesh (world space) and its unit vertex normals.
    faces : array_like of int, shape (F, 3)
        Its triangles (the mesh neighbours of the second pass).
    caster : RayCaster
        Its Embree scene.
    order : int
        SH order of the result.
    n_dirs : int
        Points of each vertex's set (:func:`strata` cuts them).
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` times the caster's
        bounding-box diagonal).
    """
    from shtools.geometry.visibility import RAY_OFFSET, _subtract_blocked

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    local, first, cell, touching = strata(n_dirs)
    frames = turned_frames(nrm).astype(np.float32)
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    origins = caster.embree_points(p + offset * nrm)
    weight = 2.0 * math.pi / len(local)
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    dirs, blocked = _blocked(caster, origins, frames, local[first])
    vi, qi = np.nonzero(blocked)
    if not vi.size:
        return g
    # a vertex traced once has no blocked ray (its g stays 1): the first pass's blocked
    # rays all belong to vertices of the second pass
    _subtract_blocked(g, vi, dirs[vi, qi], weight, order)
    rest = np.setdiff1d(np.arange(len(local)), first)
    if not rest.size:
        return g
    adj = _adjacency(faces, len(p))
    busy = blocked.any(axis=1)
    for _ in range(DILATE_RINGS):
        busy = busy | (adj @ busy.astype(np.float64) > 0)
    active = blocked | _neighbour_strata(blocked, dirs, frames, local[first], adj)
    for _ in range(STRATUM_RINGS):
        active = (active.astype(np.float32) @ touching) > 0
    rows = np.flatnonzero(busy & active.any(axis=1))
    step = max(1, (1 << 20) // rest.size)  # rays per Embree call: bounded memory
    for start in range(0, rows.size, step):
        at = rows[start:start + step]
        take = active[at][:, cell[rest]]  # (B, n - K): the rest in the strata cast
        flat = np.flatnonzero(take)
        d = np.take(np.matmul(local[rest][None], frames[at]).reshape(-1, 3), flat, axis=0)
        hit = caster.occluded_embree(np.repeat(origins[at], take.sum(axis=1), axis=0), d)
        # flat is sorted: the blocked rays come in one run per vertex (np.compress:
        # several times faster than a boolean index on a mask without runs)
        _subtract_blocked(g, at[np.compress(hit, flat) // rest.size],
                          np.compress(hit, d, axis=0), weight, order)
    return g
