"""Ray-traced ground truth: binary visibility on a quadrature set of directions.

Visibility of a receiver ``p`` with normal ``N`` in direction ``s`` is 0 when a
ray from ``p`` along ``s`` hits a blocker and 1 otherwise; **directions below
the tangent plane** (``s . N <= 0``) **count as visible** — the convention the
SHEXP self-shadow rules implement (they remove everything behind the plane),
and harmless for shading since ``H(N)`` weighs those directions by 0.  The
binary function is projected to SH order ``n`` with a Gauss–Legendre x uniform
quadrature (:func:`shtools.sh.sphere_quadrature`); a discontinuous function is
not integrated exactly by any rule, so ``n_dirs`` sets the accuracy (about
``1/sqrt(n_dirs)`` in the worst case, far less in practice).

* :func:`raytrace_visibility`: against the actual triangle meshes (Embree via
  ``trimesh.ray``); ray origins are offset along ``N`` to avoid self-hits;
* :func:`sphere_union_visibility`: against the union of the blocker spheres,
  exactly (analytic ray-sphere), optionally after the runtime's self-shadow
  rules so that only the SH errors remain (Fig. 7b vs c–d).
"""

from __future__ import annotations

import numpy as np

from shtools.geometry.visibility import RAY_OFFSET, direction_quadrature
from shtools.runtime.self_shadow import apply_self_shadow_rules
from shtools.sh import project

#: Default number of quadrature directions.
DEFAULT_DIRECTIONS = 2000
#: Elements of the (vertices x directions x spheres) block of the sphere tracer.
_SPHERE_BLOCK = 1 << 22


def raytrace_visibility(vertices, normals, meshes, order: int, n_dirs: int = DEFAULT_DIRECTIONS,
                        *, offset: float | None = None) -> np.ndarray:
    """Ray-traced visibility of triangle meshes, projected to SH.

    Parameters
    ----------
    vertices, normals : array_like, shape (V, 3)
        Receivers and unit normals.
    meshes : list of trimesh.Trimesh
        Blocker geometry (may include the receiver's own mesh for self-shadowing).
    order : int
        SH order ``n``.
    n_dirs : int
        Minimum number of quadrature directions.
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` x the
        meshes' bounding-box diagonal).

    Returns
    -------
    ndarray, shape (V, n*n)
    """
    from shtools.geometry.raycast import RayCaster

    p = np.asarray(vertices, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    dirs, w = direction_quadrature(n_dirs)
    caster = RayCaster.from_meshes(list(meshes))
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    vis = caster.visibility(p, dirs, normals=nrm, offset=offset).astype(np.float64)
    return project(vis, dirs, w, order)


def sphere_union_visibility(vertices, normals, centers, radii, order: int,
                            n_dirs: int = DEFAULT_DIRECTIONS, *, self_shadow: bool = True
                            ) -> np.ndarray:
    """Exact visibility of a union of spheres (analytic ray-sphere), projected to SH.

    Parameters
    ----------
    vertices, normals : array_like, shape (V, 3)
    centers : array_like, shape (S, 3)
    radii : array_like, shape (S,)
    order : int
    n_dirs : int
        Minimum number of quadrature directions.
    self_shadow : bool
        Replace the spheres per receiver by the Sec. 6.2 rules first (what the
        runtime shades with); False traces the spheres as given.

    Returns
    -------
    ndarray, shape (V, n*n)
    """
    p = np.asarray(vertices, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    cen = np.asarray(centers, dtype=np.float64)
    rad = np.asarray(radii, dtype=np.float64)
    dirs, w = direction_quadrature(n_dirs)
    vis = np.ones((p.shape[0], dirs.shape[0]))
    if cen.shape[0] == 0:
        return project(vis, dirs, w, order)
    step = max(1, _SPHERE_BLOCK // (dirs.shape[0] * cen.shape[0]))
    for s in range(0, p.shape[0], step):
        pp, nn = p[s : s + step], nrm[s : s + step]
        delta = cen[None, :, :] - pp[:, None, :]  # (v, S, 3)
        r = np.broadcast_to(rad[None, :], delta.shape[:2])
        if self_shadow:
            dx, dy, dz, r = apply_self_shadow_rules(
                delta[..., 0], delta[..., 1], delta[..., 2], r,
                nn[:, None, 0], nn[:, None, 1], nn[:, None, 2])
            delta = np.stack([dx, dy, dz], axis=-1)
        c = np.einsum("vsk,vsk->vs", delta, delta) - r * r  # < 0: receiver inside
        b = delta @ dirs.T  # (v, S, Q): distance along the ray to the closest approach
        hit = ((b > 0) & (b * b > c[..., None]) & (r[..., None] > 0)) | (c[..., None] < 0)
        blocked = hit.any(axis=1)  # (v, Q)
        front = nn @ dirs.T > 0
        vis[s : s + step][blocked & front] = 0.0
    return project(vis, dirs, w, order)
