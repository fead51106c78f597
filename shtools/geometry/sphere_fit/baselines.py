"""Baseline sphere sets for comparison at equal sphere counts.

``"octree"``: circumscribed spheres of occupied octree cells (Hubbard 1995),
refined largest-first until about N cells.  ``"kmeans"``: k-means clusters of
the solid's points, each with its minimal bounding sphere.
"""

from __future__ import annotations

import numpy as np

from shtools.geometry.sphere_fit.solid import Solid
from shtools.geometry.sphere_set import minimal_bounding_sphere


def _octree(solid: Solid, n: int):
    """Circumscribed spheres of occupied octree cells, largest cells refined first."""
    pts = solid.points
    lo = pts.min(axis=0)
    size = float(np.ptp(pts, axis=0).max()) * (1 + 1e-9)
    # a cell is (corner (3,), size, member indices)
    cells = [(lo, size, np.arange(len(pts)))]
    offsets = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    while True:
        order = sorted(range(len(cells)), key=lambda c: (-cells[c][1], -len(cells[c][2])))
        split = False
        for c in order:
            corner, s, members = cells[c]
            half = s / 2
            octant = np.floor((pts[members] - corner) / half).clip(0, 1).astype(int)
            key = octant[:, 0] * 4 + octant[:, 1] * 2 + octant[:, 2]
            children = [(corner + offsets[o] * half, half, members[key == o])
                        for o in range(8) if np.any(key == o)]
            # a single occupied child only shrinks the cell: always worth it
            if len(cells) - 1 + len(children) <= n and (len(children) > 1 or s > 1e-6 * size):
                cells = cells[:c] + cells[c + 1:] + children
                split = True
                break
        if not split:
            break
    centers = np.array([corner + s / 2 for corner, s, _ in cells])
    radii = np.array([s * np.sqrt(3) / 2 for _, s, _ in cells])
    labels = np.empty(len(pts), dtype=np.int64)
    for i, (_, _, members) in enumerate(cells):
        labels[members] = i
    return centers, radii, labels


def _kmeans(solid: Solid, n: int, rng: np.random.Generator):
    """k-means clusters of the points, each bounded by its minimal sphere."""
    from scipy.cluster.vq import kmeans2

    _, labels = kmeans2(solid.points, n, minit="++", seed=rng, iter=30)
    centers, radii = [], []
    new_labels = np.empty_like(labels)
    for j in np.unique(labels):
        c, r = minimal_bounding_sphere(solid.points[labels == j])
        new_labels[labels == j] = len(centers)
        centers.append(c)
        radii.append(r)
    return np.array(centers), np.array(radii), new_labels
