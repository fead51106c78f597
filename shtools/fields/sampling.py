r"""Shadow-field sampling: the object's visibility seen from points around it, in SH.

* :func:`bounding_sphere` -- the object's minimal bounding sphere (centre, ``V_r``);
* :func:`shell_radii` -- Tamura's ``r_c = 0.2 V_r (1 + c)``;
* :func:`direction_map` -- the per-sample direction set: Tamura et al.'s 64 x 64
  (theta, phi) map, cell-centred, each direction weighted by its cell's exact
  solid angle (``(cos theta_lo - cos theta_hi) 2 pi / M``), so the weights sum
  to ``4 pi`` exactly;
* :func:`object_visibility` -- binary visibility of an object from points over
  a direction set, **cone-culled**: from a point at distance ``d > V_r`` of the
  centre only directions within ``asin(V_r / d)`` of the centre can hit the
  object, the others are exactly unoccluded and are not cast (about 19 % of
  the rays remain over the 32 default shells).  Public so that other samplers
  (deformable fields on a bounding sphere) reuse it;
* :func:`sample_ocvs` -- that visibility projected to SH (the OCV), per point.

Ray casting itself is :class:`shtools.geometry.raycast.RayCaster`.
"""

from __future__ import annotations

import math

import numpy as np

from shtools.sh import basis

#: Shell spacing and first radius as a fraction of V_r (Tamura Sec. 6).
SHELL_STEP = 0.2
#: Points per cast batch (four rows of a 64 x 64 shell: a narrow polar-angle band).
POINT_CHUNK = 256
#: Relative margin on the bounding radius of the cone cull: the test runs in
#: float32, whose round-off (~1e-7 of the distance) is far below what this margin
#: adds to the cone (>= 2e-6 of the distance out to 6.4 V_r), so no ray that can
#: touch the bounding sphere is ever culled.
CONE_MARGIN = 1e-4


def bounding_sphere(vertices) -> tuple[np.ndarray, float]:
    """Minimal bounding sphere of points (trimesh's ``minimum_nsphere``).

    Parameters
    ----------
    vertices : array_like, shape (P, 3)

    Returns
    -------
    center : ndarray, shape (3,)
    radius : float
    """
    from trimesh import nsphere

    center, radius = nsphere.minimum_nsphere(np.asarray(vertices, dtype=np.float64))
    return np.asarray(center, dtype=np.float64), float(radius)


def shell_radii(bounding_radius: float, shells: int) -> np.ndarray:
    """``r_c = 0.2 V_r (1 + c)``, ``c < shells``, shape (C,)."""
    return SHELL_STEP * float(bounding_radius) * (1.0 + np.arange(shells))


def grid_directions(res: int) -> np.ndarray:
    """Unit directions of the cell-centred (theta, phi) grid, shape ``(R, R, 3)``.

    theta from the pole axis ``+z`` (first index), phi from ``+x`` towards ``+y``
    (second index); ``theta_s = (s + 1/2) pi / R``, ``phi_t = (t + 1/2) 2 pi / R``.
    """
    k = np.arange(res) + 0.5
    theta = k * math.pi / res
    phi = k * 2 * math.pi / res
    st = np.sin(theta)[:, None]
    return np.stack([st * np.cos(phi)[None, :], st * np.sin(phi)[None, :],
                     np.broadcast_to(np.cos(theta)[:, None], (res, res))], axis=-1)


def direction_map(size: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``size x size`` (theta, phi) direction map with exact cell solid angles.

    Returns
    -------
    dirs : ndarray, shape (size*size, 3)
    weights : ndarray, shape (size*size,)
        Solid angle of each cell; they sum to ``4 pi``.
    """
    edges = np.cos(np.arange(size + 1) * math.pi / size)
    band = (edges[:-1] - edges[1:]) * (2 * math.pi / size)
    dirs = grid_directions(size).reshape(-1, 3)
    return dirs, np.repeat(band, size)


def cone_mask(points, center, radius: float, dirs) -> np.ndarray:
    """Directions from each point that can hit a sphere, shape ``(P, Q)`` bool.

    Points inside the sphere (``d <= radius``) get every direction.
    """
    rel = np.asarray(center, dtype=np.float64) - np.asarray(points, dtype=np.float64)
    d = np.linalg.norm(rel, axis=1)
    r = radius * (1 + CONE_MARGIN)
    cos_cone = np.sqrt(np.clip(1.0 - (r / np.maximum(d, 1e-300)) ** 2, 0.0, 1.0))
    cos_cone = np.where(d > r, cos_cone, -2.0)
    unit = (rel / np.maximum(d, 1e-300)[:, None]).astype(np.float32)
    return (unit @ np.asarray(dirs, dtype=np.float32).T) >= cos_cone.astype(np.float32)[:, None]


def object_visibility(caster, center, radius: float, points, dirs, *,
                      stats: dict | None = None) -> np.ndarray:
    """Binary visibility of one object from points, cone-culled.

    Only rays inside the cone of the bounding sphere are cast; the others are
    unoccluded.  Points are taken in chunks; a chunk tests only the directions
    whose polar angle can fall in some point's cone (a band of the direction
    set sorted by polar angle), so far shells, whose cones are narrow, do not
    pay for the whole direction set.

    Parameters
    ----------
    caster : shtools.geometry.raycast.RayCaster
        The object's triangles.
    center : array_like, shape (3,)
    radius : float
        A sphere bounding every triangle of ``caster``.
    points : array_like, shape (P, 3)
        Viewpoints (typically outside the sphere; inside ones cast every ray).
        Neighbouring rows should be neighbouring points (e.g. a shell's grid in
        row order) for the band to be narrow.
    dirs : array_like, shape (Q, 3)
        Unit directions.
    stats : dict, optional
        ``stats["rays"]`` is increased by the number of rays cast.

    Returns
    -------
    ndarray of bool, shape (P, Q)
        True where the direction is unoccluded.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    dirs32 = np.ascontiguousarray(dirs, dtype=np.float32)
    Q = dirs32.shape[0]
    theta_dir = np.arccos(np.clip(np.asarray(dirs, dtype=np.float64)[:, 2], -1.0, 1.0))
    by_theta = np.argsort(theta_dir, kind="stable")
    sorted_theta = theta_dir[by_theta]
    origins = caster.embree_points(p)
    center = np.asarray(center, dtype=np.float64)
    r = radius * (1 + CONE_MARGIN)
    vis = np.ones((p.shape[0], Q), dtype=bool)
    for s in range(0, p.shape[0], POINT_CHUNK):
        pp = p[s:s + POINT_CHUNK]
        rel = center - pp
        d = np.linalg.norm(rel, axis=1)
        if np.any(d <= r):
            sel = np.arange(Q)
        else:
            theta_axis = np.arccos(np.clip(rel[:, 2] / d, -1.0, 1.0))
            half = np.arcsin(r / d) + 1e-6  # + float32 slack of the mask
            lo = np.searchsorted(sorted_theta, (theta_axis - half).min(), side="left")
            hi = np.searchsorted(sorted_theta, (theta_axis + half).max(), side="right")
            sel = np.sort(by_theta[lo:hi])
        mask = cone_mask(pp, center, radius, dirs32[sel])
        counts = mask.sum(axis=1)
        row, col = np.nonzero(mask)  # row-major: each point's rays are consecutive
        if stats is not None:
            stats["rays"] = stats.get("rays", 0) + int(row.size)
        if row.size == 0:
            continue
        qi = sel[col]
        hit = caster.occluded_embree(np.repeat(origins[s:s + POINT_CHUNK], counts, axis=0),
                                     np.take(dirs32, qi, axis=0))
        vis[s + row[hit], qi[hit]] = False
    return vis


def sample_ocvs(caster, center, radius: float, points, dirs, weights, order: int, *,
                stats: dict | None = None) -> np.ndarray:
    """Occlusion coefficient vectors (SH visibility) of an object at points.

    Parameters
    ----------
    caster, center, radius, points, dirs, stats
        As :func:`object_visibility`.
    weights : array_like, shape (Q,)
        Quadrature weights of ``dirs``.
    order : int

    Returns
    -------
    ndarray, shape (P, n*n)
        ``sum_q weights[q] vis[p, q] y(dirs[q])``.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    yw = basis(np.asarray(dirs, dtype=np.float64), order) * np.asarray(weights)[:, None]
    out = np.empty((p.shape[0], order * order))
    for s in range(0, p.shape[0], POINT_CHUNK):
        vis = object_visibility(caster, center, radius, p[s:s + POINT_CHUNK], dirs, stats=stats)
        out[s:s + POINT_CHUNK] = vis.astype(np.float32) @ yw
    return out
