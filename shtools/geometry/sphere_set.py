"""The sphere set: spheres bounding a solid, as SHEXP uses for blockers."""

from __future__ import annotations

from itertools import combinations

import numpy as np

# the SphereSet dataclass lives with its asset (data_formats may not import geometry)
from shtools.data_formats.spheres import SphereSet

__all__ = ["SphereSet", "hull_vertices", "minimal_bounding_sphere"]


#: Subsets of ``s`` core points of size ``k`` (index arrays), by (s, k).
_SUBSETS: dict = {}

#: Core points at most (a safety net: the fits' clusters need far fewer).
MAX_CORE = 40


def minimal_bounding_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The minimal sphere containing every point (exactly bounding).

    A core set: the minimal ball of a few points is the smallest ball
    circumscribed about 2-4 of them that holds them all (every subset tried at
    once, vectorised); the point farthest outside it joins them, until none is
    outside.  The core stays small, so this is exact up to rounding and
    faster than an SLSQP solve on the convex hull (the two agree: radii to
    1e-12, centres to 1e-8 of the radius, where the radius is flat).  The
    radius returned is the largest distance from the centre, so the sphere
    bounds every point whatever the rounding.

    Parameters
    ----------
    points : ndarray, shape (P, 3)

    Returns
    -------
    center : ndarray, shape (3,)
    radius : float
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        raise ValueError("need at least one point")
    a = points[np.argmax(np.sum((points - points.mean(axis=0)) ** 2, axis=1))]
    b = int(np.argmax(np.sum((points - a) ** 2, axis=1)))
    core = [int(np.argmax(np.sum((points - points[b]) ** 2, axis=1))), b]
    while True:
        center, r2 = _core_ball(points[core])
        d2 = np.sum((points - center) ** 2, axis=1)
        far = int(np.argmax(d2))
        if d2[far] <= r2 * (1 + 1e-12) or far in core or len(core) >= MAX_CORE:
            return center, float(np.sqrt(d2[far]))
        core.append(far)


def _core_ball(core: np.ndarray) -> tuple[np.ndarray, float]:
    """(centre, squared radius) of the minimal ball of a few points ``(s, 3)``.

    The minimal ball has 1-4 of the points on its boundary and its centre in
    their affine hull: the smallest such circumscribed ball that holds every
    point.  A subset's ball: centre ``p0 + Σ x_j (p_j - p0)`` with ``G x =
    diag(G) / 2``, ``G`` the Gram matrix of the ``p_j - p0``; (nearly)
    degenerate subsets (collinear, coplanar) are skipped, their points are
    handled by smaller subsets.
    """
    s = len(core)
    # the ball about the mean holding every point: valid, rarely minimal
    best_c = core.mean(axis=0)
    best_r2 = float(np.max(np.sum((core - best_c) ** 2, axis=1)))
    for k in range(2, min(4, s) + 1):
        if (s, k) not in _SUBSETS:
            _SUBSETS[s, k] = np.array(list(combinations(range(s), k)), dtype=np.int64)
        pts = core[_SUBSETS[s, k]]  # (C, k, 3)
        rel = pts[:, 1:] - pts[:, :1]  # (C, k - 1, 3)
        gram = rel @ rel.transpose(0, 2, 1)
        trace = np.einsum("cii->c", gram)
        ok = np.abs(np.linalg.det(gram)) > 1e-12 * np.maximum(trace, 1e-300) ** (k - 1)
        if not np.any(ok):
            continue
        x = np.linalg.solve(gram[ok], 0.5 * np.einsum("cii->ci", gram[ok])[..., None])
        centers = pts[ok, 0] + np.einsum("ck,ckd->cd", x[..., 0], rel[ok])
        r2 = np.sum((centers - pts[ok, 0]) ** 2, axis=1)
        d2 = np.sum((core[None] - centers[:, None]) ** 2, axis=-1)  # (C', s)
        holds = np.all(d2 <= r2[:, None] * (1 + 1e-10), axis=1)
        if np.any(holds):
            j = np.flatnonzero(holds)[np.argmin(r2[holds])]
            if r2[j] < best_r2:
                best_c, best_r2 = centers[j], float(r2[j])
    return best_c, best_r2


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """Convex-hull vertices of ``points (P, 3)``; all points when the hull is degenerate."""
    from scipy.spatial import ConvexHull, QhullError

    if len(points) < 5:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):  # coplanar or collinear points
        return points
