r"""A skinned object's self-visibility, ray traced on its posed mesh every frame.

A posed character is traced on its own vertices over each vertex's hemisphere.
The error of a vertex's estimate is that of its binary samples, and it sits
exactly where the character shadows itself (between the legs, under the arms):
the shadowed vertices need several times the rays a fully visible one does.
So the rays go where the shadows are, in two passes
(:func:`adaptive_self_visibility`):

1. every vertex casts a few rays (:data:`FIRST_FRACTION` of the count);
2. the vertices that any of them finds blocked, and their mesh neighbours (a
   faint shadow the first rays missed sits next to a stronger one they found),
   cast the rest.

A vertex of the second pass averages both passes' estimates by their counts; a
vertex of the first pass alone, none of whose rays was blocked and none of whose
neighbours', keeps the exact constant 1.  Each vertex's hemisphere set (a
spherical Fibonacci set in its tangent frame) is turned about its normal by its
own angle (``v`` golden angles for vertex ``v``), the second set half a golden
angle from the first, so neighbouring vertices do not repeat one pattern's error.

The rays are not shared between neighbours, and the visibility is not filtered over
the surface: on a character's mesh neighbouring vertices' visibilities differ far
more than the rays' error does (a one-ring filter, or a one-ring pool of rays, was
less accurate at every count than the vertex's own rays; ``bench_look``).
"""

from __future__ import annotations

import math

import numpy as np

from shtools.geometry.visibility import GOLDEN_ANGLE
from shtools.sh.basis import SQRT_4PI

#: Rays per vertex of a skinned object's posed mesh where it is self-shadowed (the
#: ``self_visibility_directions`` default): the fewest that keep the error over
#: CesiumMan's own shadowed vertices under 4 % (``benchmarks/bench_look.py``).
SKINNED_DIRECTIONS = 112
#: Share of the rays every vertex casts first (at least :data:`FIRST_MIN`).
FIRST_FRACTION = 1.0 / 9.0
FIRST_MIN = 4
#: Mesh rings around the vertices the first rays find blocked that cast the rest too.
DILATE_RINGS = 1


def turned_frames(normals) -> np.ndarray:
    """Tangent frames ``(V, 3, 3)`` (rows t1, t2, N), each turned about its normal by
    ``v`` golden angles (vertex ``v``)."""
    from shtools.geometry.visibility import tangent_frames

    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    t1, t2 = tangent_frames(n)
    phi = (np.arange(len(n)) * GOLDEN_ANGLE)[:, None]
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([c * t1 + s * t2, c * t2 - s * t1, n], axis=1)


def split_directions(n_dirs: int) -> tuple[int, int]:
    """Rays of the first pass and of the second for a count of ``n_dirs``."""
    n = int(n_dirs)
    first = min(n, max(FIRST_MIN, round(FIRST_FRACTION * n)))
    return first, n - first


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


def adaptive_self_visibility(points, normals, faces, caster, order: int,
                             n_dirs: int = SKINNED_DIRECTIONS, *,
                             offset: float | None = None) -> np.ndarray:
    r"""Self-visibility ``(V, order^2)`` float64 of a posed mesh on its own vertices.

    With ``n`` the rays a vertex casts in all (``n_dirs`` where it is self-shadowed,
    the first pass's count elsewhere) and the blocked ones ``s_q``:

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
        Rays of a self-shadowed vertex (:func:`split_directions` splits them).
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` times the caster's
        bounding-box diagonal).
    """
    from shtools.geometry.visibility import RAY_OFFSET, _subtract_blocked, hemisphere_directions

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    n_first, n_rest = split_directions(n_dirs)
    frames = turned_frames(nrm).astype(np.float32)
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    origins = caster.embree_points(p + offset * nrm)
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    dirs, blocked = _blocked(caster, origins, frames,
                             hemisphere_directions(n_first).astype(np.float32))
    busy = blocked.any(axis=1)
    if not busy.any():
        return g
    if n_rest:
        adj = _adjacency(faces, len(p))
        for _ in range(DILATE_RINGS):
            busy = busy | (adj @ busy.astype(np.float64) > 0)
    rows = np.flatnonzero(busy)
    # a vertex traced once has no blocked ray (its g stays 1): the first pass's blocked
    # rays all belong to vertices of the second pass, whose ray total is n_dirs
    vi, qi = np.nonzero(blocked)
    _subtract_blocked(g, vi, dirs[vi, qi], 2.0 * math.pi / (n_first + n_rest), order)
    if not n_rest:
        return g
    rest = hemisphere_directions(n_rest).astype(np.float32)
    c, s = math.cos(0.5 * GOLDEN_ANGLE), math.sin(0.5 * GOLDEN_ANGLE)
    rest = rest @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32)
    step = max(1, (1 << 20) // rest.shape[0])  # rays per Embree call: bounded memory
    for start in range(0, rows.size, step):
        at = rows[start:start + step]
        dirs, blocked = _blocked(caster, origins[at], frames[at], rest)
        vi, qi = np.nonzero(blocked)
        _subtract_blocked(g, at[vi], dirs[vi, qi], 2.0 * math.pi / (n_first + n_rest), order)
    return g
