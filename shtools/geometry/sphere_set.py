"""The sphere set: spheres bounding a solid, as SHEXP uses for blockers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SphereSet:
    """A set of spheres bounding a solid.

    Attributes
    ----------
    centers : ndarray, shape (N, 3), float64
    radii : ndarray, shape (N,), float64
    outside_volume_ratio : float
        E = sum_i V(S_i - T) / V(T): the volume the spheres add outside the
        solid T, summed over spheres, relative to T's volume (NaN if unknown,
        e.g. after importing a ``.sph`` file without its mesh).
    coverage : float
        Fraction of surface samples inside at least one sphere (1.0 for a
        bounding set; NaN if unknown).
    method : str
        How the set was made (``"variational"``, ``"octree"``, ``"kmeans"``,
        ``"import"``).
    info : dict
        Extra diagnostics (iterations, timings, solid volume, ...).
    """

    centers: np.ndarray
    radii: np.ndarray
    outside_volume_ratio: float = float("nan")
    coverage: float = float("nan")
    method: str = ""
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.centers = np.ascontiguousarray(self.centers, dtype=np.float64).reshape(-1, 3)
        self.radii = np.ascontiguousarray(self.radii, dtype=np.float64).reshape(-1)
        if len(self.centers) != len(self.radii):
            raise ValueError(
                f"centers {self.centers.shape} and radii {self.radii.shape} disagree"
            )

    def __len__(self) -> int:
        return len(self.radii)

    def contains(self, points: np.ndarray, *, tolerance: float = 0.0) -> np.ndarray:
        """Which points lie inside at least one sphere.

        Parameters
        ----------
        points : ndarray, shape (P, 3)
        tolerance : float
            Added to every radius.

        Returns
        -------
        ndarray, shape (P,), bool
        """
        from scipy.spatial import cKDTree

        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        inside = np.zeros(len(points), dtype=bool)
        if len(self) == 0 or len(points) == 0:
            return inside
        tree = cKDTree(points)
        for c, r in zip(self.centers, self.radii + tolerance, strict=True):
            inside[tree.query_ball_point(c, r)] = True
        return inside


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
