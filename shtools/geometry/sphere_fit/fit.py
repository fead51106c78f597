"""``fit_spheres``: the entry point, the coarse-to-fine schedule and the finish."""

from __future__ import annotations

import time

import numpy as np
import trimesh

from shtools.errors import InputError
from shtools.geometry.fit_methods import DEFAULT_ROUNDS, FIT_METHODS
from shtools.geometry.sphere_fit.baselines import _kmeans, _octree
from shtools.geometry.sphere_fit.cover import COVER_PASSES, _cover, _covered_fraction, _settle_cover
from shtools.geometry.sphere_fit.lloyd import _lloyd_search
from shtools.geometry.sphere_fit.shrink import SHRINK_ROUNDS
from shtools.geometry.sphere_fit.solid import DEAD_RADIUS, Solid, discretize
from shtools.geometry.sphere_fit.starts import (
    _first_centers,
    _initial_centers,
    _revive,
    _split_clusters,
)
from shtools.geometry.sphere_set import SphereSet

#: Default round budget (rounds at N spheres; see ``max_iterations``) at every
#: N: enough for the search to settle at the sphere counts the scenes use,
#: from COARSE_TO_FINE_MIN spheres on too, where the coarse fit spends half.
ROUNDS = DEFAULT_ROUNDS

#: A fit of fewer rounds than SHRINK_ROUNDS is a quick fit: its finish scales
#: with its budget (:func:`_finish_effort`), at least this many shrink rounds,
#: so that a short budget buys a short fit (the full finish would dominate it).
QUICK_SHRINK_ROUNDS = 4

#: From this N on, the variational fit starts from a fit of ceil(N/2) spheres
#: whose clusters are split in two (recursively), instead of random centres:
#: Lloyd steps and one-sphere teleports relocate spheres one at a time, which
#: does not converge within the round budget once N is large.  Below it a
#: coarse fit costs more than it gains on compact shapes, and the split start
#: serves (:data:`.starts.SPLIT_START_MIN`).  The coarse fit gets
#: COARSE_SHARE of the work budget (rounds x spheres).
COARSE_TO_FINE_MIN = 64
COARSE_SHARE = 0.5

#: Fresh, evenly spread surface points on which the reported coverage is measured.
COVERAGE_SAMPLES = 20_000


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
    diagnostics: bool = True,
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
        the finish shortens with the budget too (:func:`_finish_effort`).
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
        lowest E is returned (the search is non-convex: E varies from seed to
        seed).
        ``info["restart_E"]`` lists every start's E.  The knob for spending
        more CPU on a lower E.
    diagnostics : bool
        Measure the result's ``outside_volume_ratio`` and ``coverage`` (NaN
        otherwise; a bake that fits on the fly uses only the spheres, and the
        accurate flux evaluation of E costs about half of a k-means fit).  Always
        measured with ``restarts > 1``, which picks the start of lowest E.

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
    if method not in FIT_METHODS:
        raise InputError(f"unknown method '{method}'; use one of {', '.join(FIT_METHODS)}")
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
                         path=path, bar=bar, diagnostics=diagnostics)


def _fit_once(mesh, n, *, method, seed, thickness, max_iterations, max_teleport_failures,
              samples, path, bar, diagnostics=True) -> SphereSet:
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
        # the search's objective: E on the solid's sample points, before the spheres are
        # grown to hold the whole surface -- not the accurate E the result reports
        bar.set_postfix(objective=f"{energy:.3f}", refresh=False)
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
    covered = ratio = float("nan")
    if diagnostics:
        # coverage on fresh, evenly spread surface points the fit never saw
        fresh = np.asarray(trimesh.sample.sample_surface_even(unit, COVERAGE_SAMPLES,
                                                              seed=seed + 1)[0])
        covered = _covered_fraction(centers, radii, fresh)
        ratio = float(solid.evaluator.outside_volume(centers, radii).sum() / solid.volume)
    info["seconds"] = time.perf_counter() - start
    info["volume"] = solid.volume * scale**3
    return SphereSet(centers * scale + origin, radii * scale, outside_volume_ratio=ratio,
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


def _variational(solid: Solid, n: int, rng: np.random.Generator, *, max_iterations: int,
                 max_teleport_failures: int, progress=None, split: bool = True):
    """The search of :func:`fit_spheres` at ``n`` spheres: its start, its rounds and
    the final shrink.

    From COARSE_TO_FINE_MIN spheres on the search starts from a fit of
    ceil(n/2) spheres split in two, which spends COARSE_SHARE of the work
    budget (max_iterations rounds at ``n``); below that the start is
    :func:`_first_centers` (split from SPLIT_START_MIN on, random below), or
    random without ``split`` (the coarse stages: their fits are only split
    further, and a random start keeps them cheap).

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


def _finish_effort(max_iterations: int) -> tuple[int, int]:
    """Shrink rounds and surface-cover passes of the finish of a fit of
    ``max_iterations`` rounds: SHRINK_ROUNDS and COVER_PASSES, or for a quick
    fit (fewer rounds than SHRINK_ROUNDS) as many shrink rounds as search
    rounds, at least QUICK_SHRINK_ROUNDS, and one cover pass, so that a short
    budget buys a short fit (the finish would otherwise dominate it)."""
    if max_iterations >= SHRINK_ROUNDS:
        return SHRINK_ROUNDS, COVER_PASSES
    return max(QUICK_SHRINK_ROUNDS, int(max_iterations)), min(1, COVER_PASSES)
