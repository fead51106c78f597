"""Minimal spheres enclosing spheres.

:func:`minimal_enclosing_sphere` solves ``min_{c, r} r`` subject to
``|c - c_i| + r_i <= r`` (the smallest ball containing a set of balls, a convex
second-order cone problem).  It is solved with SLSQP on the smooth equivalent
``(r - r_i)^2 >= |c - c_i|^2, r >= r_i`` in coordinates normalised by a feasible
starting bound, with analytic gradients.  The returned radius is always
recomputed as ``max_i |c - c_i| + r_i`` about the returned centre, so the
result bounds every input sphere exactly (up to rounding) whatever the
optimiser did; optimality is to the solver tolerance (``~1e-9`` relative,
checked against an exhaustive support-set search in the tests).

:func:`sphere_pair_bound` (exact for two spheres) is re-exported from the
numpy-only runtime module, which uses it to refit trees every frame.
:func:`box_sphere` is the cheap bound of a posed mesh the traced shadows' cones and
hand-over reach use, :func:`overlapping_groups` the objects those bounds join.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from shtools.runtime.spheres import sphere_pair_bound

__all__ = ["box_sphere", "enclosing_radius", "minimal_enclosing_sphere", "overlapping_groups",
           "sphere_pair_bound"]

#: SLSQP stopping tolerance on the radius, in units of the starting radius.
SOLVER_FTOL = 1e-13
SOLVER_MAXITER = 200


def box_sphere(points) -> tuple[np.ndarray, float]:
    """Bounding sphere of points ``(V, 3)``: their box centre ``(3,)`` and the farthest
    point's distance from it (not minimal: one pass, and the same for every caller)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    center = 0.5 * (p.min(axis=0) + p.max(axis=0))
    return center, float(np.sqrt(((p - center) ** 2).sum(axis=1).max()))


def overlapping_groups(spheres: list) -> list[list[int]]:
    """Indices of bounding spheres ``[(center (3,), radius), ...]`` grouped by overlap,
    directly or through others (each group and the groups in the spheres' order)."""
    group = list(range(len(spheres)))

    def root(i):
        while group[i] != i:
            i = group[i]
        return i

    for i, (ci, ri) in enumerate(spheres):
        for j in range(i):
            cj, rj = spheres[j]
            if np.linalg.norm(np.asarray(ci) - np.asarray(cj)) < ri + rj:
                group[max(root(i), root(j))] = min(root(i), root(j))
    out: dict = {}
    for i in range(len(spheres)):
        out.setdefault(root(i), []).append(i)
    return list(out.values())


def enclosing_radius(center, centers, radii) -> float:
    """Radius of the smallest sphere about ``center`` containing every sphere.

    Parameters
    ----------
    center : array_like, shape (3,)
    centers : array_like, shape (K, 3)
    radii : array_like, shape (K,)

    Returns
    -------
    float
        ``max_i |center - c_i| + r_i``.
    """
    centers = np.asarray(centers, dtype=np.float64)
    return float(np.max(np.linalg.norm(centers - np.asarray(center), axis=1) + radii))


def _initial_bound(centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """A feasible centre: pair-merge from the largest sphere, farthest first."""
    order = np.argsort(-radii, kind="stable")
    c, r = centers[order[0]], radii[order[0]]
    remaining = list(order[1:])
    while remaining:
        reach = np.linalg.norm(centers[remaining] - c, axis=1) + radii[remaining]
        k = int(np.argmax(reach))
        if reach[k] <= r:
            break
        j = remaining.pop(k)
        c, r = sphere_pair_bound(c, r, centers[j], radii[j])
    return np.asarray(c, dtype=np.float64)


def minimal_enclosing_sphere(centers, radii, *, initial_center=None) -> tuple[np.ndarray, float]:
    """Smallest sphere containing every given sphere.

    Parameters
    ----------
    centers : array_like, shape (K, 3)
    radii : array_like, shape (K,)
        Non-negative.
    initial_center : array_like, shape (3,), optional
        Warm start (e.g. the mean of the centres, as SHEXP section 6.3 does).

    Returns
    -------
    center : ndarray, shape (3,)
    radius : float
        ``radius >= |center - c_i| + r_i`` for every ``i`` (by construction).
    """
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    k = centers.shape[0]
    if k == 0:
        raise ValueError("need at least one sphere")
    if radii.shape != (k,) or np.any(radii < 0) or not np.all(np.isfinite(centers)):
        raise ValueError("radii must be finite, non-negative, one per centre")
    if k == 1:
        return centers[0].copy(), float(radii[0])
    if k == 2:
        c, r = sphere_pair_bound(centers[0], radii[0], centers[1], radii[1])
        return np.asarray(c), float(r)
    big = int(np.argmax(radii))
    # any enclosing sphere has r >= r_max, so a largest sphere containing all is optimal
    if enclosing_radius(centers[big], centers, radii) <= radii[big]:
        return centers[big].copy(), float(radii[big])

    start = _initial_bound(centers, radii)
    start_r = enclosing_radius(start, centers, radii)
    if initial_center is not None:
        guess = np.asarray(initial_center, dtype=np.float64)
        if enclosing_radius(guess, centers, radii) < start_r:
            start, start_r = guess, enclosing_radius(guess, centers, radii)
    scale = start_r if start_r > 0 else 1.0
    # normalised coordinates: the start is the origin with radius 1
    p = (centers - start) / scale
    s = radii / scale

    def objective(x):
        return x[3]

    def objective_grad(x):
        return np.array([0.0, 0.0, 0.0, 1.0])

    def cons(x):
        d = x[:3] - p
        return (x[3] - s) ** 2 - np.einsum("ij,ij->i", d, d)

    def cons_jac(x):
        jac = np.empty((k, 4))
        jac[:, :3] = -2.0 * (x[:3] - p)
        jac[:, 3] = 2.0 * (x[3] - s)
        return jac

    x0 = np.array([0.0, 0.0, 0.0, 1.0])
    result = minimize(
        objective,
        x0,
        jac=objective_grad,
        method="SLSQP",
        bounds=[(None, None)] * 3 + [(float(s.max()), None)],
        constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
        options={"ftol": SOLVER_FTOL, "maxiter": SOLVER_MAXITER},
    )
    best_center, best_radius = start, start_r
    if np.all(np.isfinite(result.x)):
        center = start + scale * result.x[:3]
        radius = enclosing_radius(center, centers, radii)
        if radius < best_radius:
            best_center, best_radius = center, radius
    return np.asarray(best_center, dtype=np.float64), float(best_radius)
