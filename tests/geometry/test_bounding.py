"""Minimal enclosing sphere of spheres vs closed forms and an exhaustive support-set search."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from shtools.geometry.bounding import minimal_enclosing_sphere, sphere_pair_bound
from shtools.geometry.sphere_set import minimal_bounding_sphere

#: SLSQP stops at ftol 1e-13 of the starting radius; 1e-7 relative leaves a wide
#: margin for its last step while still catching any suboptimal (e.g. Ritter) bound,
#: which is typically 1e-2 too large.
OPT_RTOL = 1e-7
#: the returned radius is recomputed from the centre, so containment holds to rounding
CONTAIN_ATOL = 1e-12


def _tangent_sphere(c, r):
    """Candidate balls internally tangent to every ball of a support set (Apollonius).

    Independent of the library: centre in the affine hull of the support centres,
    |x - c_i| = R - r_i for all i, solved as a linear system in (t, R) plus one
    quadratic in R.
    """
    c0, r0 = c[0], r[0]
    if len(c) == 1:
        return [(c0, r0)]
    a = (c[1:] - c0).T  # (3, m-1)
    g = a.T @ a
    if abs(np.linalg.det(g)) < 1e-14:
        return []
    dr = r[1:] - r0
    # G t = (|a_i|^2 - (r_i - r0)(r_i + r0))/2 + (r_i - r0) R
    t0 = np.linalg.solve(g, 0.5 * (np.sum(a * a, axis=0) - dr * (r[1:] + r0)))
    t1 = np.linalg.solve(g, dr)
    e0, e1 = a @ t0, a @ t1
    # |e0 + e1 R|^2 = (R - r0)^2
    qa = e1 @ e1 - 1.0
    qb = 2 * e0 @ e1 + 2 * r0
    qc = e0 @ e0 - r0 * r0
    if abs(qa) < 1e-14:
        roots = [-qc / qb] if abs(qb) > 1e-14 else []
    else:
        disc = qb * qb - 4 * qa * qc
        if disc < 0:
            return []
        roots = [(-qb + s * np.sqrt(disc)) / (2 * qa) for s in (1, -1)]
    return [(c0 + e0 + e1 * R, R) for R in roots if R >= r.max() - 1e-12]


def brute_force_enclosing(centers, radii):
    best = (None, np.inf)
    for m in range(1, 5):
        for subset in itertools.combinations(range(len(radii)), m):
            for c, R in _tangent_sphere(centers[list(subset)], radii[list(subset)]):
                reach = np.linalg.norm(centers - c, axis=1) + radii
                if np.all(reach <= R + 1e-9 * max(R, 1)) and R < best[1]:
                    best = (c, R)
    return best


def test_two_spheres_closed_form():
    c1, r1 = np.array([0.0, 0.0, 0.0]), 1.0
    c2, r2 = np.array([4.0, 0.0, 0.0]), 0.5
    # diameter from x = -1 to x = 4.5
    c, r = minimal_enclosing_sphere(np.stack([c1, c2]), [r1, r2])
    assert r == pytest.approx(2.75, rel=1e-15)
    np.testing.assert_allclose(c, [1.75, 0, 0], atol=1e-15)
    c, r = sphere_pair_bound(c1, r1, c2, r2)
    assert float(r) == pytest.approx(2.75, rel=1e-15)


def test_spheres_inside_another_return_it():
    centers = np.array([[0.0, 0, 0], [0.5, 0, 0], [0, -0.3, 0.2], [0.1, 0.1, 0.1]])
    radii = np.array([2.0, 1.0, 0.5, 1.2])
    c, r = minimal_enclosing_sphere(centers, radii)
    np.testing.assert_allclose(c, centers[0], atol=0)
    assert r == 2.0
    c, r = sphere_pair_bound(centers[0], radii[0], centers[1], radii[1])
    assert float(r) == 2.0


def test_regular_tetrahedron_of_equal_spheres():
    # circumradius of a tetrahedron with vertices (±1,±1,±1) (even parity) is sqrt(3)
    verts = np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
    c, r = minimal_enclosing_sphere(verts + 0.3, np.full(4, 0.25))
    np.testing.assert_allclose(c, [0.3, 0.3, 0.3], atol=1e-7)
    assert r == pytest.approx(np.sqrt(3) + 0.25, rel=OPT_RTOL)


@pytest.mark.parametrize("seed", range(12))
def test_random_sets_match_exhaustive_search(seed):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(3, 8))
    centers = rng.normal(size=(k, 3)) * rng.uniform(0.5, 3.0)
    radii = rng.uniform(0.0, 1.0, size=k) ** 2
    c, r = minimal_enclosing_sphere(centers, radii)
    reach = np.linalg.norm(centers - c, axis=1) + radii
    assert np.all(reach <= r + CONTAIN_ATOL * max(r, 1))
    _, r_exact = brute_force_enclosing(centers, radii)
    assert r == pytest.approx(r_exact, rel=OPT_RTOL)


def test_points_are_zero_radius_spheres():
    # three points of a right triangle: the hypotenuse is a diameter
    pts = np.array([[0.0, 0, 0], [2.0, 0, 0], [0, 2.0, 0]])
    c, r = minimal_enclosing_sphere(pts, np.zeros(3))
    np.testing.assert_allclose(c, [1, 1, 0], atol=1e-7)
    assert r == pytest.approx(np.sqrt(2), rel=OPT_RTOL)


#: minimal_bounding_sphere is exact up to rounding: it accepts a core ball that holds
#: its points to 1e-10 of r² and returns the largest distance from that centre, so its
#: radius is >= the minimum and within ~1e-10 of it; 1e-9 leaves a margin for rounding.
POINTS_RTOL = 1e-9


@pytest.mark.parametrize("seed", range(12))
def test_minimal_ball_of_points_matches_exhaustive_search(seed):
    rng = np.random.default_rng(100 + seed)
    k = int(rng.integers(2, 10))
    pts = rng.normal(size=(k, 3)) * rng.uniform(0.01, 100.0, size=3)  # anisotropic, any scale
    c, r = minimal_bounding_sphere(pts)
    assert np.all(np.linalg.norm(pts - c, axis=1) <= r)  # bounds every point, exactly
    _, r_exact = brute_force_enclosing(pts, np.zeros(k))
    assert r == pytest.approx(r_exact, rel=POINTS_RTOL)


@pytest.mark.parametrize("case", ["octahedron", "coincident", "collinear", "square", "one"])
def test_minimal_ball_of_points_closed_forms(case):
    rng = np.random.default_rng(7)
    if case == "octahedron":  # vertices on the unit sphere, a cloud inside: the unit ball
        inner = rng.normal(size=(500, 3))
        inner *= 0.57 / np.linalg.norm(inner, axis=1).max()  # inside the octahedron
        pts, center, radius = np.vstack([np.eye(3), -np.eye(3), inner]), np.zeros(3), 1.0
    elif case == "coincident":
        pts, center, radius = np.tile([[1.0, 2.0, 3.0]], (6, 1)), np.array([1.0, 2.0, 3.0]), 0.0
    elif case == "collinear":  # the extreme pair is a diameter
        pts = np.outer(np.linspace(-1.0, 3.0, 9), [1.0, 2.0, 2.0])
        center, radius = np.array([1.0, 2.0, 2.0]), 6.0
    elif case == "square":  # coplanar: the diagonal is a diameter
        pts = np.array([[0.0, 0, 5], [2, 0, 5], [0, 2, 5], [2, 2, 5], [1, 1, 5]])
        center, radius = np.array([1.0, 1.0, 5.0]), np.sqrt(2.0)
    else:
        pts, center, radius = np.array([[4.0, -1.0, 0.5]]), np.array([4.0, -1.0, 0.5]), 0.0
    c, r = minimal_bounding_sphere(pts)
    # 1e-12: a few rounding steps on coordinates of size <= 6 (a 2-4-point
    # circumscribed centre by one small linear solve); abs for the zero radii
    np.testing.assert_allclose(c, center, atol=1e-12)
    assert r == pytest.approx(radius, rel=POINTS_RTOL, abs=1e-12)
    assert np.all(np.linalg.norm(pts - c, axis=1) <= r)


def test_pair_bound_batched_is_minimal():
    rng = np.random.default_rng(3)
    c1, c2 = rng.normal(size=(2, 50, 3))
    r1, r2 = rng.uniform(0, 2, size=(2, 50))
    c, r = sphere_pair_bound(c1, r1, c2, r2)
    for i in range(50):
        _, r_exact = brute_force_enclosing(np.stack([c1[i], c2[i]]), np.array([r1[i], r2[i]]))
        assert r[i] == pytest.approx(r_exact, rel=1e-12)
    for cc, rr in ((c1, r1), (c2, r2)):
        assert np.all(np.linalg.norm(cc - c, axis=1) + rr <= r * (1 + 1e-14) + 1e-14)


def test_box_sphere_bounds_the_points_about_their_box_centre():
    """The box centre of the points and the farthest point's distance, by hand for a
    right triangle (box centre (0.5, 0.5, 0), every vertex sqrt(0.5) from it)."""
    from shtools.geometry.bounding import box_sphere

    center, radius = box_sphere([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(center, [0.5, 0.5, 0.0])
    assert radius == pytest.approx(np.sqrt(0.5), rel=1e-15)


def test_overlapping_groups_join_chains_and_keep_the_order():
    """Spheres join through others (a chain 0-2-1 is one group although 0 and 1 are
    apart), touching without overlap does not join, and groups come in first-index
    order."""
    from shtools.geometry.bounding import overlapping_groups

    spheres = [(np.array([0.0, 0, 0]), 1.0), (np.array([3.0, 0, 0]), 1.0),
               (np.array([1.5, 0, 0]), 1.0), (np.array([10.0, 0, 0]), 1.0),
               (np.array([12.0, 0, 0]), 1.0)]  # the last two touch at x = 11
    assert overlapping_groups(spheres) == [[0, 1, 2], [3], [4]]
    assert overlapping_groups([]) == []
