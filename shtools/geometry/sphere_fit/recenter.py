"""The batched compass search that moves sphere centres to minimise V(S - T).

Each sphere keeps the radius that bounds its points (their convex hull's
vertices suffice), and the search moves its centre within a box.  V(S - T)
comes from the flux samples: those a move may bring inside the sphere are
summed exactly, the rest through a first-order far-field expansion.  All
spheres of a batch move in one vectorised pass per compass iteration, and
results are memoised on the :class:`~.solid.Solid` (the search is
deterministic).
"""

from __future__ import annotations

import hashlib

import numpy as np
import scipy.sparse

from shtools.geometry.outside_volume import FOUR_PI, dot_rows
from shtools.geometry.sphere_fit.solid import Solid

#: Largest centre move per update, as a fraction of the cluster radius: bounds
#: the samples the objective must visit; the next round continues the walk.
CENTER_STEP = 0.25

#: The compass search's tolerance, in units of the largest centre move.
POWELL_XTOL = 1e-2

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
    # cluster has settled) reuses that result
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
