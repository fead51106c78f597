"""The solid a sphere set must bound, discretised for fitting.

Surface samples (with the mesh's vertices) and interior grid corners, inside
or outside by generalized winding numbers (libigl: robust for open scans,
several components and non-manifold vertices); a k-nearest-neighbour graph
for the flood fill (:mod:`.lloyd`); flux samples for the inner loop's
V(S - T) (:class:`~shtools.geometry.outside_volume.FluxSamples`); and the
dense cover points every final sphere set must contain (:mod:`.cover`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from shtools.errors import InputError
from shtools.geometry.outside_volume import FluxSamples, OutsideVolume
from shtools.geometry.sphere_set import hull_vertices

#: Points per sphere for the discretisation (surface and interior each), clipped
#: to [MIN_POINTS, MAX_POINTS]: enough for every cluster to have a shape, few
#: enough for the flood fill to stay interactive.  Below MIN_POINTS /
#: POINTS_PER_SPHERE (125) spheres the point set does not depend on N, so that
#: fits at different N bound the same points: a point set that grows with N
#: makes the larger fit cover more points, which can cost more E than its
#: extra spheres save.
POINTS_PER_SPHERE = 16
MIN_POINTS = 2000
MAX_POINTS = 8000

#: Mesh vertices added to the surface points (a random subset beyond this).
#: The whole surface is covered at the end anyway (:mod:`.cover`); these only
#: steer the clustering, and the flood fill costs points x N per round, so
#: more of them buy CPU, not a lower E.
MAX_VERTEX_POINTS = 5_000

#: Neighbours per point in the flood-fill graph.
NEIGHBOURS = 10

#: Solid volume below this fraction of diag³ counts as "no volume".
ZERO_VOLUME_FRACTION = 1e-7

#: Quadrature for the inner loop: triangles split until edges <= diag / this,
#: or merged per cell beyond a budget of samples per sphere (clipped).  Spheres
#: shrink as N grows, so the quadrature they need refines with N.
FLUX_EDGE_DIVISOR = 120
FLUX_SAMPLES_PER_SPHERE = 500
MIN_FLUX_SAMPLES = 4_000
MAX_FLUX_SAMPLES = 16_000

#: Evenly spread surface points added to the points the spheres must contain:
#: dense enough that the shrink steps open no gaps between the sparser fitting
#: samples, which the final cover would have to close by growing spheres.
COVER_SURFACE_POINTS = 20_000

#: Radius (fraction of the diagonal) below which a sphere counts as redundant.
DEAD_RADIUS = 1e-9


@dataclass
class Solid:
    """A mesh discretised for sphere fitting.

    Attributes
    ----------
    mesh : trimesh.Trimesh
    evaluator : OutsideVolume
        Accurate V(S - T).
    flux : FluxSamples
        Fast V(S - T) for the optimiser.
    surface : ndarray, shape (S, 3)
        Surface samples.
    points : ndarray, shape (P, 3)
        Surface samples followed by interior grid corners.
    neighbors : ndarray, shape (P, k), int
    cover : ndarray, shape (C, 3)
        Every point the final spheres must contain (samples and vertices).
    cover_tree : scipy.spatial.cKDTree
        Of ``cover``.
    volume : float
    diag : float
    evaluations : int
        Outside-volume evaluations of single spheres by the inner loop so far
        (a radial profile counts once): a deterministic measure of the work.
    sample_terms : int
        Flux-sample terms summed by the centre searches so far (one sample
        for one candidate centre): the deterministic measure of their cost.
    recentred : dict
        Results of :func:`.recenter._recenter` by (start, step, points) digest.
    hulls : dict
        Convex hulls by point-index digest (see :meth:`hull`).
    """

    mesh: trimesh.Trimesh
    evaluator: OutsideVolume
    flux: FluxSamples
    surface: np.ndarray
    points: np.ndarray
    neighbors: np.ndarray
    cover: np.ndarray
    cover_tree: cKDTree
    volume: float
    diag: float
    evaluations: int = 0
    sample_terms: int = 0
    recentred: dict = field(default_factory=dict)
    hulls: dict = field(default_factory=dict)

    @cached_property
    def points_tree(self) -> cKDTree:
        """k-d tree of ``points`` (they never change: built once, not per round)."""
        return cKDTree(self.points)

    def outside_estimate(self, centers: np.ndarray, radii: np.ndarray) -> float:
        """Σ V(S_i - T) of a set ``(N, 3), (N,)`` by the inner-loop quadrature,
        counted as N evaluations."""
        self.evaluations += len(centers)
        return float(np.sum(self.flux.outside_volumes(centers, radii)))

    def hull(self, points: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Convex-hull vertices of ``points[index]``, remembered by the points
        themselves (settled clusters keep their points from round to round).

        The key is a digest of the coordinates, not of ``index`` and the array's
        ``id``: a freed array's ``id`` is reused by the next one, which made the
        fit depend on memory layout (two results for one seed, seen across runs)."""
        chosen = points[np.sort(index)]
        key = hashlib.blake2b(np.ascontiguousarray(chosen).tobytes(), digest_size=16).digest()
        if key not in self.hulls:
            self.hulls[key] = hull_vertices(chosen)
        return self.hulls[key]


def discretize(mesh: trimesh.Trimesh, n: int, *, seed: int = 0, samples: int | None = None,
               path=None) -> Solid:
    """Sample a mesh's surface and interior for fitting ``n`` spheres.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    n : int
        Number of spheres (sets the sample density).
    seed : int
    samples : int, optional
        Surface samples and (about) interior grid points, each; default
        ``POINTS_PER_SPHERE * n`` clipped to [MIN_POINTS, MAX_POINTS].
    path : path-like, optional
        Named in error messages.

    Returns
    -------
    Solid

    Raises
    ------
    InputError
        The mesh encloses no volume (suggests ``--thickness``).
    """
    import igl

    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    f = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    evaluator = OutsideVolume(mesh)
    volume = evaluator.volume
    flat_msg = ("the mesh encloses no volume (a flat or open sheet); pass --thickness T "
                "to fit spheres to a shell of thickness T")
    if not diag > 0 or not abs(volume) > ZERO_VOLUME_FRACTION * diag**3:
        raise InputError(flat_msg, path)
    if volume < 0:
        raise InputError("the mesh is inside out (negative volume); flip its faces", path)
    target = int(samples) if samples else int(np.clip(POINTS_PER_SPHERE * n, MIN_POINTS,
                                                         MAX_POINTS))
    # interior: grid corners inside T, spacing for ~target points
    h = max((volume / target) ** (1.0 / 3.0), diag / 400.0)
    counts = np.maximum(np.ceil((hi - lo) / h).astype(int), 1)
    offset = lo + 0.5 * ((hi - lo) - (counts - 1) * h)
    axes = [offset[k] + h * np.arange(counts[k]) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = igl.fast_winding_number(v, f, grid) >= 0.5
    interior = grid[inside]
    if len(interior) == 0:
        raise InputError(flat_msg, path)
    surface, _ = trimesh.sample.sample_surface(mesh, target, seed=seed)
    # mesh vertices are surface points too: clustering them keeps sharp tips
    # (ears, horns) inside spheres the optimiser knows about
    verts = v if len(v) <= MAX_VERTEX_POINTS else v[
        np.random.default_rng(seed).choice(len(v), MAX_VERTEX_POINTS, replace=False)]
    surface = np.vstack([np.asarray(surface, dtype=np.float64), verts])
    points = np.vstack([surface, interior])
    k = min(NEIGHBOURS + 1, len(points))
    _, nb = cKDTree(points).query(points, k=k)
    # spheres shrink as N grows, so the quadrature they need refines with N
    budget = int(np.clip(FLUX_SAMPLES_PER_SPHERE * n, MIN_FLUX_SAMPLES, MAX_FLUX_SAMPLES))
    flux = FluxSamples.from_mesh(mesh, max_edge=diag / FLUX_EDGE_DIVISOR, max_samples=budget)
    # the spheres must hold the whole surface (see .cover): dense, evenly
    # spread surface points keep the shrink steps from opening gaps
    # between the sparser fitting samples that the final cover must close
    even = np.asarray(trimesh.sample.sample_surface_even(mesh, COVER_SURFACE_POINTS,
                                                         seed=seed + 2)[0], dtype=np.float64)
    cover = np.vstack([points, even])
    return Solid(mesh, evaluator, flux, surface, points, np.asarray(nb)[:, 1:], cover,
                 cKDTree(cover), float(volume), diag)


def _squared_distances(points: np.ndarray, centers_t: np.ndarray) -> np.ndarray:
    """|p - c|² of points ``(P, 3)`` to centres given as coordinate rows ``(3, N)``
    -> (P, N), summed axis by axis as ``np.linalg.norm`` does (the same bits),
    without a (P, N, 3) temporary."""
    d2 = points[:, 0, None] - centers_t[0]
    d2 *= d2
    for axis in (1, 2):
        d = points[:, axis, None] - centers_t[axis]
        d *= d
        d2 += d
    return d2
