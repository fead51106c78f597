"""Where the variational search starts, and the cluster split it is built on.

Below SPLIT_START_MIN spheres the start is random centres spread by D²
sampling (k-means++ seeding).  From there on it is k-means clusters split in
two SPLIT_LEVELS times (:func:`_split_start`): every part of a shape gets
spheres in proportion to what it costs, where random centres crowd some parts
and starve others (thin limbs).  The split itself (:func:`_split_clusters`)
also refines a coarse fit (:mod:`.fit`) and replaces vanishing or duplicate
spheres (:func:`_revive`).
"""

from __future__ import annotations

import hashlib
import warnings

import numpy as np

from shtools.geometry.outside_volume import FOUR_PI
from shtools.geometry.sphere_fit.baselines import _kmeans
from shtools.geometry.sphere_fit.cover import _cover
from shtools.geometry.sphere_fit.lloyd import PROFILE_BINS, _flood_fill, _State
from shtools.geometry.sphere_fit.shrink import SHRINK_SLACK
from shtools.geometry.sphere_fit.solid import DEAD_RADIUS, Solid
from shtools.geometry.sphere_set import minimal_bounding_sphere

#: From this N on (below COARSE_TO_FINE_MIN) the variational fit starts from
#: k-means clusters of the points, ceil(N / 2**SPLIT_LEVELS) of them, split in
#: two SPLIT_LEVELS times (:func:`_split_start`) instead of random centres:
#: spheres go to the parts of a shape as a coarse fit sends them, for a
#: fraction of its cost.  Two levels do better than one; three start from so
#: few k-means clusters that compact shapes lose.  Below SPLIT_START_MIN the
#: split start predicts little and the start is random.
SPLIT_START_MIN = 32
SPLIT_LEVELS = 2

#: Smallest radius (fraction of the diagonal) of a sphere made by a split: a
#: cut that leaves a (near) single point on one side would make a vanishing
#: sphere, which the fit must not return.
MIN_CHILD_RADIUS = 1e-6


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


def _first_centers(solid: Solid, n: int, rng: np.random.Generator) -> np.ndarray:
    """Start centres ``(n, 3)`` of a search below COARSE_TO_FINE_MIN: split
    k-means clusters from SPLIT_START_MIN on (:func:`_split_start`), random
    ones (:func:`_initial_centers`) below."""
    if n >= SPLIT_START_MIN:
        return _split_start(solid, n, rng)
    return _initial_centers(solid.points, n, rng)


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
    # estimate (zero-radius placeholders could survive the search
    # as vanishing duplicates)
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
