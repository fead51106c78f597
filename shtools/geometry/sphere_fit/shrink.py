"""Shrink every sphere to the points no other sphere covers, then re-centre it.

E sums the spheres' outside volumes, so a point already inside another sphere
need not hold a radius up: each sphere shrinks to its own points (largest
first, so the union still covers every point) and the compass search
(:mod:`.recenter`) moves it for them.
"""

from __future__ import annotations

import numpy as np

from shtools.geometry.sphere_fit.recenter import CENTER_STEP, _recenter
from shtools.geometry.sphere_fit.solid import Solid

#: Rounds of shrink-to-own-points and re-centring after the Lloyd iterations
#: (at most; they stop at a fixed point, when no sphere moves or shrinks by more
#: than SHRINK_TOLERANCE of the diagonal).
SHRINK_ROUNDS = 12
SHRINK_TOLERANCE = 1e-5

#: Distance (fraction of the diagonal) within which a point counts as on a
#: sphere during shrinking: absorbs the rounding of the mat-mul distances.
SHRINK_SLACK = 1e-9


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
    # must grow to take back), so from two rounds on the round of least
    # estimated E is kept
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
