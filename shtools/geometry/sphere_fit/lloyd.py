"""Lloyd steps with cluster teleportation: the search of the variational fit.

One step (:func:`_lloyd_step`) is a flood-fill clustering, a centre update and
one shrink round.  In the flood fill, fronts grow over the k-nearest-neighbour
graph from every centre, and each point joins the cluster whose sphere's
outside volume V(S - T) grows least when its radius is extended to include it;
radial outside-volume profiles per centre make this a table look-up, and the
fronts are processed as vectorised breadth-first batches.  Each cluster's
centre then moves to minimise V(S - T) with the radius bounding the cluster
(:mod:`.recenter`), and each sphere shrinks to the points no other sphere
covers (:mod:`.shrink`).

When a step no longer lowers E, the search teleports (:func:`_teleport`):
it splits the cluster of largest outside volume at its farthest-apart points
and deletes another sphere, tries TELEPORT_CANDIDATES such choices for one
step each, and keeps the best, refined, only if E drops.  Steps are memoised
(they are deterministic), so returning to the best state after a rejected
teleport costs nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.geometry.outside_volume import FOUR_PI
from shtools.geometry.sphere_fit.recenter import CENTER_STEP, _recenter
from shtools.geometry.sphere_fit.shrink import _shrink
from shtools.geometry.sphere_fit.solid import DEAD_RADIUS, Solid, _squared_distances

#: Radial profile resolution (radii from 0 to the bounding-box diagonal).
PROFILE_BINS = 512

#: Teleportation candidates (split cluster, deleted sphere) tried per stall;
#: the one with the lowest E after a Lloyd step is refined and kept if E drops.
TELEPORT_CANDIDATES = 3

#: A Lloyd step or teleport counts as progress when it lowers E by more than
#: this fraction of the average sphere's share E / N.  The threshold is per
#: sphere because a teleport moves one or two spheres: a fixed fraction of the
#: total E would reject every useful teleport once N is large (at N = 128 a
#: 0.5 % drop of E is 64 % of an average sphere's outside volume).
STALL_SHARE = 0.08


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
