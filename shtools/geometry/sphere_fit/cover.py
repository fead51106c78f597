"""Make a sphere set hold the whole surface, not only its samples.

A ball is convex, so a triangle whose three corners lie in one sphere is
inside it.  Triangles split between spheres are subdivided, and only small
pieces make a sphere grow: the sphere whose volume grows least, since E sums
volumes.  A piece also counts as held when it lies in the union of two
spheres (:func:`_pair_held`).  :func:`_settle_cover` then lets the spheres
that grew re-centre for the pieces that made them grow.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from shtools.geometry.sphere_fit.shrink import SHRINK_ROUNDS, _shrink
from shtools.geometry.sphere_fit.solid import Solid, _squared_distances
from shtools.geometry.sphere_set import SphereSet

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
#: then need no growth.
COVER_PAIRS = True

#: Rounds of adding the surface pieces no sphere holds to the cover points and
#: re-centring the spheres for them (see :func:`_settle_cover`).  The set of
#: least estimated E among the passes' results is kept, so a pass that does
#: not help costs only time; a second pass still helps shapes with thin parts,
#: whose seams leave the most pieces uncovered.
COVER_PASSES = 2

#: Radius growth added to every sphere at the end (fraction of the diagonal) so
#: that points on a sphere's boundary are inside after floating-point rounding.
COVER_SLACK = 1e-9


def _covered_fraction(centers, radii, points) -> float:
    return float(SphereSet(centers, radii).contains(points).mean())


def _cover(solid: Solid, centers: np.ndarray, radii: np.ndarray, *, pieces: list | None = None,
           ) -> np.ndarray:
    """Grow radii (least volume growth first) until every cover point and every
    point of the mesh's surface lies in some sphere.

    A ball is convex, so a triangle (or piece of one) whose three corners are
    in one sphere is inside it: the whole surface is covered, not only its
    samples (covering samples alone leaves slivers of surface between them
    outside).  Growing a sphere to hold a whole large triangle would cost
    much outside volume, so triangles split between spheres are subdivided
    first and only small pieces make a sphere grow.
    """
    radii = np.asarray(radii, dtype=np.float64).copy()
    n = len(centers)
    centers_t = np.ascontiguousarray(np.asarray(centers, dtype=np.float64).T)  # (3, N)

    def grow_for(pieces_: np.ndarray) -> None:
        """Grow, for each piece ``(T, K, 3)``, the sphere whose volume grows least.

        E sums sphere volumes, so the cost of holding a piece is the volume a
        sphere gains (need³ - r³), not the radius it gains: ranking by radius
        would grow large spheres as readily as small ones."""
        corners = pieces_.shape[1]
        # the radii grow after each batch of ``per`` pieces (the batches are
        # part of the rule: later pieces see the earlier growth); within a
        # batch the (pieces, N) distances are built ``sub`` pieces at a time,
        # axis by axis, in cache-sized blocks instead of one (T, K, N, 3)
        # temporary (several times faster; same sums, same result)
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
    :func:`_cover` grow spheres, and growing alone is costly.  The corners of
    the pieces that made spheres grow join the cover points and the
    shrink-and-re-centre steps run again, so that the spheres move to hold
    them instead of only growing; then :func:`_cover` closes what is left.
    ``passes`` times at most, each with ``shrink_rounds`` shrink-and-re-centre
    rounds (see :func:`.fit._finish_effort`).

    Every pass ends in a surface-bounding set, and so does the growth alone
    before the first; the set of least outside volume (inner-loop estimate)
    is returned.  Which one wins is chaotic: re-centring lowers E on most fits
    but can raise it, depending on bits of the search.

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


def _unique_rows(points: np.ndarray) -> np.ndarray:
    """``np.unique(points, axis=0)`` for float rows ``(P, 3)`` without NaN: the
    distinct rows in lexicographic order, by one lexsort (several times faster
    than sorting rows as structured records)."""
    ordered = points[np.lexsort(points.T[::-1])]
    first = np.ones(len(ordered), dtype=bool)
    first[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    return ordered[first]
