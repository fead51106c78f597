"""The sphere set: spheres bounding a solid, as SHEXP uses for blockers."""

from __future__ import annotations

import numpy as np

# the SphereSet dataclass lives with its asset (data_formats may not import geometry)
from shtools.data_formats.spheres import SphereSet

__all__ = ["SphereSet", "hull_vertices", "minimal_bounding_sphere"]


#: Iterations of the Badoiu–Clarkson core-set walk; its radius is within a
#: factor (1 + 1/sqrt(iterations)) of the minimum before the polish step.


def minimal_bounding_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """A near-minimal sphere containing every point (exactly bounding).

    Parameters
    ----------
    points : ndarray, shape (P, 3)

    Returns
    -------
    center : ndarray, shape (3,)
    radius : float
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    hull = hull_vertices(points)
    from shtools.geometry.bounding import minimal_enclosing_sphere

    return minimal_enclosing_sphere(hull, np.zeros(len(hull)))


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """Convex-hull vertices of ``points (P, 3)``; all points when the hull is degenerate."""
    from scipy.spatial import ConvexHull, QhullError

    if len(points) < 5:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):  # coplanar or collinear points
        return points
