"""The receivers' neighbour lists and the surface filter of a traced visibility.

A traced visibility (:mod:`shtools.scene.traced_shadows`) steps by one ray's solid
angle where the mesh's silhouette crosses a direction of the shared set;
:func:`surface_filter` smooths those steps with a Gaussian over each receiver's
nearest receivers facing the same way (:func:`neighbours`), its width set by the
distance to the mesh (:func:`mesh_distance`, :func:`nearest_distance`).  The
reasoning behind the widths is in :mod:`shtools.scene.traced_shadows`.
"""

from __future__ import annotations

import math

import numpy as np

from shtools.blend import smoothstep

#: The neighbour (by rank, self excluded) whose distance is a receiver's spacing.
SPACING_NEIGHBOUR = 4
#: Receivers whose normals differ by more than this cosine are not filtered together.
FILTER_MIN_COS = 0.9
_CUT = math.exp(-2.0)  # the filter's Gaussian at its cut, 2 widths

#: Neighbours each receiver's filter may take per pass (the nearest ones: about 3
#: receiver spacings on a grid).
FILTER_NEIGHBOURS = 24

#: Receiver sets whose neighbour lists a process keeps (the newest first).
NEIGHBOUR_ENTRIES = 16
#: Per process: the last receivers' neighbour lists and the last meshes' search trees
#: (a static ground and a rigid object are searched once per bake).
_NEIGHBOURS: list = []
_SITES: list = []


def nearest_distance(points, mesh_vertices, faces, caster=None) -> np.ndarray:
    """Distance ``(V,)`` from each point to the nearest vertex or face centroid of a mesh.

    A cheap stand-in for the distance to the surface: exact enough for the
    filter's width, which only needs its scale.  The search tree is kept while
    ``caster`` (the mesh's Embree scene, rebuilt whenever the mesh moves) is the same
    object.
    """
    from scipy.spatial import cKDTree

    if caster is not None and _SITES and _SITES[0][0] is caster:
        tree = _SITES[0][1]
    else:
        v = np.asarray(mesh_vertices, dtype=np.float64)
        tree = cKDTree(np.concatenate([v, v[np.asarray(faces)].mean(axis=1)]))
        _SITES[:] = [(caster, tree)] if caster is not None else []
    d, _ = tree.query(np.asarray(points, dtype=np.float64), k=1)
    return d


#: Sphere distances (in the largest sphere's radius) within which
#: :func:`mesh_distance` is the exact distance to the mesh, and beyond which it is the
#: spheres'.  A loose bound's spheres are nearer than its mesh, next to a thin leg
#: by 28 % of the distance; the filter that much too narrow leaves the steps
#: there (the ground under the glTF sample Fox, 576 faces and 32 spheres: smoothness
#: ratio 1.19 on ``benchmarks/bench_look.py``'s measure; 1.11 with the exact distance
#: within these radii, the same within noise out to 3 to 6).
EXACT_REACH = (1.0, 2.5)
#: Vertices (about) whose nearest to each receiver bounds the triangles
#: :func:`mesh_distance` hands to libigl.
REACH_SAMPLE = 2048


def mesh_distance(points, vertices, faces, spheres) -> np.ndarray:
    """Distance ``(V,)`` from each point to a mesh bound by spheres, for the filter's width.

    The exact distance to the triangles (libigl's AABB tree) within ``EXACT_REACH[0]``
    of the largest sphere's radius of the spheres, the distance to the spheres' union
    (:func:`sphere_distance`) beyond ``EXACT_REACH[1]``, and between them a smoothstep
    of the sphere distance blending the two (continuous over the receivers); only the
    receivers near the spheres pay for the exact query.

    Parameters
    ----------
    points : array_like, shape (V, 3)
        The receivers (world space).
    vertices, faces : array_like, shapes (P, 3) and (F, 3)
        The mesh (at least one triangle).
    spheres : tuple of ndarray, shapes (S, 3) and (S,)
        Its bounding spheres' centres and radii (at least one sphere).

    Returns
    -------
    ndarray, shape (V,) float64
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = sphere_distance(p, *spheres)
    r_max = float(np.max(spheres[1]))
    lo, hi = (k * r_max for k in EXACT_REACH)
    t = np.clip((d - lo) / max(hi - lo, 1e-300), 0.0, 1.0)
    w = 1.0 - smoothstep(t)
    near = np.flatnonzero(w > 0)
    if near.size:
        import igl
        from scipy.spatial import cKDTree

        v = np.ascontiguousarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        q = np.ascontiguousarray(p[near])
        # libigl builds its tree over the triangles it is given (about 1 us a face, every
        # frame for a moving mesh): only those that can hold a nearest point.  A point's
        # nearest surface point is no farther than any vertex, so within ``reach`` of a
        # sample of the vertices; triangles whose boxes miss the receivers' box grown by
        # it cannot hold one
        sample = v[::max(1, len(v) // REACH_SAMPLE)]
        reach = float(cKDTree(sample).query(q, k=1)[0].max())
        lo_q, hi_q = q.min(axis=0) - reach, q.max(axis=0) + reach
        a, b, c = (np.take(v, f[:, i], axis=0) for i in range(3))
        lo_f = np.minimum(np.minimum(a, b), c)
        hi_f = np.maximum(np.maximum(a, b), c)
        keep = np.ones(len(f), dtype=bool)
        for k in range(3):  # by column: a reduction over rows of 3 is several times slower
            keep &= (hi_f[:, k] >= lo_q[k]) & (lo_f[:, k] <= hi_q[k])
        d2, _, _ = igl.point_mesh_squared_distance(q, v, np.ascontiguousarray(f[keep]))
        d[near] = w[near] * np.sqrt(np.maximum(d2, 0.0)) + (1.0 - w[near]) * d[near]
    return d


def sphere_distance(points, centers, radii) -> np.ndarray:
    """Distance ``(V,)`` from each point to a union of spheres (0 inside one)."""
    # relative to the spheres' centroid, in float32 (a filter width needs no more)
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    o = c.mean(axis=0)
    p = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - o).astype(np.float32)
    c = (c - o).astype(np.float32)
    r = np.asarray(radii, dtype=np.float32).reshape(-1)
    d2 = np.einsum("vk,vk->v", p, p)[:, None] - 2.0 * (p @ c.T) + np.einsum("sk,sk->s", c, c)
    d = np.sqrt(np.maximum(d2, 0.0)) - r[None, :]
    return np.maximum(0.0, d.min(axis=1)).astype(np.float64)


def neighbours(points, normals, rest=None, cache=None) -> tuple[np.ndarray, np.ndarray]:
    """The ``FILTER_NEIGHBOURS`` nearest receivers of each, self first: ``(V, K)`` indices
    (-1 for a neighbour facing away by more than ``FILTER_MIN_COS``: a wall's receivers
    are not a floor's) and distances, kept while the same receivers come back (the last
    ``NEIGHBOUR_ENTRIES`` sets: the ground and the objects a frame traces).

    ``rest`` is ``(points (V, 3), normals (V, 3), scale)`` when the receivers are one
    rigid object posed by a rotation, a translation and a uniform ``scale``: its
    neighbours are those of its rest geometry (the distances times ``scale``), so a
    moving rigid object is searched once per bake, not once per frame.  With ``cache``
    (a :class:`~shtools.cache.SetupCache`) the search is done once for all bakes of the
    same receivers.
    """
    if rest is not None:
        idx, dist = neighbours(rest[0], rest[1], cache=cache)
        return idx, dist * float(rest[2])
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    for k, entry in enumerate(_NEIGHBOURS):  # the ground and the objects of a frame
        if entry[0].shape == p.shape and np.array_equal(entry[0], p) and np.array_equal(
                entry[1], nrm):
            _NEIGHBOURS.insert(0, _NEIGHBOURS.pop(k))  # the least recently used go first
            return entry[2:]
    if cache is None:
        idx, dist = _search_neighbours(p, nrm)
    else:
        got = cache.fetch("filter_neighbours", NEIGHBOURS_VERSION, {"points": p, "normals": nrm},
                          lambda: dict(zip(("idx", "dist"), _search_neighbours(p, nrm),
                                           strict=True)))
        idx, dist = got["idx"], got["dist"]
    _NEIGHBOURS[:] = [(p.copy(), nrm.copy(), idx, dist), *_NEIGHBOURS[:NEIGHBOUR_ENTRIES - 1]]
    return idx, dist


#: Version of :func:`_search_neighbours`' results in the set-up cache.
NEIGHBOURS_VERSION = 1


def _search_neighbours(p, nrm) -> tuple[np.ndarray, np.ndarray]:
    """:func:`neighbours` of receivers ``p``, ``nrm`` ``(V, 3)`` searched (k-d tree)."""
    from scipy.spatial import cKDTree

    k = min(FILTER_NEIGHBOURS, len(p))
    dist, idx = cKDTree(p).query(p, k=k)
    dist, idx = dist.reshape(len(p), k), idx.reshape(len(p), k)
    # self first even where a coincident vertex (a mesh's split normals) came first
    r = np.arange(len(p))
    at = np.argmax(idx == r[:, None], axis=1)  # 0 where self is first or missing
    idx[r, at], dist[r, at] = idx[:, 0], dist[:, 0]
    idx[:, 0], dist[:, 0] = r, 0.0
    idx = np.where(np.einsum("vk,vnk->vn", nrm, nrm[idx]) >= FILTER_MIN_COS, idx, -1)
    return idx, dist


def surface_filter(values, width, idx, dist, rows=None, passes: int = 1) -> np.ndarray:
    """Gaussian filter of per-vertex values over neighbouring receivers, ``(R, C)``.

    Each filtered receiver ``v`` averages the values of its neighbours within
    ``2 width_v``, weighted by ``exp(-|p_u - p_v|^2 / 2 width_v^2) - exp(-2)`` (a
    Gaussian lowered to 0 at the cut); a receiver of width 0 keeps its value.

    Parameters
    ----------
    values : array_like, shape (N, C)
    width : array_like, shape (R,)
        Standard deviation of each filtered receiver's Gaussian (world units).
    idx, dist : ndarray, shape (R, K)
        Each filtered receiver's neighbours (indices into the ``N`` rows, -1 for none)
        and their distances, itself first (:func:`neighbours`).
    rows : ndarray of int, shape (R,), optional
        The filtered receivers' own rows of ``values`` (needed when ``passes > 1``).
    passes : int
        Times the filter is applied, each pass reading the last one's values on
        ``rows`` (the other rows keep theirs): the variances add up, and the support
        grows ``passes`` times past the ``K`` neighbours.
    """
    from scipy import sparse

    x = np.asarray(values, dtype=np.float64)
    sigma = np.asarray(width, dtype=np.float32).reshape(-1, 1)
    inside = (idx >= 0) & (dist <= 2.0 * sigma) & (sigma > 0)
    u = np.where(inside, dist, 0.0).astype(np.float32) / np.where(sigma > 0, sigma, 1.0)
    # lowered to 0 at the cut (2 widths): no step where a neighbour enters the window
    w = np.where(inside, np.maximum(np.exp(-0.5 * u * u) - np.float32(_CUT), 0.0), 0.0)
    w[sigma[:, 0] <= 0, 0] = 1.0  # a receiver of width 0 keeps its own value
    total = w.sum(axis=1, dtype=np.float64)[:, None]
    k = idx.shape[1]
    m = sparse.csr_matrix((w.ravel(), np.maximum(idx, 0).ravel(), np.arange(0, w.size + 1, k)),
                          shape=(len(w), len(x)))
    out = (m @ x) / total
    if passes > 1:  # the passes between in float32 (the weights' precision)
        x = x.astype(np.float32)
        for _ in range(passes - 1):
            x[rows] = out
            out = (m @ x) / total
    return out


def receiver_spacing(idx, dist) -> np.ndarray:
    """Each receiver's spacing ``(R,)``: the distance to its ``SPACING_NEIGHBOUR``-th
    nearest neighbour facing the same way (a grid's edge neighbours; robust to a
    coincident duplicate vertex), infinite when it has none.

    Parameters
    ----------
    idx, dist : ndarray, shape (R, K)
        Neighbours and their distances, self first (:func:`neighbours`).
    """
    d = np.where((idx >= 0) & (dist > 0), dist, np.inf)
    d.sort(axis=1)
    k = min(SPACING_NEIGHBOUR, d.shape[1]) - 1
    return d[:, k] if k >= 0 else np.full(len(d), np.inf)
