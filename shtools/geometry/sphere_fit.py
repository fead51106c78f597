"""Fit a set of N spheres that bounds a mesh's solid with minimal outside volume.

``method="variational"`` is the algorithm of Wang et al. 2006 as summarised in
SHEXP (Ren et al. 2006, section 6.2):

1. Discretise the solid T into surface samples and interior grid corners;
   inside/outside by generalized winding numbers (libigl), robust for open
   scans, several components and non-manifold vertices.
2. Flood-fill clustering: fronts grow over a k-nearest-neighbour graph from
   each sphere centre; every point joins the cluster whose sphere's outside
   volume V(S - T) grows least when its radius is extended to include it
   (radial outside-volume profiles per centre make this a table look-up).
   Fronts are processed as vectorised batches (breadth first) instead of one
   point per stack pop.
3. Centre update: every cluster's centre moves to minimise V(S - T) with the
   radius bounding the cluster's points, all spheres in one batched compass
   search (:func:`_recenter`; each pass sums only the flux samples a move of
   the current step can reach, and only for the spheres still searching).
   Then each sphere shrinks to the points no other sphere covers (E sums the
   spheres' outside volumes, so a point inside another sphere need not hold a
   radius up; k-d tree queries, not points x spheres) and is re-centred for
   those points; the union still covers every point.  V(S - T) in this inner
   loop comes from :class:`FluxSamples` (centroid rule of the flux on small
   triangles, radial profiles for the flood fill).
4. Cluster teleportation: when an iteration no longer lowers E, split the
   cluster of largest outside volume at its farthest-apart points and delete
   another sphere — TELEPORT_CANDIDATES choices (the most overlapped one, or
   those covering the fewest points nobody else covers), one Lloyd step each;
   the best is refined and kept only if E drops.  Later stalls split the
   next-worst clusters.  Lloyd steps are memoised (they are deterministic), so
   returning to the best state after a rejected teleport costs nothing.

5. Coarse to fine: from N = COARSE_TO_FINE_MIN on, the search starts from a
   fit of ceil(N/2) spheres (itself fitted the same way) whose clusters with
   the largest gain are split in two, so that E keeps falling as N grows;
   Lloyd steps and teleports then refine at N.  Each stage spends part of one
   work budget (rounds x spheres).  From SPLIT_START_MIN to
   COARSE_TO_FINE_MIN spheres the search starts from k-means clusters split
   in two twice (:func:`_split_start`), below that from random centres.

The shrink-and-re-centre step is iterated to a fixed point at the end.  The
spheres then must hold the whole surface, not only its samples
(:func:`_settle_cover`): every radius grows just enough to contain every
point and every piece of the surface (coverage 1; a piece counts as held
when it lies in one sphere or in the union of two, :func:`_pair_held`); the
pieces that made spheres grow join the points, the spheres re-centre for
them and grow again for what is left; of these surface-bounding sets (growth
alone, growth after each re-centring pass) the one of least estimated
outside volume is kept, and E = Σ V(S_i - T)/V(T) is computed with the
accurate flux evaluator of :mod:`.outside_volume`.

Baselines for comparison at equal sphere counts: ``"octree"`` (circumscribed
spheres of occupied octree cells, Hubbard 1995, refined largest-first until
about N cells) and ``"kmeans"`` (k-means clusters of the same points, each
with its minimal bounding sphere).
"""

from __future__ import annotations

import hashlib
import time
import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse
import trimesh
from scipy.spatial import cKDTree

from shtools.errors import InputError
from shtools.geometry.fit_methods import DEFAULT_ROUNDS, FIT_METHODS
from shtools.geometry.outside_volume import FOUR_PI, FluxSamples, OutsideVolume, dot_rows
from shtools.geometry.sphere_set import SphereSet, hull_vertices, minimal_bounding_sphere

METHODS = FIT_METHODS

#: Points per sphere for the discretisation (surface and interior each), clipped
#: to [MIN_POINTS, MAX_POINTS]: enough for every cluster to have a shape, few
#: enough for the flood fill to stay interactive.  Below MIN_POINTS /
#: POINTS_PER_SPHERE (125) spheres the point set does not depend on N, so that
#: fits at different N bound the same points: at 40 per sphere the N = 128 fit
#: had to cover twice the points of the N = 64 fit, which raised its E by about
#: 10 %, more than the 64 extra spheres lowered it.
POINTS_PER_SPHERE = 16
MIN_POINTS = 2000
MAX_POINTS = 8000

#: Mesh vertices added to the surface points (a random subset beyond this).
#: The whole surface is covered at the end anyway (:func:`_cover`); these only
#: steer the clustering, and the flood fill costs points x N per round
#: (dragon N = 64: 20 000 of them cost twice the CPU for no better E).
MAX_VERTEX_POINTS = 5_000

#: Neighbours per point in the flood-fill graph.
NEIGHBOURS = 10

#: Radial profile resolution (radii from 0 to the bounding-box diagonal).
PROFILE_BINS = 512

#: Solid volume below this fraction of diag³ counts as "no volume".
ZERO_VOLUME_FRACTION = 1e-7

#: Quadrature for the inner loop: triangles split until edges <= diag / this,
#: or merged per cell beyond a budget of samples per sphere (clipped).
FLUX_EDGE_DIVISOR = 120
FLUX_SAMPLES_PER_SPHERE = 500
MIN_FLUX_SAMPLES = 4_000
MAX_FLUX_SAMPLES = 16_000

#: Largest centre move per update, as a fraction of the cluster radius (bounds
#: the samples the objective must visit; the next round continues the walk).
CENTER_STEP = 0.25

#: Powell's line-search tolerance, in units of the largest centre move.
POWELL_XTOL = 1e-2

#: Rounds of shrink-to-own-points and re-centring after the Lloyd iterations
#: (at most; they stop at a fixed point, when no sphere moves or shrinks by more
#: than SHRINK_TOLERANCE of the diagonal).
SHRINK_ROUNDS = 12
SHRINK_TOLERANCE = 1e-5

#: A fit of fewer rounds than SHRINK_ROUNDS is a quick fit: its finish scales
#: with its budget (:func:`_finish_effort`), at least this many shrink rounds.
#: With the full finish a 1-round fit of spot at N = 40 took 5.4 s, 4.2 s of
#: it finishing; a quick finish took 2.0 s there (E 0.67 instead of 0.54) and
#: 5 rounds 3.2 s (E 0.333 instead of 0.326), both from random centres; with
#: the split start 3.0 s (E 0.376) and 3.8 s (E 0.292).
QUICK_SHRINK_ROUNDS = 4

#: Distance (fraction of the diagonal) within which a point counts as on a
#: sphere during shrinking: absorbs the rounding of the mat-mul distances.
SHRINK_SLACK = 1e-9

#: Default round budget (rounds at N spheres; see ``max_iterations``) at every
#: N.  Measured: CesiumMan at N = 32, E 1.231 after 30 rounds, 1.154 after 60
#: and 90; the torus of the tests at N = 32, 0.156 / 0.115 / 0.108 after
#: 30 / 60 / 150.  From COARSE_TO_FINE_MIN spheres on the coarse fit gives the
#: search a good start, and 30 rounds had been the default there; 60 lowers
#: the mean E over seeds 0-2 (wave 5, main b600a11, load 4-8): spot N = 128
#: 0.236 -> 0.219, the tests' torus N = 64 0.084 -> 0.072, dragon N = 64
#: 0.929 -> 0.909, N = 128 0.685 -> 0.669 (spot N = 64 0.227 -> 0.226), for
#: 1.3x (dragon) to 1.55x (spot N = 128) the CPU.
ROUNDS = DEFAULT_ROUNDS

#: Teleportation candidates (split cluster, deleted sphere) tried per stall;
#: the one with the lowest E after a Lloyd step is refined and kept if E drops.
TELEPORT_CANDIDATES = 3

#: A Lloyd step or teleport counts as progress when it lowers E by more than
#: this fraction of the average sphere's share E / N.  The threshold is per
#: sphere because a teleport moves one or two spheres: a fixed fraction of the
#: total E would reject every useful teleport once N is large (at N = 128 a
#: 0.5 % drop of E is 64 % of an average sphere's outside volume).
STALL_SHARE = 0.08

#: From this N on (below COARSE_TO_FINE_MIN) the variational fit starts from
#: k-means clusters of the points, ceil(N / 2**SPLIT_LEVELS) of them, split in
#: two SPLIT_LEVELS times (:func:`_split_start`) instead of random centres:
#: spheres go to the parts of a shape as a coarse fit sends them, for a
#: fraction of its cost (0.95 s on spot at N = 40, 8 % of the fit).
#: Measured (wave 7, seeds 0-2, means against the random start): the tests'
#: character at N = 32 -20 %, capsules -27 %, CesiumMan -11 %, armadillo
#: -9 %, spot N = 32 / 40 / 48 -6 / -2 / -12 %, teapot -2 %, the bunny +2 %.
#: On the geometric mean of those ten cases one level gave -4 % and two
#: -10 %; three lost badly on compact shapes (seed 0: the bunny 0.565, spot
#: N = 32 0.443, against 0.412 and 0.286).  It replaced wave 6's race of a
#: random and a coarse start (``race=True``): raced against the split start,
#: the coarse start changed the mean E by -11 % to +7 % over those cases for
#: 1.1-1.35x the CPU.  Below N = 32 the start is random: there the coarse
#: starts predicted little (wave 6: the race lost as often as it won at
#: N = 16 and 24).
SPLIT_START_MIN = 32
SPLIT_LEVELS = 2

#: From this N on, the variational fit starts from a fit of ceil(N/2) spheres
#: whose clusters are split in two (recursively), instead of random centres:
#: Lloyd steps and one-sphere teleports relocate spheres one at a time, which
#: does not converge within the round budget once N is large (E at N = 128 was
#: no better than at N = 64).  Below 64 a coarse fit costs more than it
#: gains on compact shapes, and the split start serves (SPLIT_START_MIN).
#: The coarse fit gets COARSE_SHARE of the work budget (rounds x spheres).
COARSE_TO_FINE_MIN = 64
COARSE_SHARE = 0.5

#: Radius (fraction of the diagonal) below which a sphere counts as redundant.
DEAD_RADIUS = 1e-9

#: Smallest radius (fraction of the diagonal) of a sphere made by a split: a
#: cut that leaves a (near) single point on one side would make a vanishing
#: sphere, which the fit must not return.
MIN_CHILD_RADIUS = 1e-6

#: Surface cover: triangles not inside one sphere are split in four up to
#: COVER_LEVELS times; pieces whose circumradius is below COVER_PIECE (fraction
#: of the diagonal) are not split further but make a sphere grow.
COVER_LEVELS = 8
COVER_PIECE = 2e-4

#: Piece-sphere distances the surface cover builds at a time (a block of
#: pieces x N that stays in cache; performance only, no effect on the result).
GROW_BLOCK = 1 << 16

#: The cover also counts a piece as held when it lies in the union of two
#: spheres (:func:`_pair_held`), not only inside one: seams between spheres
#: then need no growth.  In the final cover alone this changes E by < 0.1 %;
#: through the re-centring pass (fewer piece corners join the cover points)
#: it moves E chaotically (one pass, seed 0: the tests' character at N = 32
#: 0.199 -> 0.185, spot N = 128 0.215 -> 0.213, dragon N = 64 0.940 -> 0.947).
COVER_PAIRS = True

#: Evenly spread surface points added to the points the spheres must contain.
COVER_SURFACE_POINTS = 20_000

#: Rounds of adding the surface pieces no sphere holds to the cover points and
#: re-centring the spheres for them (see :func:`_settle_cover`; the set of
#: least estimated E among the passes' results is kept, so a pass that does
#: not help costs only time).  Measured, seeds 0 / 1 / 2, one pass -> two:
#: the tests' character at N = 32 0.185 / 0.168 / 0.188 -> 0.175 / 0.160 /
#: 0.180, the torus at N = 64 0.092 / 0.095 / 0.073 -> 0.082 / 0.095 / 0.073;
#: CesiumMan N = 32 and spot N = 128 unchanged (about +1.2 s CPU on CesiumMan).
COVER_PASSES = 2

#: Fresh, evenly spread surface points on which the reported coverage is measured.
COVERAGE_SAMPLES = 20_000

#: Radius growth added to every sphere at the end (fraction of the diagonal) so
#: that points on a sphere's boundary are inside after floating-point rounding.
COVER_SLACK = 1e-9


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
        Results of :func:`_recenter` by (start, step, points) digest.
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
    # the spheres must hold the whole surface (see _cover): dense, evenly
    # spread surface points keep the shrink steps from opening gaps
    # between the sparser fitting samples that the final cover must close
    even = np.asarray(trimesh.sample.sample_surface_even(mesh, COVER_SURFACE_POINTS,
                                                         seed=seed + 2)[0], dtype=np.float64)
    cover = np.vstack([points, even])
    return Solid(mesh, evaluator, flux, surface, points, np.asarray(nb)[:, 1:], cover,
                 cKDTree(cover), float(volume), diag)


def fit_spheres(
    mesh: trimesh.Trimesh,
    n: int,
    *,
    method: str = "variational",
    seed: int = 0,
    thickness: float | None = None,
    max_iterations: int | None = None,
    max_teleport_failures: int = 8,
    samples: int | None = None,
    path=None,
    progress=None,
    restarts: int = 1,
    _desc: str = "fit",
) -> SphereSet:
    """Fit ``n`` spheres bounding the solid of ``mesh`` with minimal outside volume.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Validated mesh (:func:`shtools.geometry.mesh.load_mesh`).  Open meshes
        and several components are fine (winding numbers define the solid).
    n : int
        Number of spheres, >= 1.
    method : {"variational", "octree", "kmeans"}
    seed : int
        Seeds sampling and initialisation; the same seed gives the same spheres.
    thickness : float, optional
        Fit a shell of this thickness around the surface instead of its
        enclosed volume (for flat or open sheets).
    max_iterations : int, optional
        Budget of clustering + centre-update rounds (variational), counted
        in rounds at ``n`` spheres: the coarse stages (ceil(n/2), ... spheres)
        spend their share of it in proportionally cheaper rounds, so the total
        round count reported in ``info`` can exceed it.  Below SHRINK_ROUNDS
        the finish shortens with the budget too (:func:`_finish_effort`):
        spot at N = 40 in 3.0 s CPU for 1 round, 3.8 s for 5 (12.6 s for
        the default).
        Default ``ROUNDS``.
    max_teleport_failures : int
        Consecutive rejected teleportations before stopping (variational).
    samples : int, optional
        Surface and interior sample counts (see :func:`discretize`).
    path : path-like, optional
        Mesh file, named in error messages.
    progress : callable, optional
        A progress factory (:mod:`shtools.progress`): the fit shows one bar
        over its round budget, counted in rounds at ``n`` spheres (coarse
        rounds count by their share of the work), with the current E.
    restarts : int
        Independent starts with seeds ``seed, seed + 1, ...``; the fit with the
        lowest E is returned (the search is non-convex: on spot at N = 40,
        seeds 0-5 gave E = 0.168, 0.185, 0.164, 0.185, 0.169, 0.197).
        ``info["restart_E"]`` lists every start's E.  The knob for spending
        more CPU on a lower E.

    Returns
    -------
    SphereSet
        ``centers (N, 3)``, ``radii (N,)``, ``outside_volume_ratio`` (accurate
        flux evaluation), ``coverage`` (1.0), ``info`` with timings.

    Raises
    ------
    InputError
        Unknown method, ``n < 1``, more spheres than sample points, no volume.
    """
    if method not in METHODS:
        raise InputError(f"unknown method '{method}'; use one of {', '.join(METHODS)}")
    if int(n) != n or n < 1:
        raise InputError(f"the number of spheres must be >= 1 (got {n})")
    if int(restarts) != restarts or restarts < 1:
        raise InputError(f"restarts must be an integer >= 1 (got {restarts})")
    n = int(n)
    if restarts > 1:
        start = time.perf_counter()
        fits = [fit_spheres(mesh, n, method=method, seed=seed + k, thickness=thickness,
                            max_iterations=max_iterations,
                            max_teleport_failures=max_teleport_failures, samples=samples,
                            path=path, progress=progress,
                            _desc=f"fit {k + 1}/{restarts}")
                for k in range(int(restarts))]
        best = min(fits, key=lambda f: f.outside_volume_ratio)  # first of equals
        best.info["restart_E"] = [f.outside_volume_ratio for f in fits]
        best.info["seconds"] = time.perf_counter() - start
        return best
    from shtools.progress import silent

    with (progress or silent)(desc=_desc, unit="rounds") as bar:
        return _fit_once(mesh, n, method=method, seed=seed, thickness=thickness,
                         max_iterations=max_iterations,
                         max_teleport_failures=max_teleport_failures, samples=samples,
                         path=path, bar=bar)


def _fit_once(mesh, n, *, method, seed, thickness, max_iterations, max_teleport_failures,
              samples, path, bar) -> SphereSet:
    """One start of :func:`fit_spheres`, reporting to the progress object ``bar``."""
    start = time.perf_counter()
    if thickness is not None:
        from shtools.geometry.mesh import thicken

        mesh = thicken(mesh, float(thickness))
    # fit in a frame of unit diagonal about the box centre: every tolerance
    # and step below is then relative to the mesh, so the fit does not depend
    # on its units (tested on cubes from 1e-9 to 1e9)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    origin = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    scale = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    if not scale > 0 or not np.isfinite(scale):
        raise InputError("the mesh encloses no volume (all vertices coincide)", path)
    unit = trimesh.Trimesh((vertices - origin) / scale, np.asarray(mesh.faces), process=False)
    solid = discretize(unit, n, seed=seed, samples=samples, path=path)
    if n > len(solid.points):
        raise InputError(
            f"asked for {n} spheres but the solid has only {len(solid.points)} sample points; "
            "use fewer spheres", path)
    if max_iterations is None:
        max_iterations = ROUNDS
    bar.total = max_iterations  # known once the solid is sampled; shown at the next update

    def progress(rounds: float, energy: float) -> None:
        bar.set_postfix(E=f"{energy:.3f}", refresh=False)
        bar.update(min(int(rounds), bar.total) - bar.n)

    rng = np.random.default_rng(seed)
    info: dict = {"points": len(solid.points), "surface_points": len(solid.surface),
                  "flux_samples": len(solid.flux.points)}
    if method == "variational":
        centers, radii, _, extra = _variational(
            solid, n, rng, max_iterations=max_iterations,
            max_teleport_failures=max_teleport_failures, progress=progress)
        info.update(extra)
        centers, radii, info["revived"] = _revive(solid, centers, radii)
        shrink_rounds, passes = _finish_effort(max_iterations)
        centers, radii, info["cover_passes_kept"] = _settle_cover(
            solid, centers, radii, passes=passes, shrink_rounds=shrink_rounds)
        info["evaluations"] = solid.evaluations
        info["sample_terms"] = solid.sample_terms
    else:
        centers, radii, _ = (_octree(solid, n) if method == "octree"
                             else _kmeans(solid, n, rng))
        radii = _cover(solid, centers, radii)
    info["distinct_spheres"] = distinct_spheres(centers, radii)
    if method == "variational" and info["distinct_spheres"] < n:
        # _revive replaces every vanishing or duplicate sphere; reaching this
        # is a bug, not a property of the input
        raise RuntimeError(f"the fit returned {n - info['distinct_spheres']} vanishing or "
                           "duplicate spheres")
    # coverage on fresh, evenly spread surface points the fit never saw
    fresh = np.asarray(trimesh.sample.sample_surface_even(unit, COVERAGE_SAMPLES,
                                                          seed=seed + 1)[0])
    covered = _covered_fraction(centers, radii, fresh)
    outside = solid.evaluator.outside_volume(centers, radii)
    info["seconds"] = time.perf_counter() - start
    info["volume"] = solid.volume * scale**3
    return SphereSet(centers * scale + origin, radii * scale,
                     outside_volume_ratio=float(outside.sum() / solid.volume),
                     coverage=covered, method=method, info=info)


def distinct_spheres(centers: np.ndarray, radii: np.ndarray) -> int:
    """Spheres that neither vanish nor repeat another (centre and radius within
    DEAD_RADIUS of the set's extent).

    Parameters
    ----------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)

    Returns
    -------
    int
    """
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    if len(radii) == 0:
        return 0
    extent = float(np.max(np.linalg.norm(centers - centers.mean(axis=0), axis=1) + radii))
    tol = DEAD_RADIUS * max(extent, np.finfo(float).tiny)
    live = radii > tol
    keys = np.round(np.column_stack([centers[live], radii[live]]) / tol)
    return len(np.unique(keys, axis=0))


# --------------------------------------------------------------------------- shared


def _covered_fraction(centers, radii, points) -> float:
    return float(SphereSet(centers, radii).contains(points).mean())


def _cover(solid: Solid, centers: np.ndarray, radii: np.ndarray, *, pieces: list | None = None,
           ) -> np.ndarray:
    """Grow radii (least volume growth first) until every cover point and every
    point of the mesh's surface lies in some sphere.

    A ball is convex, so a triangle (or piece of one) whose three corners are
    in one sphere is inside it: the whole surface is covered, not only its
    samples (covering samples alone left 0.19 % of the dragon's surface
    outside).  Growing a sphere to hold a whole large triangle would cost
    much outside volume (CesiumMan: E 1.50 -> 2.51), so triangles split
    between spheres are subdivided first and only small pieces make a
    sphere grow.
    """
    radii = np.asarray(radii, dtype=np.float64).copy()
    n = len(centers)
    centers_t = np.ascontiguousarray(np.asarray(centers, dtype=np.float64).T)  # (3, N)

    def grow_for(pieces_: np.ndarray) -> None:
        """Grow, for each piece ``(T, K, 3)``, the sphere whose volume grows least.

        E sums sphere volumes, so the cost of holding a piece is the volume a
        sphere gains (need³ - r³), not the radius it gains: ranking by radius
        grew large spheres as readily as small ones (measured, E after the
        cover: the tests' character at N = 32 0.207 -> 0.187, spot N = 64
        0.249 -> 0.239, teapot N = 128 0.197 -> 0.168, CesiumMan N = 32
        1.154 -> 1.155)."""
        corners = pieces_.shape[1]
        # the radii grow after each batch of ``per`` pieces (the batches are
        # part of the rule: later pieces see the earlier growth); within a
        # batch the (pieces, N) distances are built ``sub`` pieces at a time,
        # axis by axis, in cache-sized blocks instead of one (T, K, N, 3)
        # temporary (teapot N = 128: 13 s -> 1.7 s; same sums, same result)
        per = max(1, 2_000_000 // (corners * n))
        sub = max(1, GROW_BLOCK // n)
        for a in range(0, len(pieces_), per):
            batch = pieces_[a:a + per]
            r3 = radii**3
            j = np.empty(len(batch), dtype=np.int64)
            need_j = np.empty(len(batch))
            for b in range(0, len(batch), sub):
                t = batch[b:b + sub]
                # the squared radius each sphere needs to hold each piece, (T, N)
                need2 = _squared_distances(t[:, 0], centers_t)
                for k in range(1, corners):
                    np.maximum(need2, _squared_distances(t[:, k], centers_t), out=need2)
                need = np.sqrt(need2, out=need2)
                cost = need**3
                cost -= r3
                jb = np.argmin(cost, axis=1)
                j[b:b + sub] = jb
                need_j[b:b + sub] = need[np.arange(len(t)), jb]
            np.maximum.at(radii, j, need_j)

    def held(pieces_: np.ndarray, tree: cKDTree) -> np.ndarray:
        """Which pieces ``(T, K, 3)`` lie inside one sphere; ``tree`` of a point
        of each piece (inside a sphere if the piece is): k-d tree candidates
        instead of pieces x spheres."""
        lists = tree.query_ball_point(centers, radii)
        ti = np.concatenate([np.asarray(ix, dtype=np.int64) for ix in lists])
        sj = np.repeat(np.arange(n), [len(ix) for ix in lists])
        d2 = np.max(np.sum((pieces_[ti] - centers[sj, None, :]) ** 2, axis=-1), axis=1)
        out = np.zeros(len(pieces_), dtype=bool)
        out[ti[d2 <= radii[sj] ** 2]] = True
        return out

    lost = ~held(solid.cover[:, None, :], solid.cover_tree)
    grow_for(solid.cover[lost][:, None, :])
    # the surface: a triangle inside one sphere is covered (a ball is convex);
    # the others are split in four until inside one sphere or smaller than
    # COVER_PIECE, and those pieces grow the sphere whose volume grows least
    tri = solid.mesh.vertices[solid.mesh.faces]  # (F, 3, 3)
    for _ in range(COVER_LEVELS + 1):
        centroid = tri.mean(axis=1)
        small = np.max(np.linalg.norm(tri - centroid[:, None], axis=-1),
                       axis=1) <= COVER_PIECE * solid.diag
        out = ~held(tri, cKDTree(centroid))
        if COVER_PAIRS and np.any(out):  # a piece can also lie in the union of two spheres
            out[out] = ~_pair_held(tri[out], centers, radii)
        grow = tri[out & small]
        if len(grow):
            grow_for(grow)
            if pieces is not None:
                pieces.append(grow.reshape(-1, 3))
        tri = tri[out & ~small]
        if len(tri) == 0:
            break
        mid = 0.5 * (tri[:, [0, 1, 2]] + tri[:, [1, 2, 0]])  # edge midpoints 01, 12, 20
        tri = np.concatenate([np.stack([tri[:, 0], mid[:, 0], mid[:, 2]], axis=1),
                              np.stack([mid[:, 0], tri[:, 1], mid[:, 1]], axis=1),
                              np.stack([mid[:, 2], mid[:, 1], tri[:, 2]], axis=1),
                              mid])
    if len(tri):  # pieces left after COVER_LEVELS splits: grow for them
        grow_for(tri)
        if pieces is not None:
            pieces.append(tri.reshape(-1, 3))
    return radii * (1.0 + 1e-12) + COVER_SLACK * solid.diag


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


def _pair_held(tri: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Which triangles ``tri (T, 3, 3)`` lie inside the union of two spheres.

    Two balls' union splits along their radical plane (equal power
    |x - c|² - r²): on sphere i's side a point of the union is in ball i.  So a
    triangle is in B_i ∪ B_j exactly when each corner is in one of them and
    every point where an edge crosses the radical plane is in B_i (the parts
    of the triangle on each side are convex polygons with those vertices).
    The pairs tried are those of the corners' deepest spheres (least power / r²).
    """
    n = len(centers)
    held = np.zeros(len(tri), dtype=bool)
    if n < 2 or len(tri) == 0:
        return held
    c2 = np.sum(centers**2, axis=1) - radii**2
    inv_r2 = 1.0 / np.maximum(radii, 1e-300) ** 2
    per = max(1, 1_000_000 // (3 * n))
    for a in range(0, len(tri), per):
        t = tri[a:a + per]  # (t, 3, 3)
        m = len(t)
        pw = np.sum(t * t, axis=-1)[:, :, None] - 2.0 * t @ centers.T + c2  # (t, 3, N)
        deepest = np.argmin(pw * inv_r2, axis=2)  # (t, 3)
        rows = np.arange(m)[:, None]
        inside = pw[rows, np.arange(3)[None, :], deepest] <= 0.0
        ok_rows = np.flatnonzero(np.all(inside, axis=1))
        if len(ok_rows) == 0:
            continue
        t, pw, deepest = t[ok_rows], pw[ok_rows], deepest[ok_rows]
        rows = np.arange(len(t))[:, None]
        ok_any = np.zeros(len(t), dtype=bool)
        for u, v in ((0, 1), (1, 2), (2, 0)):
            i, j = deepest[:, u], deepest[:, v]
            pi = pw[rows, np.arange(3)[None, :], i[:, None]]  # (t, 3)
            pj = pw[rows, np.arange(3)[None, :], j[:, None]]
            ok = (i != j) & np.all(np.minimum(pi, pj) <= 0.0, axis=1)
            g = pi - pj
            for e0, e1 in ((0, 1), (1, 2), (2, 0)):
                ga, gb = g[:, e0], g[:, e1]
                cross = ga * gb < 0.0
                s = np.where(cross, ga / np.where(cross, ga - gb, 1.0), 0.0)
                x = t[:, e0] + s[:, None] * (t[:, e1] - t[:, e0])
                ok &= ~cross | (np.sum((x - centers[i]) ** 2, axis=1) <= radii[i] ** 2)
            ok_any |= ok
        held[a + ok_rows] = ok_any
    return held


def _settle_cover(solid: Solid, centers: np.ndarray, radii: np.ndarray, *,
                  passes: int = COVER_PASSES, shrink_rounds: int = SHRINK_ROUNDS):
    """Make the spheres hold the whole surface; let the spheres that grew re-centre.

    The fit bounds sample points; the surface between them that no sphere
    holds (at seams between spheres, gaps of about the sample spacing) makes
    :func:`_cover` grow spheres, and growing alone is costly (CesiumMan at
    N = 32: E 0.95 -> 1.28).  The corners of the pieces that made spheres
    grow join the cover points and the shrink-and-re-centre steps run again,
    so that the spheres move to hold them instead of only growing; then
    :func:`_cover` closes what is left.  ``passes`` times at most, each
    with ``shrink_rounds`` shrink-and-re-centre rounds (see
    :func:`_finish_effort`).

    Every pass ends in a surface-bounding set, and so does the growth alone
    before the first; the set of least outside volume (inner-loop estimate)
    is returned.  Which one wins is chaotic: re-centring lowers E on most fits
    but raised it on some (spot at N = 128, seed 1: 0.256 grown, 0.274-0.328
    after re-centring, depending on bits of the search).

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
        Holding every cover point and the whole surface.
    passes : int
        Re-centring passes behind the returned set (0: growth alone).
    """
    pieces: list = []
    grown = _cover(solid, centers, radii, pieces=pieces)
    best = (solid.outside_estimate(centers, grown), centers, grown, 0)
    for k in range(passes):
        if not pieces:
            break
        extra = _unique_rows(np.concatenate(pieces))
        solid.cover = np.vstack([solid.cover, extra])
        solid.cover_tree = cKDTree(solid.cover)
        centers, radii = _shrink(solid, centers, grown, rounds=shrink_rounds)
        pieces = []
        grown = _cover(solid, centers, radii, pieces=pieces)
        e = solid.outside_estimate(centers, grown)
        if e < best[0]:
            best = (e, centers, grown, k + 1)
    return best[1], best[2], best[3]


def _finish_effort(max_iterations: int) -> tuple[int, int]:
    """Shrink rounds and surface-cover passes of the finish of a fit of
    ``max_iterations`` rounds: SHRINK_ROUNDS and COVER_PASSES, or for a quick
    fit (fewer rounds than SHRINK_ROUNDS) as many shrink rounds as search
    rounds, at least QUICK_SHRINK_ROUNDS, and one cover pass, so that a short
    budget buys a short fit (the finish would otherwise dominate it)."""
    if max_iterations >= SHRINK_ROUNDS:
        return SHRINK_ROUNDS, COVER_PASSES
    return max(QUICK_SHRINK_ROUNDS, int(max_iterations)), min(1, COVER_PASSES)


def _unique_rows(points: np.ndarray) -> np.ndarray:
    """``np.unique(points, axis=0)`` for float rows ``(P, 3)`` without NaN: the
    distinct rows in lexicographic order, by one lexsort (several times faster
    than sorting rows as structured records)."""
    ordered = points[np.lexsort(points.T[::-1])]
    first = np.ones(len(ordered), dtype=bool)
    first[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    return ordered[first]


def _revive(solid: Solid, centers: np.ndarray, radii: np.ndarray):
    """Replace vanishing (radius <= DEAD_RADIUS) and duplicate spheres by splits.

    A sphere the search leaves at zero radius (or on top of another) costs no
    outside volume but wastes one of the N spheres.  Each such slot takes
    one half of the sphere whose own points (those no other sphere covers)
    split with the largest gain; the union still covers every point.

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    revived : int
        Spheres replaced.
    """
    n = len(centers)
    tol = DEAD_RADIUS * solid.diag
    keys = np.round(np.column_stack([centers, radii]) / tol)
    _, first = np.unique(keys, axis=0, return_index=True)
    keep = np.zeros(n, dtype=bool)
    keep[first] = True
    keep &= radii > tol
    dead = int(n - keep.sum())
    if dead == 0:
        return centers, radii, 0
    # no shrink afterwards: shrinking re-centres a sphere with few points of
    # its own onto them, which is how spheres vanish in the first place
    state = _split_clusters(solid, centers[keep], radii[keep], dead)
    return state.centers, state.radii, dead


# --------------------------------------------------------------------------- variational


def _profile_lookup(table: np.ndarray, step: float, radii: np.ndarray) -> np.ndarray:
    """Interpolate ``table (N, R)`` at ``radii (C, N)`` (column j uses row j)."""
    nbins = table.shape[1]
    x = np.clip(radii / step, 0.0, nbins - 1.000001)
    i = np.floor(x).astype(np.int64)
    t = x - i
    i += np.arange(table.shape[0]) * nbins  # flat index of (row j, bin i)
    flat = table.reshape(-1)
    return flat[i] * (1 - t) + flat[i + 1] * t


def _flood_fill(solid: Solid, centers: np.ndarray, table: np.ndarray, step: float):
    """Cluster the points by least outside-volume growth, in fronts from the centres.

    Returns
    -------
    labels : ndarray, shape (P,), int
    radii : ndarray, shape (N,)
    """
    pts = solid.points
    n = len(centers)
    labels = np.full(len(pts), -1, dtype=np.int64)
    radii = np.zeros(n)
    # seed every cluster at a distinct point nearest to its centre
    k = min(len(pts), n + 1)
    _, near = solid.points_tree.query(centers, k=k)
    near = np.asarray(near).reshape(n, k)
    for j in range(n):
        for p in near[j]:
            if labels[p] < 0:
                labels[p] = j
                radii[j] = np.linalg.norm(pts[p] - centers[j])
                break
    front = np.flatnonzero(labels >= 0)
    # tie-break equal growth (e.g. inside T or inside the sphere) by distance
    tie = 1e-9 * solid.volume / solid.diag
    centers_t = np.ascontiguousarray(centers.T)  # (3, N)
    unlabelled = labels < 0
    while True:
        # the front's unlabelled neighbours, sorted (a mark, not np.unique)
        mark = np.zeros(len(pts), dtype=bool)
        mark[solid.neighbors[front].ravel()] = True
        mark &= unlabelled
        cand = np.flatnonzero(mark)
        if len(cand) == 0:
            cand = np.flatnonzero(unlabelled)
            if len(cand) == 0:
                break
        d = np.sqrt(_squared_distances(pts[cand], centers_t))  # (C, N)
        grown = np.maximum(radii[None, :], d)
        cost = _profile_lookup(table, step, grown) - _profile_lookup(table, step, radii[None, :])
        j = np.argmin(cost + tie * d, axis=1)
        labels[cand] = j
        unlabelled[cand] = False
        np.maximum.at(radii, j, d[np.arange(len(cand)), j])
        front = cand
    return labels, radii


#: Compass directions of the batched centre search (the six axis directions).
_COMPASS = np.vstack([np.eye(3), -np.eye(3)])

#: Compass-search iterations at most (each evaluates six candidates per sphere);
#: the step starts at half the box and halves on every failure, so 6 failures
#: reach POWELL_XTOL and the rest allow moves.
COMPASS_ITERATIONS = 18

#: A compass pass keeps in its exact sum the samples within the current radius
#: plus NEAR_REACH steps of the centre (a move of one step changes the radius
#: and the distance by at most one step each; the rest allow a few more moves
#: before the far field's first-order expansion is re-made); the rest join the
#: far field once fewer than KEEP_FRACTION of the samples remain.
NEAR_REACH = 4.0
KEEP_FRACTION = 0.8


def _recenter(solid: Solid, hulls: list[np.ndarray], p0: np.ndarray, delta: np.ndarray):
    """Move every centre within its box ``p0 ± delta`` to minimise V(S_i - T), the
    radius bounding ``hulls[i]``; all spheres in one batched compass search.

    V(S - T) comes from :class:`FluxSamples`: samples within reach of any
    sphere the search may try are summed exactly; the rest (always outside the
    sphere) enter through a first-order expansion of Σ s_k/ρ_k³ about ``p0``.
    Each round evaluates six axis moves of every sphere as one vectorised pass
    over the concatenated near samples (no Python loop per sphere).

    Parameters
    ----------
    solid : Solid
    hulls : list of ndarray, shape (H_i, 3)
        Points each sphere must contain (convex-hull vertices suffice).
    p0 : ndarray, shape (M, 3)
    delta : ndarray, shape (M,)

    Returns
    -------
    centers : ndarray, shape (M, 3)
    outside : ndarray, shape (M,)
        V(S_i - T) at the returned centres (inner-loop estimate).
    outside0 : ndarray, shape (M,)
        The same at ``p0``.
    """
    # the search is deterministic: a sphere re-centred before from the same
    # start for the same points (after a rejected teleport, or once its
    # cluster has settled) reuses that result (a third of them on CesiumMan)
    keys = [hashlib.blake2b(b"".join([c.tobytes(), np.float64(d).tobytes(), h.tobytes()]),
                            digest_size=16).digest()
            for c, d, h in zip(p0, delta, hulls, strict=True)]
    todo = [i for i, k in enumerate(keys) if k not in solid.recentred]
    if len(todo) < len(keys):
        if todo:
            _recenter(solid, [hulls[i] for i in todo], p0[todo], delta[todo])
        got = np.array([solid.recentred[k] for k in keys])  # (M, 5)
        return got[:, :3].copy(), got[:, 3].copy(), got[:, 4].copy()
    flux = solid.flux
    m = len(p0)
    hull = np.concatenate(hulls)
    hull_starts = np.concatenate([[0], np.cumsum([len(h) for h in hulls])])
    hull_owner = np.repeat(np.arange(m), np.diff(hull_starts))
    r0 = np.sqrt(np.maximum.reduceat(np.sum((hull - p0[hull_owner]) ** 2, axis=1),
                                     hull_starts[:-1]))
    reach = r0 + 2.0 * np.sqrt(3.0) * delta
    lists = flux.tree.query_ball_point(p0, reach)
    near = np.concatenate([np.asarray(ix, dtype=np.int64) for ix in lists])
    near_starts = np.concatenate([[0], np.cumsum([len(ix) for ix in lists])])
    near_owner = np.repeat(np.arange(m), np.diff(near_starts))
    # far field about p0: all samples minus the near ones, spheres in chunks;
    # Σ_far s_k/ρ_k³ ≈ far_c + far_g · e for a centre p0 + e
    far_c = np.empty(m)
    far_g = np.empty((m, 3))
    per = max(1, 2_000_000 // max(len(flux.points), 1))
    for a in range(0, m, per):
        b = min(a + per, m)
        rho2, sk = flux.relative(p0[a:b])  # (m, K)
        inv3 = 1.0 / (rho2 * np.sqrt(rho2))
        sel = (near_owner >= a) & (near_owner < b)
        inv3[near_owner[sel] - a, near[sel]] = 0.0
        far_c[a:b] = np.sum(sk * inv3, axis=1)
        # d/de of s/ρ³ = -q/ρ³ + 3 s (x - c)/ρ⁵, with x - c = x - p0 summed by mat-muls
        w5 = sk * inv3 / rho2
        far_g[a:b] = (-inv3 @ flux.q + 3.0 * (w5 @ flux.points
                                               - np.sum(w5, axis=1)[:, None] * p0[a:b]))
    # near samples and hull points relative to p0: a compass move along axis
    # k by t changes |y|² by -2 t y_k + t² and y·q by -t q_k, so the six
    # candidates of every sphere cost a few elementwise passes
    xn = flux.points[near] - p0[near_owner]
    qn = flux.q[near]
    own = near_owner
    hr = hull - p0[hull_owner]
    hown = hull_owner

    def segment_matrix(owner: np.ndarray) -> scipy.sparse.csr_matrix:
        """``(M, L)`` matrix whose product with ``values (L, C)`` sums them per
        sphere, ``owner (L,)`` sorted; built once per set of near samples."""
        starts = np.searchsorted(owner, np.arange(m + 1))
        return scipy.sparse.csr_matrix((np.ones(len(owner)), np.arange(len(owner)), starts),
                                       shape=(m, len(owner)))

    # value at p0
    s0 = np.einsum("ij,ij->i", xn, qn)
    w = np.minimum(r0[own] ** 2 / np.maximum(np.einsum("ij,ij->i", xn, xn), 1e-300), 1.0)
    r3 = r0**3
    segments = segment_matrix(own)
    f0 = FOUR_PI / 3.0 * r3 - ((segments @ (s0 * w * np.sqrt(w))[:, None])[:, 0]
                               + r3 * far_c)
    solid.evaluations += m
    solid.sample_terms += len(own)
    best = f0.copy()
    # the passes below work on coordinate rows (3, L): contiguous elementwise
    # passes, the same arithmetic (about a third faster than (L, 3) columns)
    xn, qn = np.ascontiguousarray(xn.T), np.ascontiguousarray(qn.T)
    r2u = r0**2  # squared radius at the current centre

    # compass search in units of delta, inside the box [-1, 1]^3; each pass
    # evaluates the six moves of the spheres still searching, over the
    # samples within their reach (the others are dropped into the far field)
    u = np.zeros((m, 3))
    step = np.full(m, 0.5)
    for _ in range(COMPASS_ITERATIONS):
        active = step >= POWELL_XTOL
        if not np.any(active):
            break
        e = delta[:, None] * u
        h = delta * step
        y = np.empty((3, len(own)))
        for k in range(3):
            np.subtract(xn[k], e[:, k].take(own), out=y[k])
        a = dot_rows(y, y)
        # samples a move of this pass (or the next few) cannot bring inside
        # the sphere, and every sample of a sphere that has converged, leave
        # the exact sum: the first ones enter the far field through a
        # first-order expansion about the current centre
        reach = np.sqrt(r2u) + NEAR_REACH * h
        keep = active[own] & (a <= (reach * reach)[own])
        if keep.sum() < KEEP_FRACTION * len(keep):
            # (np.take of indices: about 3x faster than boolean indexing of rows)
            drop = np.flatnonzero(~keep & active[own])
            yd, qd, od = y.take(drop, axis=1), qn.take(drop, axis=1), own[drop]
            inv2 = 1.0 / np.maximum(a[drop], 1e-300)
            inv3 = inv2 * np.sqrt(inv2)
            sd = dot_rows(yd, qd)
            c3 = 3.0 * sd * inv3 * inv2
            gsum = np.stack([np.bincount(od, weights=-qd[k] * inv3 + c3 * yd[k], minlength=m)
                             for k in range(3)], axis=1)
            far_c += np.bincount(od, weights=sd * inv3, minlength=m) - np.sum(gsum * e, axis=1)
            far_g += gsum
            keep = np.flatnonzero(keep)
            xn, qn, own = xn.take(keep, axis=1), qn.take(keep, axis=1), own[keep]
            y, a = y.take(keep, axis=1), a[keep]
            segments = segment_matrix(own)
            hkeep = np.flatnonzero(active[hown])
            hr, hown = hr.take(hkeep, axis=0), hown[hkeep]
        # rows: +x, +y, +z, -x, -y, -z
        t = h[own]
        t2 = 2.0 * t
        base = a + t * t
        rho2 = np.empty((6, len(own)))
        sq = dot_rows(y, qn)
        sn = np.empty((6, len(own)))
        for k in range(3):
            ty = t2 * y[k]
            np.subtract(base, ty, out=rho2[k])
            np.add(base, ty, out=rho2[3 + k])
            tq = t * qn[k]
            np.subtract(sq, tq, out=sn[k])
            np.add(sq, tq, out=sn[3 + k])
        np.maximum(rho2, 1e-300, out=rho2)
        yh = hr - e[hown]
        th = h[hown]
        tyh = (2.0 * th)[:, None] * yh
        baseh = (np.einsum("ij,ij->i", yh, yh) + th * th)[:, None]
        starts = np.searchsorted(hown, np.arange(m + 1))
        present = starts[:-1] < starts[1:]
        hull_r2 = np.empty((len(hown), 6))
        np.subtract(baseh, tyh, out=hull_r2[:, :3])
        np.add(baseh, tyh, out=hull_r2[:, 3:])
        r2 = np.zeros((m, 6))
        r2[present] = np.maximum.reduceat(hull_r2, starts[:-1][present], axis=0)
        np.maximum(r2, 0.0, out=r2)
        # min(1, r³/ρ³) = min(1, r²/ρ²)^1.5
        w = r2.T.take(own, axis=1)  # (6, L)
        w /= rho2
        np.minimum(w, 1.0, out=w)
        w *= np.sqrt(w)
        w *= sn
        r3 = r2 * np.sqrt(r2)
        moves = e[:, None, :] + h[:, None, None] * _COMPASS  # (M, 6, 3)
        inter = segments @ w.T + r3 * (far_c[:, None] + np.einsum("mj,mdj->md", far_g, moves))
        solid.evaluations += 6 * int(active.sum())
        solid.sample_terms += 6 * len(own)
        f = FOUR_PI / 3.0 * r3 - inter
        # moves that would leave the box are not taken
        cand = u[:, None, :] + step[:, None, None] * _COMPASS  # (M, 6, 3)
        f = np.where(np.all(np.abs(cand) <= 1.0, axis=-1), f, np.inf)
        j = np.argmin(f, axis=1)
        fj = f[np.arange(m), j]
        better = active & (fj < best - 1e-12 * np.abs(best))
        u[better] = cand[better, j[better]]
        best = np.where(better, fj, best)
        r2u = np.where(better, r2[np.arange(m), j], r2u)
        step[active & ~better] *= 0.5
    centers = p0 + delta[:, None] * u
    for k, c, b, f in zip(keys, centers, best, f0, strict=True):
        solid.recentred[k] = (*c, b, f)
    return centers, best, f0


def _update_centers(solid: Solid, centers: np.ndarray, labels: np.ndarray):
    """Move every centre to minimise V(S_i - T) subject to bounding its cluster.

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    outside : ndarray, shape (N,)
        Inner-loop estimate of V(S_i - T).
    """
    n = len(centers)
    new_c = centers.copy()
    radii = np.zeros(n)
    outside = np.zeros(n)
    order = np.argsort(labels, kind="stable")
    bounds_idx = np.searchsorted(labels[order], np.arange(n + 1))
    zero = 1e-9 * solid.volume
    hulls, which = [], []
    for i in range(n):
        members = order[bounds_idx[i]:bounds_idx[i + 1]]
        if len(members):
            hulls.append(solid.hull(solid.points, members))
            which.append(i)
    if not which:
        return new_c, radii, outside
    which = np.asarray(which)
    p0 = centers[which]
    r0 = np.array([np.sqrt(np.max(np.sum((h - c) ** 2, axis=1))) for h, c in zip(hulls, p0,
                                                                                  strict=True)])
    p, fp, f0 = _recenter(solid, hulls, p0, CENTER_STEP * r0 + 1e-3 * solid.diag)
    # a sphere already (almost) inside T stays where it is
    keep = ~((f0 > zero) & (fp < f0))
    p[keep], fp[keep] = p0[keep], f0[keep]
    new_c[which] = p
    radii[which] = [np.sqrt(np.max(np.sum((h - c) ** 2, axis=1))) for h, c in zip(hulls, p,
                                                                                   strict=True)]
    outside[which] = np.maximum(fp, 0.0)
    return new_c, radii, outside


@dataclass
class _State:
    centers: np.ndarray
    radii: np.ndarray
    labels: np.ndarray
    outside: np.ndarray
    energy: float


def _lloyd_step(solid: Solid, centers: np.ndarray) -> _State:
    """One round: flood-fill clustering, Powell centre update, shrink and re-centre.

    After the per-cluster update, each sphere shrinks to the points no other
    sphere covers (E sums spheres separately, so covered points need not hold a
    radius up) and Powell re-centres it for those points.
    """
    r_grid = np.linspace(0.0, solid.diag, PROFILE_BINS)
    table = solid.flux.outside_profiles(centers, r_grid)
    solid.evaluations += len(centers) * 2  # profiles, then the estimate below
    labels, _ = _flood_fill(solid, centers, table, r_grid[1])
    c, r, _ = _update_centers(solid, centers, labels)
    c, r = _shrink(solid, c, r, rounds=1)
    out = solid.flux.outside_volumes(c, r)
    return _State(c, r, labels, out, float(out.sum() / solid.volume))


def _lens_volumes(centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Pairwise intersection volumes of spheres, shape (N, N), zero diagonal."""
    d = np.linalg.norm(centers[:, None] - centers[None, :], axis=-1)
    r1, r2 = radii[:, None], radii[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        lens = (np.pi * (r1 + r2 - d) ** 2
                * (d**2 + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d))
    contained = d <= np.abs(r1 - r2)
    vol = np.where(contained, FOUR_PI / 3 * np.minimum(r1, r2) ** 3,
                   np.where(d < r1 + r2, lens, 0.0))
    np.fill_diagonal(vol, 0.0)
    return np.nan_to_num(vol)


def _teleport(solid: Solid, state: _State, attempt: int) -> np.ndarray | None:
    """Centres after splitting the worst cluster and deleting the most overlapped one."""
    n = len(state.centers)
    if n < 2:
        return None
    worst_order = np.argsort(-state.outside, kind="stable")
    worst = int(worst_order[min(attempt // TELEPORT_CANDIDATES, n - 1)])
    kind = attempt % TELEPORT_CANDIDATES
    if kind == 0:
        # the sphere most overlapped by the others
        # a sphere of (near) zero radius is redundant: delete it first
        vol = FOUR_PI / 3 * np.maximum(state.radii, DEAD_RADIUS * solid.diag) ** 3
        score = -_lens_volumes(state.centers, state.radii).sum(axis=1) / vol
        score[state.radii <= DEAD_RADIUS * solid.diag] = -np.inf
        rank = 0
    else:
        # the spheres covering the fewest points no other sphere covers
        pts = solid.points
        d2 = (np.sum(pts * pts, axis=1)[:, None] - 2.0 * pts @ state.centers.T
              + np.sum(state.centers**2, axis=1))
        inside = d2 <= (state.radii**2)[None, :] * (1 + 1e-9)
        score = (inside & (inside.sum(axis=1) == 1)[:, None]).sum(axis=0).astype(np.float64)
        rank = kind - 1
    score[worst] = np.inf
    victim = int(np.argsort(score, kind="stable")[rank])
    members = solid.points[state.labels == worst]
    if len(members) < 2:
        return None
    a = members[np.argmax(np.linalg.norm(members - members.mean(axis=0), axis=1))]
    b = members[np.argmax(np.linalg.norm(members - a, axis=1))]
    centers = state.centers.copy()
    centers[worst] = a + 0.25 * (b - a)
    centers[victim] = b + 0.25 * (a - b)
    return centers


def _initial_centers(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Random centres spread by D² sampling (k-means++ seeding)."""
    chosen = [int(rng.integers(len(points)))]
    d2 = np.sum((points - points[chosen[0]]) ** 2, axis=1)
    for _ in range(1, n):
        total = d2.sum()
        idx = int(rng.integers(len(points))) if total <= 0 else int(
            rng.choice(len(points), p=d2 / total))
        chosen.append(idx)
        d2 = np.minimum(d2, np.sum((points - points[idx]) ** 2, axis=1))
    return points[chosen].copy()


def _split_start(solid: Solid, n: int, rng: np.random.Generator) -> np.ndarray:
    """Centres ``(n, 3)`` of k-means clusters split in two SPLIT_LEVELS times.

    k-means (:func:`_kmeans`) cuts the points into ceil(n / 2**SPLIT_LEVELS)
    clusters, each bounded by its minimal sphere; the spheres grow to hold
    the cover points (:func:`_cover`) and :func:`_split_clusters` splits the
    ones whose split gains most, doubling the count at each level up to
    ``n``.  Every part of the shape gets spheres in proportion to what it
    costs, as a coarse fit's split does, where random centres crowd some parts
    and starve others (thin limbs); the Lloyd steps then start from these
    centres.
    """
    sizes = [n]
    for _ in range(SPLIT_LEVELS):
        sizes.append((sizes[-1] + 1) // 2)
    with warnings.catch_warnings():
        # an empty k-means cluster is dropped; the splits make up the count
        warnings.simplefilter("ignore", UserWarning)
        centers, radii, _ = _kmeans(solid, sizes[-1], rng)
    for size in reversed(sizes[:-1]):
        state = _split_clusters(solid, centers, _cover(solid, centers, radii),
                                size - len(centers))
        centers, radii = state.centers, state.radii
    return centers


def _box_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The sphere about the bounding box's centre that holds ``points (P, 3)``."""
    c = 0.5 * (points.min(axis=0) + points.max(axis=0))
    return c, float(np.sqrt(np.max(np.sum((points - c) ** 2, axis=1))))


def _split_clusters(solid: Solid, centers: np.ndarray, radii: np.ndarray, splits: int,
                    ) -> _State:
    """The state after splitting the ``splits`` spheres whose split gains most.

    A sphere's own points (those no other sphere covers) are cut in two by the
    plane through their centroid normal to each principal axis; the halves'
    minimal bounding spheres replace it when their outside volume
    (inner-loop estimate) undercuts its own by the most.  Splits are applied
    in order of gain, each re-deriving the sphere's own points after the
    earlier ones, so the union still covers every point; a split is only
    made when it lowers the estimate.  If fewer than ``splits`` splits lower
    it, the best remaining ones are made anyway (largest gain first): every
    sphere of the result bounds points of its own, none has zero radius.

    Returns
    -------
    _State
        ``N + splits`` spheres, their flood-fill clusters and outside volumes.
    """
    pts = solid.cover
    slack = SHRINK_SLACK * solid.diag

    def covers(c: np.ndarray, r: float) -> np.ndarray:
        limit = r * (1 + 1e-9) + slack
        # k-d tree candidates within a margin, then the exact test on them only
        near = np.asarray(solid.cover_tree.query_ball_point(c, limit * (1 + 1e-9) + slack),
                          dtype=np.int64)
        inside = np.zeros(len(pts), dtype=bool)
        inside[near[np.linalg.norm(pts[near] - c, axis=1) <= limit]] = True
        return inside

    def outside(spheres: list) -> list[float]:
        """V(S - T) of each sphere ``(c, r)`` (inner-loop estimate), in one pass."""
        solid.evaluations += len(spheres)
        inter = solid.flux.intersection_volume_each([c for c, _ in spheres],
                                                    [r for _, r in spheres])
        return [max(FOUR_PI / 3 * r**3 - float(v), 0.0)
                for (_, r), v in zip(spheres, inter, strict=True)]

    # the cut of a set of own points does not depend on the parent: the same
    # points (a sphere whose own points no earlier split changed) reuse it
    cuts: dict = {}

    def best_split(own: np.ndarray, parent: float):
        """(gain, children, their outside volumes) of the best plane cut."""
        key = hashlib.blake2b(np.ascontiguousarray(own).tobytes(), digest_size=16).digest()
        if key not in cuts:
            cuts[key] = plane_cut(own)
        halves, out = cuts[key]
        return (-np.inf, None, None) if halves is None else (parent - sum(out), halves, out)

    def plane_cut(own: np.ndarray):
        """(children, their outside volumes) of the best plane cut, or (None, None)."""
        best = (None, None)
        if len(own) < 2:
            return best
        mean = own.mean(axis=0)
        _, _, axes = np.linalg.svd(own - mean, full_matrices=False)
        # the three cuts are ranked with the halves' box-centred spheres (a
        # minimal sphere costs an SLSQP solve); only the best cut's halves get
        # their minimal spheres
        sides, boxes = [], []
        for axis in axes:
            side = (own - mean) @ axis > 0
            if side.all() or not side.any():
                continue
            halves = [_box_sphere(own[side]), _box_sphere(own[~side])]
            if min(halves[0][1], halves[1][1]) <= MIN_CHILD_RADIUS * solid.diag:
                continue  # a (near) point-sized child would be a vanishing sphere
            sides.append(side)
            boxes += halves
        if not sides:
            return best
        out = outside(boxes)
        ranked = [(sum(out[2 * k:2 * k + 2]), side) for k, side in enumerate(sides)]
        side = min(ranked, key=lambda x: x[0])[1]
        halves = [minimal_bounding_sphere(own[side]), minimal_bounding_sphere(own[~side])]
        if min(halves[0][1], halves[1][1]) <= MIN_CHILD_RADIUS * solid.diag:
            return best
        return halves, outside(halves)

    inside = [covers(c, r) for c, r in zip(centers, radii, strict=True)]
    count = np.sum(inside, axis=0)
    parent_out = outside(list(zip(centers, radii, strict=True)))
    gains = np.array([best_split(pts[inside[i] & (count == 1)], parent_out[i])[0]
                      for i in range(len(centers))])
    new_c, new_r, new_o = list(centers), list(radii), list(parent_out)

    def apply(i: int, halves, out) -> None:
        nonlocal count
        (ca, ra), (cb, rb) = halves
        in_a, in_b = covers(ca, ra), covers(cb, rb)
        count = count + in_a.astype(np.int64) + in_b - inside[i]
        inside[i] = in_a
        inside.append(in_b)
        new_c[i], new_r[i], new_o[i] = ca, ra, out[0]
        new_c.append(cb)
        new_r.append(rb)
        new_o.append(out[1])

    # split in order of gain, re-deriving each sphere's own points after the
    # earlier splits: a point two spheres shared must stay inside a child
    for i in np.argsort(-gains, kind="stable")[:splits]:
        own = pts[inside[i] & (count == 1)]
        gain, halves, out = best_split(own, new_o[i])
        if gain > 0:
            apply(i, halves, out)
    # the rest: the best remaining splits even when they do not lower the
    # estimate (zero-radius placeholders, as before, could survive the search
    # as vanishing duplicates: the bunny's 64-sphere fit returned 25 of them)
    def owned() -> np.ndarray:
        return np.array([np.flatnonzero(inside[i] & (count == 1)).sum()
                         for i in range(len(inside))])

    pending: dict = {}
    signature = owned()
    while len(new_c) < len(centers) + splits:
        for i in range(len(new_c)):
            if i not in pending:
                pending[i] = best_split(pts[inside[i] & (count == 1)], new_o[i])
        i = max(pending, key=lambda k: pending[k][0])
        gain, halves, out = pending[i]
        if halves is None:
            raise RuntimeError("no cluster left to split: too many spheres for the points")
        apply(i, halves, out)
        # re-derive the splits of the spheres whose own points changed
        now = owned()
        for j in np.flatnonzero(now[:len(signature)] != signature):
            pending.pop(int(j), None)
        pending.pop(i, None)
        signature = now
    c = np.asarray(new_c, dtype=np.float64)
    r = np.asarray(new_r, dtype=np.float64)
    o = np.asarray(new_o, dtype=np.float64)
    r_grid = np.linspace(0.0, solid.diag, PROFILE_BINS)
    labels, _ = _flood_fill(solid, c, solid.flux.outside_profiles(c, r_grid), r_grid[1])
    solid.evaluations += len(c)
    return _State(c, r, labels, o, float(o.sum() / solid.volume))


def _variational(solid: Solid, n: int, rng: np.random.Generator, *, max_iterations: int,
                 max_teleport_failures: int, progress=None, split: bool = True):
    """The search of :func:`fit_spheres` at ``n`` spheres: its start, its rounds and
    the final shrink.

    From COARSE_TO_FINE_MIN spheres on the search starts from a fit of
    ceil(n/2) spheres split in two, which spends COARSE_SHARE of the work
    budget (max_iterations rounds at ``n``); below that the start is
    :func:`_first_centers` (split from SPLIT_START_MIN on, random below), or
    random without ``split`` (the coarse stages, which keep the starts their
    figures were measured with).

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    labels : ndarray, shape (P,)
        The clusters of the best state.
    info : dict
        Rounds, teleports and work (rounds x spheres) spent, over every stage.
    """
    shrink_rounds = _finish_effort(max_iterations)[0]
    if n >= COARSE_TO_FINE_MIN:
        # a round costs about (points x spheres), so the coarse stage's share
        # buys rounds at ``half`` spheres at a proportionally higher count
        half = (n + 1) // 2
        work = max_iterations * n
        # progress counts rounds at n: a coarse round is half a round
        c, r, _, coarse = _variational(
            solid, half, rng, max_iterations=max(1, int(COARSE_SHARE * work / half)),
            max_teleport_failures=max_teleport_failures, split=False,
            progress=None if progress is None else (lambda i, e: progress(i * half / n, e)))
        start = _split_clusters(solid, c, r, n - half)
        centers, radii, labels, info = _lloyd_search(
            solid, start, max_iterations=max(1, int((work - coarse["work"]) / n)),
            max_teleport_failures=max_teleport_failures, shrink_rounds=shrink_rounds,
            progress=None if progress is None else (
                lambda i, e: progress(coarse["work"] / n + i, e)))
        for key in ("iterations", "teleports_tried", "teleports_accepted", "work"):
            info[key] += coarse[key]
        return centers, radii, labels, info
    start = _first_centers(solid, n, rng) if split else _initial_centers(solid.points, n, rng)
    return _lloyd_search(solid, start, max_iterations=max_iterations,
                         max_teleport_failures=max_teleport_failures,
                         shrink_rounds=shrink_rounds, progress=progress)


def _first_centers(solid: Solid, n: int, rng: np.random.Generator) -> np.ndarray:
    """Start centres ``(n, 3)`` of a search below COARSE_TO_FINE_MIN: split
    k-means clusters from SPLIT_START_MIN on (:func:`_split_start`), random
    ones (:func:`_initial_centers`) below."""
    if n >= SPLIT_START_MIN:
        return _split_start(solid, n, rng)
    return _initial_centers(solid.points, n, rng)


def _lloyd_search(solid: Solid, start: np.ndarray | _State, *, max_iterations: int,
                  max_teleport_failures: int, shrink_rounds: int, progress=None):
    """Lloyd steps with teleportation from the centres ``start (N, 3)`` or a state,
    then the best state shrunk to a fixed point (``shrink_rounds`` rounds at most).

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    labels : ndarray, shape (P,)
    info : dict
        Rounds, teleports, work (rounds x spheres) and the estimated E.
    """
    n = len(start.centers) if isinstance(start, _State) else len(start)
    # Lloyd steps are deterministic: after a rejected teleport the search
    # resumes from the best state, whose successor is often already known
    memo: dict[bytes, _State] = {}

    def lloyd(centers: np.ndarray) -> tuple[_State, int]:
        key = centers.tobytes()
        if key in memo:
            return memo[key], 0
        memo[key] = _lloyd_step(solid, centers)
        return memo[key], 1

    def progress_step(state: _State) -> float:
        return STALL_SHARE * state.energy / n

    if isinstance(start, _State):
        best = start
    else:
        best, _ = lloyd(start)
    iterations, teleports, accepted, failures = 1, 0, 0, 0
    current = best
    while iterations < max_iterations:
        nxt, cost = lloyd(current.centers)
        iterations += cost
        if progress is not None:
            progress(iterations, nxt.energy)
        improved = nxt.energy < best.energy - progress_step(best)
        if nxt.energy < best.energy:
            best = nxt
        current = nxt
        if improved:
            continue
        # Lloyd has stalled: teleport
        if failures >= max_teleport_failures:
            break
        # several split candidates, one Lloyd step each; the best goes on
        trials = []
        # (attempt // TELEPORT_CANDIDATES picks the split cluster, the rest
        # the deleted sphere)
        for attempt in range(TELEPORT_CANDIDATES * failures,
                             TELEPORT_CANDIDATES * (failures + 1)):
            if iterations >= max_iterations:
                break
            trial_centers = _teleport(solid, best, attempt)
            if trial_centers is None:
                continue
            teleports += 1
            trial, cost = lloyd(trial_centers)
            iterations += cost
            trials.append(trial)
        if not trials:
            break
        trial = min(trials, key=lambda t: t.energy)
        for _ in range(2):
            if iterations >= max_iterations:
                break
            again, cost = lloyd(trial.centers)
            iterations += cost
            if again.energy >= trial.energy:
                break
            trial = again
        if trial.energy < best.energy - progress_step(best):
            best = current = trial
            accepted += 1
            failures = 0
        else:
            current = best
            failures += 1
    centers, radii = _shrink(solid, best.centers, best.radii, rounds=shrink_rounds)
    info = {"iterations": iterations, "teleports_tried": teleports,
            "teleports_accepted": accepted, "energy_estimate": best.energy,
            "work": iterations * n}
    return centers, radii, best.labels, info


def _shrink(solid: Solid, centers: np.ndarray, radii: np.ndarray, rounds: int,
            recenter: bool = True):
    """Shrink spheres to the points no other sphere covers, then re-centre them.

    E sums each sphere's outside volume, so a point already inside another
    sphere need not hold a radius up.  Largest spheres shrink first; each
    sphere keeps bounding the points only it covers, so the union still covers
    every point.  With ``recenter``, the compass search then moves each centre
    for its own points.  Each sphere visits only the cover points inside it (a
    k-d tree query), not all of them: the cost is the points times the
    spheres' overlap, not points x spheres.
    """
    pts = solid.cover
    slack = SHRINK_SLACK * solid.diag
    centers = centers.copy()
    radii = radii.copy()
    n = len(centers)
    order = np.argsort(-radii, kind="stable")

    # a sphere that neither moved nor shrank since its last query (most of them
    # once the rounds settle) reuses that query's points: (indices, distances)
    found: dict = {}

    def members(idx: np.ndarray):
        """Cover points inside spheres ``idx``: (points, owner sphere, distance),
        grouped by sphere in the order of ``idx``."""
        keys = [centers[i].tobytes() + radii[i].tobytes() for i in idx]
        todo = [k for k, key in enumerate(keys) if key not in found]
        if todo:
            ask = idx[todo]
            # (unsorted lists: nothing below depends on the order within a sphere)
            lists = solid.cover_tree.query_ball_point(centers[ask], radii[ask] + 2.0 * slack,
                                                      return_sorted=False)
            for k, i, ix in zip(todo, ask, lists, strict=True):
                ix = np.asarray(ix, dtype=np.int64)
                dist = np.linalg.norm(pts[ix] - centers[i], axis=1)
                keep = dist <= radii[i] + slack  # the same test as every later one
                found[keys[k]] = (ix[keep], dist[keep])
        parts = [found[key] for key in keys]
        owner = np.repeat(idx, [len(ix) for ix, _ in parts])
        if not parts:
            return np.zeros(0, dtype=np.int64), owner, np.zeros(0)
        return np.concatenate([ix for ix, _ in parts]), owner, np.concatenate([d for _, d in parts])

    everyone = np.arange(n)
    # a round can raise E (a re-centred sphere leaves points that another
    # must grow to take back: spot at N = 40 went 0.201 -> 0.406 in one
    # round), so from two rounds on the round of least estimated E is kept
    keep_best = rounds > 1
    kept = (np.inf, centers, radii)
    for _ in range(rounds):
        before = (centers.copy(), radii.copy())
        flat, owner, dist = members(everyone)
        starts = np.searchsorted(owner, np.arange(n + 1))
        count = np.bincount(flat, minlength=len(pts))
        alive = np.ones(len(flat), dtype=bool)
        for i in order:
            s, e = starts[i], starts[i + 1]
            ix, d, a = flat[s:e], dist[s:e], alive[s:e]
            own = a & (count[ix] == 1)
            if not np.any(own):
                continue
            radii[i] = float(d[own].max())
            lost = a & (d > radii[i] + slack)
            count[ix[lost]] -= 1
            a &= ~lost  # a view: updates alive
        if not recenter:
            return centers, radii
        # all spheres at once, each for the points only it covers (disjoint sets)
        mine = alive & (count[flat] == 1)
        per = np.bincount(owner[mine], minlength=n)
        movers = order[per[order] > 0]
        if len(movers):
            groups = np.split(flat[mine], np.cumsum(per)[:-1])
            hulls = [solid.hull(pts, groups[i]) for i in movers]
            p, fp, f0 = _recenter(solid, hulls, centers[movers],
                                  CENTER_STEP * radii[movers] + 1e-3 * solid.diag)
            moved_ok = fp < f0
            if np.any(moved_ok):
                changed = movers[moved_ok]
                for k in np.flatnonzero(moved_ok):
                    i = movers[k]
                    centers[i] = p[k]
                    radii[i] = float(np.sqrt(np.max(np.sum((hulls[k] - p[k]) ** 2, axis=1))))
                # a point two moved spheres shared may have been left by both:
                # the sphere that needs the least growth takes it back
                was = np.isin(owner, changed) & alive
                left = count.copy()
                np.subtract.at(left, flat[was], 1)
                new_flat, _, _ = members(changed)
                np.add.at(left, new_flat, 1)
                lost = np.unique(flat[was][left[flat[was]] == 0])
                if len(lost):
                    d = np.linalg.norm(pts[lost, None, :] - centers[None, :, :], axis=-1)
                    j = np.argmin(d - radii, axis=1)
                    np.maximum.at(radii, j, d[np.arange(len(lost)), j])
        if keep_best:
            estimate = solid.outside_estimate(centers, radii)
            if estimate < kept[0]:
                kept = (estimate, centers.copy(), radii.copy())
        # a fixed point: no sphere moved or shrank noticeably this round
        moved = np.max(np.linalg.norm(centers - before[0], axis=1) + before[1] - radii)
        if moved <= SHRINK_TOLERANCE * solid.diag:
            break
    return (kept[1], kept[2]) if keep_best else (centers, radii)


# --------------------------------------------------------------------------- baselines


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
