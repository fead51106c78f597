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
3. Centre update: per cluster, Powell's method moves the centre to minimise
   V(S - T) with the radius bounding the cluster's points.  Then each sphere
   shrinks to the points no other sphere covers (E sums the spheres' outside
   volumes, so a point inside another sphere need not hold a radius up) and
   Powell re-centres it for those points; the union still covers every point.
   V(S - T) in this inner loop comes from :class:`FluxSamples` (centroid rule
   of the flux on small triangles, radial profiles for the flood fill).
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
   work budget (rounds x spheres).

The shrink-and-re-centre step is iterated to a fixed point at the end.
Finally every radius grows just enough to contain its cluster, every surface
sample, mesh vertex and quadrature point (coverage 1), and E = Σ V(S_i - T)/V(T)
is computed with the accurate flux evaluator of :mod:`.outside_volume`.

Baselines for comparison at equal sphere counts: ``"octree"`` (circumscribed
spheres of occupied octree cells, Hubbard 1995, refined largest-first until
about N cells) and ``"kmeans"`` (k-means clusters of the same points, each
with its minimal bounding sphere).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from shtools.errors import InputError
from shtools.geometry.fit_methods import FIT_METHODS
from shtools.geometry.outside_volume import FOUR_PI, FluxSamples, OutsideVolume
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
MAX_VERTEX_POINTS = 20_000

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
MAX_FLUX_SAMPLES = 25_000

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

#: Distance (fraction of the diagonal) within which a point counts as on a
#: sphere during shrinking: absorbs the rounding of the mat-mul distances.
SHRINK_SLACK = 1e-9

#: Default iteration cap: rounds cost about (cover points) x N, so the cap is
#: this work budget divided by that (a 100k-triangle mesh at N = 64 gets ~75
#: rounds, inside two minutes), clipped to [MIN_ITERATIONS, MAX_ITERATIONS].
ITERATION_WORK = 3.6e8
MIN_ITERATIONS = 40
MAX_ITERATIONS = 150

#: Teleportation candidates (split cluster, deleted sphere) tried per stall;
#: the one with the lowest E after a Lloyd step is refined and kept if E drops.
TELEPORT_CANDIDATES = 3

#: A Lloyd step or teleport counts as progress when it lowers E by more than
#: this fraction of the average sphere's share E / N.  The threshold is per
#: sphere because a teleport moves one or two spheres: a fixed fraction of the
#: total E would reject every useful teleport once N is large (at N = 128 a
#: 0.5 % drop of E is 64 % of an average sphere's outside volume).
STALL_SHARE = 0.08

#: From this N on, the variational fit starts from a fit of ceil(N/2) spheres
#: whose clusters are split in two (recursively), instead of random centres:
#: Lloyd steps and one-sphere teleports relocate spheres one at a time, which
#: does not converge within the round budget once N is large (E at N = 128 was
#: no better than at N = 64).  Below 64 the random start with teleports is as
#: good or better (spot at N = 40: E 0.168 direct, 0.215 from a 20-sphere fit).
#: The coarse fit gets COARSE_SHARE of the work budget (rounds x spheres).
COARSE_TO_FINE_MIN = 64
COARSE_SHARE = 0.5

#: Radius (fraction of the diagonal) below which a sphere counts as redundant.
DEAD_RADIUS = 1e-9

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
    volume : float
    diag : float
    """

    mesh: trimesh.Trimesh
    evaluator: OutsideVolume
    flux: FluxSamples
    surface: np.ndarray
    points: np.ndarray
    neighbors: np.ndarray
    cover: np.ndarray
    volume: float
    diag: float


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
    cover = np.vstack([points, v])
    return Solid(mesh, evaluator, flux, surface, points, np.asarray(nb)[:, 1:], cover,
                 float(volume), diag)


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
        round count reported in ``info`` can exceed it.  Default
        ``ITERATION_WORK / (cover points * n)`` clipped to
        [MIN_ITERATIONS, MAX_ITERATIONS], a round costing about points x n.
    max_teleport_failures : int
        Consecutive rejected teleportations before stopping (variational).
    samples : int, optional
        Surface and interior sample counts (see :func:`discretize`).
    path : path-like, optional
        Mesh file, named in error messages.
    progress : callable, optional
        Called as ``progress(iteration, E_estimate)`` after each round.
    restarts : int
        Independent starts with seeds ``seed, seed + 1, ...``; the fit with the
        lowest E is returned (the search is non-convex: on spot at N = 40,
        seeds 0-5 gave E = 0.168, 0.185, 0.164, 0.185, 0.169, 0.197).
        ``info["restart_E"]`` lists every start's E.

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
                            path=path, progress=progress)
                for k in range(int(restarts))]
        best = min(fits, key=lambda f: f.outside_volume_ratio)  # first of equals
        best.info["restart_E"] = [f.outside_volume_ratio for f in fits]
        best.info["seconds"] = time.perf_counter() - start
        return best
    start = time.perf_counter()
    if thickness is not None:
        from shtools.geometry.mesh import thicken

        mesh = thicken(mesh, float(thickness))
    solid = discretize(mesh, n, seed=seed, samples=samples, path=path)
    if n > len(solid.points):
        raise InputError(
            f"asked for {n} spheres but the solid has only {len(solid.points)} sample points; "
            "use fewer spheres", path)
    if max_iterations is None:
        max_iterations = int(np.clip(ITERATION_WORK / (len(solid.cover) * n), MIN_ITERATIONS,
                                     MAX_ITERATIONS))
    rng = np.random.default_rng(seed)
    info: dict = {"points": len(solid.points), "surface_points": len(solid.surface),
                  "flux_samples": len(solid.flux.points)}
    if method == "variational":
        centers, radii, _, extra = _variational(
            solid, n, rng, max_iterations=max_iterations,
            max_teleport_failures=max_teleport_failures, progress=progress)
        info.update(extra)
    elif method == "octree":
        centers, radii, _ = _octree(solid, n)
    else:
        centers, radii, _ = _kmeans(solid, n, rng)
    radii = _cover(solid, centers, radii)
    covered = _covered_fraction(centers, radii, np.vstack([solid.surface, solid.mesh.vertices]))
    outside = solid.evaluator.outside_volume(centers, radii)
    info["seconds"] = time.perf_counter() - start
    info["volume"] = solid.volume
    return SphereSet(centers, radii, outside_volume_ratio=float(outside.sum() / solid.volume),
                     coverage=covered, method=method, info=info)


# --------------------------------------------------------------------------- shared


def _covered_fraction(centers, radii, points) -> float:
    return float(SphereSet(centers, radii).contains(points).mean())


def _cover(solid: Solid, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Grow radii so that every cover point lies in some sphere (least growth)."""
    radii = np.asarray(radii, dtype=np.float64).copy()
    pts = solid.cover
    inside = SphereSet(centers, radii).contains(pts)
    rest = pts[~inside]
    if len(rest):
        d = np.linalg.norm(rest[:, None, :] - centers[None, :, :], axis=-1)
        j = np.argmin(d - radii[None, :], axis=1)
        np.maximum.at(radii, j, d[np.arange(len(rest)), j])
    return radii * (1.0 + 1e-12) + COVER_SLACK * solid.diag


# --------------------------------------------------------------------------- variational


def _profile_lookup(table: np.ndarray, step: float, radii: np.ndarray) -> np.ndarray:
    """Interpolate ``table (N, R)`` at ``radii (C, N)`` (column j uses row j)."""
    nbins = table.shape[1]
    x = np.clip(radii / step, 0.0, nbins - 1.000001)
    i = np.floor(x).astype(np.int64)
    t = x - i
    cols = np.broadcast_to(np.arange(table.shape[0]), radii.shape)
    return table[cols, i] * (1 - t) + table[cols, i + 1] * t


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
    _, near = cKDTree(pts).query(centers, k=k)
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
    while True:
        cand = np.unique(solid.neighbors[front].ravel())
        cand = cand[labels[cand] < 0]
        if len(cand) == 0:
            cand = np.flatnonzero(labels < 0)
            if len(cand) == 0:
                break
        d = np.linalg.norm(pts[cand, None, :] - centers[None, :, :], axis=-1)  # (C, N)
        grown = np.maximum(radii[None, :], d)
        cost = _profile_lookup(table, step, grown) - _profile_lookup(table, step, radii[None, :])
        j = np.argmin(cost + tie * d, axis=1)
        labels[cand] = j
        np.maximum.at(radii, j, d[np.arange(len(cand)), j])
        front = cand
    return labels, radii


def _sphere_objective(solid: Solid, hull: np.ndarray, p0: np.ndarray, delta: float):
    """V(S - T) as a function of the centre, radius bounding ``hull``.

    Samples within reach of any sphere the optimiser may try are summed
    exactly; the rest (always outside the sphere) enter through a first-order
    expansion of Σ s_k/ρ_k³ about ``p0``.
    """
    flux = solid.flux
    r0 = float(np.sqrt(np.max(np.sum((hull - p0) ** 2, axis=1))))
    reach = r0 + 2.0 * np.sqrt(3.0) * delta
    near = np.asarray(flux.tree.query_ball_point(p0, reach), dtype=np.int64)
    mask = np.ones(len(flux.points), dtype=bool)
    mask[near] = False
    xf, qf = flux.points[mask], flux.q[mask]
    d = xf - p0
    rho2 = np.sum(d * d, axis=1)
    rho = np.sqrt(rho2)
    s = np.sum(d * qf, axis=1)
    g0 = float(np.sum(s / (rho2 * rho)))
    grad = -np.sum(qf / (rho2 * rho)[:, None], axis=0) + 3.0 * np.sum(
        (s / (rho2 * rho2 * rho))[:, None] * d, axis=0)
    xn, qn = flux.points[near], flux.q[near]
    # expand |x - p|² and (x - p)·q so that one evaluation is two mat-vecs
    xx = np.sum(xn * xn, axis=1)
    xq = np.sum(xn * qn, axis=1)
    hh = np.sum(hull * hull, axis=1)

    def outside(p: np.ndarray) -> float:
        pp = float(p @ p)
        r2 = float(np.max(hh - 2.0 * (hull @ p))) + pp
        r3 = max(r2, 0.0) ** 1.5
        rho2n = np.maximum(xx - 2.0 * (xn @ p) + pp, 1e-300)
        sn = xq - qn @ p
        inter = float(sn @ np.minimum(1.0, r3 / (rho2n * np.sqrt(rho2n))))
        inter += r3 * (g0 + float(grad @ (p - p0)))
        return FOUR_PI / 3.0 * r3 - inter

    return outside


def _powell(f, p0: np.ndarray, delta: float) -> tuple[np.ndarray, float]:
    """Powell's method on the centre within ``p0 ± delta``, in units of ``delta``.

    scipy's bounded Powell line search has an absolute tolerance, so the
    variables are scaled to make the fit independent of the mesh's units.
    """
    from scipy.optimize import minimize

    def scaled(u):
        return f(p0 + delta * u)

    res = minimize(scaled, np.zeros(3), method="Powell", bounds=[(-1.0, 1.0)] * 3,
                   options={"xtol": POWELL_XTOL, "ftol": 1e-3, "maxiter": 2, "maxfev": 80})
    return p0 + delta * np.asarray(res.x, dtype=np.float64), float(res.fun)


def _update_centers(solid: Solid, centers: np.ndarray, labels: np.ndarray):
    """Powell per cluster: minimise V(S_i - T) subject to bounding the cluster.

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
    for i in range(n):
        members = solid.points[order[bounds_idx[i]:bounds_idx[i + 1]]]
        if len(members) == 0:
            continue
        hull = hull_vertices(members)
        p0 = centers[i]
        r0 = float(np.sqrt(np.max(np.sum((hull - p0) ** 2, axis=1))))
        delta = CENTER_STEP * r0 + 1e-3 * solid.diag
        f = _sphere_objective(solid, hull, p0, delta)
        f0 = f(p0)
        best_p, best_f = p0, f0
        if f0 > zero:
            p, fp = _powell(f, p0, delta)
            if fp < f0:
                best_p, best_f = p, fp
        new_c[i] = best_p
        radii[i] = float(np.sqrt(np.max(np.sum((hull - best_p) ** 2, axis=1))))
        outside[i] = max(best_f, 0.0)
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
    labels, _ = _flood_fill(solid, centers, table, r_grid[1])
    c, r, _ = _update_centers(solid, centers, labels)
    c, r = _shrink(solid, c, r, rounds=1)
    out = np.array([max(FOUR_PI / 3 * ri**3 - solid.flux.intersection_volume(ci, ri), 0.0)
                    for ci, ri in zip(c, r, strict=True)])
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


def _split_clusters(solid: Solid, centers: np.ndarray, radii: np.ndarray, splits: int,
                    ) -> _State:
    """The state after splitting the ``splits`` spheres whose split gains most.

    A sphere's own points (those no other sphere covers) are cut in two by the
    plane through their centroid normal to each principal axis; the halves'
    minimal bounding spheres replace it when their outside volume
    (inner-loop estimate) undercuts its own by the most.  Splits are applied
    in order of gain, each re-deriving the sphere's own points after the
    earlier ones, so the union still covers every point; a split is only
    made when it lowers the estimate, so the state's E is at most the input's.
    Spheres that cannot be split usefully are added with zero radius (they
    cost nothing; Lloyd steps and teleports put them to use).

    Returns
    -------
    _State
        ``N + splits`` spheres, their flood-fill clusters and outside volumes.
    """
    pts = solid.cover
    slack = SHRINK_SLACK * solid.diag

    def covers(c: np.ndarray, r: float) -> np.ndarray:
        return np.linalg.norm(pts - c, axis=1) <= r * (1 + 1e-9) + slack

    def outside(c: np.ndarray, r: float) -> float:
        return max(FOUR_PI / 3 * r**3 - solid.flux.intersection_volume(c, r), 0.0)

    def best_split(own: np.ndarray, parent: float):
        """(gain, children, their outside volumes) of the best plane cut."""
        best = (-np.inf, None, None)
        if len(own) < 2:
            return best
        mean = own.mean(axis=0)
        _, _, axes = np.linalg.svd(own - mean, full_matrices=False)
        for axis in axes:
            side = (own - mean) @ axis > 0
            if side.all() or not side.any():
                continue
            halves = [minimal_bounding_sphere(own[side]), minimal_bounding_sphere(own[~side])]
            out = [outside(c, r) for c, r in halves]
            if parent - sum(out) > best[0]:
                best = (parent - sum(out), halves, out)
        return best

    inside = [covers(c, r) for c, r in zip(centers, radii, strict=True)]
    count = np.sum(inside, axis=0)
    parent_out = [outside(c, r) for c, r in zip(centers, radii, strict=True)]
    gains = np.array([best_split(pts[inside[i] & (count == 1)], parent_out[i])[0]
                      for i in range(len(centers))])
    new_c, new_r, new_o = list(centers), list(radii), list(parent_out)
    # split in order of gain, re-deriving each sphere's own points after the
    # earlier splits: a point two spheres shared must stay inside a child
    for i in np.argsort(-gains, kind="stable")[:splits]:
        own = pts[inside[i] & (count == 1)]
        gain, halves, out = best_split(own, new_o[i])
        if not gain > 0:
            continue
        (ca, ra), (cb, rb) = halves
        in_a, in_b = covers(ca, ra), covers(cb, rb)
        count += in_a.astype(np.int64) + in_b - inside[i]
        inside[i] = in_a
        inside.append(in_b)
        new_c[i], new_r[i], new_o[i] = ca, ra, out[0]
        new_c.append(cb)
        new_r.append(rb)
        new_o.append(out[1])
    while len(new_c) < len(centers) + splits:
        # a zero sphere next to the sphere of largest outside volume
        j = int(np.argmax(new_o))
        new_c.append(new_c[j] + 1e-3 * solid.diag)
        new_r.append(0.0)
        new_o.append(0.0)
    c = np.asarray(new_c, dtype=np.float64)
    r = np.asarray(new_r, dtype=np.float64)
    o = np.asarray(new_o, dtype=np.float64)
    r_grid = np.linspace(0.0, solid.diag, PROFILE_BINS)
    labels, _ = _flood_fill(solid, c, solid.flux.outside_profiles(c, r_grid), r_grid[1])
    return _State(c, r, labels, o, float(o.sum() / solid.volume))


def _variational(solid: Solid, n: int, rng: np.random.Generator, *, max_iterations: int,
                 max_teleport_failures: int, progress=None):
    if n >= COARSE_TO_FINE_MIN:
        # the budget is max_iterations rounds at n spheres; a round costs
        # about (points x spheres), so the coarse stage's share buys rounds
        # at ``half`` spheres at a proportionally higher count
        half = (n + 1) // 2
        work = max_iterations * n
        c, r, _, coarse = _variational(
            solid, half, rng, max_iterations=max(1, int(COARSE_SHARE * work / half)),
            max_teleport_failures=max_teleport_failures, progress=progress)
        start = _split_clusters(solid, c, r, n - half)
        used = coarse["iterations"]
        fine_rounds = max(1, int((work - coarse["work"]) / n))
        centers, radii, labels, info = _lloyd_search(
            solid, start, max_iterations=fine_rounds,
            max_teleport_failures=max_teleport_failures,
            progress=None if progress is None else (lambda i, e: progress(used + i, e)))
        for key in ("iterations", "teleports_tried", "teleports_accepted", "work"):
            info[key] += coarse[key]
        return centers, radii, labels, info
    return _lloyd_search(solid, _initial_centers(solid.points, n, rng),
                         max_iterations=max_iterations,
                         max_teleport_failures=max_teleport_failures, progress=progress)


def _lloyd_search(solid: Solid, start: np.ndarray | _State, *, max_iterations: int,
                  max_teleport_failures: int, progress=None):
    """Lloyd steps with teleportation from the centres ``start (N, 3)`` or a state."""
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
    centers, radii = _shrink(solid, best.centers, best.radii, rounds=SHRINK_ROUNDS)
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
    every point.  With ``recenter``, Powell then moves each centre for its own
    points.
    """
    pts = solid.cover
    # distances through |p|² - 2 p·c + |c|² (one mat-mul instead of a (P, N, 3)
    # temporary), about the points' mean to keep the cancellation small; the
    # final cover step re-checks containment exactly
    origin = pts.mean(axis=0)
    pts = pts - origin
    pp = np.einsum("ij,ij->i", pts, pts)
    slack = SHRINK_SLACK * solid.diag

    def distances(c: np.ndarray) -> np.ndarray:
        c = c - origin
        return np.sqrt(np.maximum(pp[:, None] - 2.0 * (pts @ c.T) + np.sum(c * c, axis=-1), 0.0))

    centers = centers.copy()
    radii = radii.copy()
    order = np.argsort(-radii, kind="stable")
    for _ in range(rounds):
        before = (centers.copy(), radii.copy())
        dist = distances(centers)  # (P, N)
        inside = dist <= radii[None, :] + slack
        count = inside.sum(axis=1)
        for i in order:
            own = inside[:, i] & (count == 1)
            if not np.any(own):
                continue
            radii[i] = float(dist[own, i].max())
            lost = inside[:, i] & (dist[:, i] > radii[i] + slack)
            count[lost] -= 1
            inside[lost, i] = False
        if not recenter:
            break
        # sequentially, so that a point two spheres share is dropped by at
        # most one of them
        for i in order:
            own = inside[:, i] & (count == 1)
            if not np.any(own):
                continue
            hull = hull_vertices(pts[own]) + origin
            p0 = centers[i]
            delta = CENTER_STEP * radii[i] + 1e-3 * solid.diag
            f = _sphere_objective(solid, hull, p0, delta)
            f0 = f(p0)
            p, fp = _powell(f, p0, delta)
            if not fp < f0:
                continue
            centers[i] = p
            radii[i] = float(np.sqrt(np.max(np.sum((hull - p) ** 2, axis=1))))
            dist[:, i] = distances(centers[i:i + 1])[:, 0]
            now = dist[:, i] <= radii[i] + slack
            count += now.astype(np.int64) - inside[:, i]
            inside[:, i] = now
        # a fixed point: no sphere moved or shrank noticeably this round
        moved = np.max(np.linalg.norm(centers - before[0], axis=1) + before[1] - radii)
        if moved <= SHRINK_TOLERANCE * solid.diag:
            break
    return centers, radii


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
