"""Fit a set of N spheres that bounds a mesh's solid with minimal outside volume.

``method="variational"`` is the algorithm of Wang et al. 2006 as summarised in
SHEXP (Ren et al. 2006, section 6.2; see docs/references.md):

1. Discretise the solid T into surface samples and interior grid corners
   (:mod:`.solid`).
2. Flood-fill clustering: every point joins the cluster whose sphere's outside
   volume V(S - T) grows least when its radius is extended to include it
   (:mod:`.lloyd`).
3. Centre update: every cluster's centre moves to minimise V(S - T) with the
   radius bounding the cluster's points, all spheres in one batched compass
   search (:mod:`.recenter`).  Then each sphere shrinks to the points no
   other sphere covers and is re-centred for them (:mod:`.shrink`); the union
   still covers every point.
4. Cluster teleportation when an iteration no longer lowers E (:mod:`.lloyd`).
5. Starts: random centres for few spheres, split k-means clusters from
   SPLIT_START_MIN on (:mod:`.starts`), and from COARSE_TO_FINE_MIN on a fit
   of ceil(N/2) spheres whose clusters are split in two (:mod:`.fit`).  Each
   stage spends part of one work budget (rounds x spheres).

The spheres then must hold the whole surface, not only its samples
(:mod:`.cover`), and E = Σ V(S_i - T)/V(T) is computed with the accurate flux
evaluator of :mod:`shtools.geometry.outside_volume`.  Baselines for comparison
at equal sphere counts: ``"octree"`` and ``"kmeans"`` (:mod:`.baselines`).
"""

from shtools.geometry.sphere_fit.cover import (
    COVER_LEVELS,
    COVER_PAIRS,
    COVER_PASSES,
    COVER_PIECE,
    COVER_SLACK,
    GROW_BLOCK,
)
from shtools.geometry.sphere_fit.fit import (
    COARSE_SHARE,
    COARSE_TO_FINE_MIN,
    COVERAGE_SAMPLES,
    QUICK_SHRINK_ROUNDS,
    ROUNDS,
    distinct_spheres,
    fit_spheres,
)
from shtools.geometry.sphere_fit.lloyd import PROFILE_BINS, STALL_SHARE, TELEPORT_CANDIDATES
from shtools.geometry.sphere_fit.recenter import (
    CENTER_STEP,
    COMPASS_ITERATIONS,
    KEEP_FRACTION,
    NEAR_REACH,
    POWELL_XTOL,
)
from shtools.geometry.sphere_fit.shrink import SHRINK_ROUNDS, SHRINK_SLACK, SHRINK_TOLERANCE
from shtools.geometry.sphere_fit.solid import (
    COVER_SURFACE_POINTS,
    DEAD_RADIUS,
    FLUX_EDGE_DIVISOR,
    FLUX_SAMPLES_PER_SPHERE,
    MAX_FLUX_SAMPLES,
    MAX_POINTS,
    MAX_VERTEX_POINTS,
    MIN_FLUX_SAMPLES,
    MIN_POINTS,
    NEIGHBOURS,
    POINTS_PER_SPHERE,
    ZERO_VOLUME_FRACTION,
    Solid,
    discretize,
)
from shtools.geometry.sphere_fit.starts import MIN_CHILD_RADIUS, SPLIT_LEVELS, SPLIT_START_MIN

__all__ = [
    "CENTER_STEP", "COARSE_SHARE", "COARSE_TO_FINE_MIN", "COMPASS_ITERATIONS", "COVERAGE_SAMPLES",
    "COVER_LEVELS", "COVER_PAIRS", "COVER_PASSES", "COVER_PIECE", "COVER_SLACK",
    "COVER_SURFACE_POINTS", "DEAD_RADIUS", "FLUX_EDGE_DIVISOR", "FLUX_SAMPLES_PER_SPHERE",
    "GROW_BLOCK", "KEEP_FRACTION", "MAX_FLUX_SAMPLES", "MAX_POINTS", "MAX_VERTEX_POINTS",
    "MIN_CHILD_RADIUS", "MIN_FLUX_SAMPLES", "MIN_POINTS", "NEAR_REACH", "NEIGHBOURS",
    "POINTS_PER_SPHERE", "POWELL_XTOL", "PROFILE_BINS", "QUICK_SHRINK_ROUNDS", "ROUNDS",
    "SHRINK_ROUNDS", "SHRINK_SLACK", "SHRINK_TOLERANCE", "SPLIT_LEVELS", "SPLIT_START_MIN",
    "STALL_SHARE", "TELEPORT_CANDIDATES", "ZERO_VOLUME_FRACTION", "Solid", "discretize",
    "distinct_spheres", "fit_spheres",
]
