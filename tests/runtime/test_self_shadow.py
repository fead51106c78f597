"""Self-shadowing rules of SHEXP Sec. 6.2 / Figure 5, case by case, and their continuity."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.runtime import CapLogTable, accumulate_log, apply_self_shadow_rules
from shtools.sh.tables import default_tables

UP = np.array([0.0, 1.0, 0.0])


def rules(center, radius, p=(0.0, 0.0, 0.0), normal=UP):
    """Apply the rules to one sphere; returns (new centre in world space, new radius)."""
    p = np.asarray(p, dtype=float)
    d = np.asarray(center, dtype=float) - p
    nx, ny, nz = normal
    dx, dy, dz, r = apply_self_shadow_rules(d[0], d[1], d[2], np.float64(radius), nx, ny, nz)
    return p + np.array([dx, dy, dz], dtype=float), float(r)


def test_sphere_behind_plane_is_removed():
    _, r = rules((0.3, -1.0, 0.2), 0.5)
    assert r == 0.0


def test_sphere_in_front_is_unaltered():
    c, r = rules((0.3, 1.0, 0.2), 0.5)
    np.testing.assert_allclose(c, (0.3, 1.0, 0.2))
    assert r == 0.5


def test_containing_sphere_with_centre_behind_is_removed():
    _, r = rules((0.1, -0.2, 0.0), 0.5)  # |P - p| < r, centre below the plane
    assert r == 0.0


def test_containing_sphere_with_centre_in_front_is_shrunk_to_tangency():
    c, r = rules((0.1, 0.2, 0.0), 0.5)
    np.testing.assert_allclose(c, (0.1, 0.2, 0.0))  # same centre
    assert r == pytest.approx(0.2)  # radius = height of the centre: tangent to the plane


@pytest.mark.parametrize("h", [-0.3, 0.0, 0.25])
def test_straddling_sphere_far_away_becomes_tangent_diameter_sphere(h):
    # p outside S, D >= 2d so alpha = 1: S' has diameter q0 q1
    r0 = 0.5
    center = np.array([3.0, h, 0.0])
    c, r = rules(center, r0)
    q0 = center + r0 * UP  # farthest point of S in front of the plane
    q1 = q0 - (q0 @ UP) * UP  # its projection onto the plane
    np.testing.assert_allclose(c, 0.5 * (q0 + q1), atol=1e-12)
    assert r == pytest.approx(0.5 * np.linalg.norm(q0 - q1))


def test_straddling_sphere_near_boundary_is_blended_and_tangent():
    # D between d and 2d: radius between the inside rule's and S''s, tangent at q1
    r0, h = 0.5, 0.3
    d = np.sqrt(r0**2 - h**2)  # radius of S ∩ T_p = 0.4
    c, r = rules((1.5 * d, h, 0.0), r0)  # alpha = 0.5
    expected = 0.5 * h + 0.5 * 0.5 * (h + r0)
    assert r == pytest.approx(expected)
    assert c[1] == pytest.approx(r)  # centre height = radius: tangent to the plane
    np.testing.assert_allclose(c[[0, 2]], (1.5 * d, 0.0))


def test_every_kept_sphere_is_in_front_of_the_tangent_plane():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(5000, 3))
    r = rng.uniform(0.01, 2.0, 5000)
    nrm = rng.normal(size=(5000, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    dx, dy, dz, rr = apply_self_shadow_rules(d[:, 0], d[:, 1], d[:, 2], r,
                                             nrm[:, 0], nrm[:, 1], nrm[:, 2])
    h = dx * nrm[:, 0] + dy * nrm[:, 1] + dz * nrm[:, 2]
    kept = rr > 0
    assert np.all(h[kept] >= rr[kept] - 1e-12)  # no kept sphere crosses T_p
    dist = np.sqrt(dx**2 + dy**2 + dz**2)
    assert np.all(dist[kept] >= rr[kept] - 1e-12)  # p is never inside a kept sphere


def _log_along_path(center, radius, xs, table):
    pts = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])
    nrm = np.tile(UP, (len(xs), 1))
    return accumulate_log(pts, nrm, np.asarray([center], float), np.asarray([radius], float),
                          table).astype(np.float64)


@pytest.mark.parametrize("height", [-0.3, -0.05, 0.05, 0.3])
def test_log_vector_is_continuous_as_p_crosses_the_sphere_boundary(height):
    """Walking p along the plane across S's boundary, the log vector has no jump.

    The boundary is at x = d = sqrt(r^2 - h^2).  A jump would show as a step at
    least as large as the vector's own variation; we require the step across the
    boundary to be no larger than 3x the largest step elsewhere on the path
    (steps are 1e-4, the vector varies smoothly).  Without the alpha blend (the
    replacement sphere S' used right up to the boundary) the step is ~100x larger.
    """
    table = CapLogTable(default_tables(4), 4)
    r0 = 0.5
    d = np.sqrt(r0**2 - height**2)
    step = 1e-4
    xs = d + step * (np.arange(-200, 201) + 0.5)
    f = _log_along_path((0.0, height, 0.0), r0, xs, table)
    jumps = np.linalg.norm(np.diff(f, axis=0), axis=1)
    at_boundary = jumps[199]
    elsewhere = np.delete(jumps, 199).max()
    assert at_boundary <= 3.0 * elsewhere + 1e-6


def test_unblended_replacement_would_jump():
    """Sanity check that the continuity test can fail: S' at alpha = 1 vs inside rule."""
    table = CapLogTable(default_tables(4), 4)
    r0, h = 0.5, 0.3
    d = np.sqrt(r0**2 - h**2)
    inside = _log_along_path((0.0, h, 0.0), r0, np.array([d - 1e-6]), table)
    # the sphere S' with diameter q0 q1 seen from just outside the boundary
    s_prime = _log_along_path((0.0, 0.5 * (h + r0), 0.0), 0.5 * (h + r0),
                              np.array([d + 1e-6]), table)
    blended = _log_along_path((0.0, h, 0.0), r0, np.array([d + 1e-6]), table)
    assert np.linalg.norm(s_prime - inside) > 50 * np.linalg.norm(blended - inside)


@pytest.mark.parametrize("radius", [0.5])
def test_continuity_across_the_plane_through_the_centre(radius):
    """p inside S while the centre crosses the tangent plane (h: - to +): no jump."""
    table = CapLogTable(default_tables(4), 4)
    hs = 1e-4 * (np.arange(-100, 101) + 0.5)
    pts = np.zeros((len(hs), 3))
    nrm = np.tile(UP, (len(hs), 1))
    f = np.stack([accumulate_log(pts[:1], nrm[:1], [[0.1, h, 0.0]], [radius], table)[0]
                  for h in hs]).astype(np.float64)
    jumps = np.linalg.norm(np.diff(f, axis=0), axis=1)
    assert jumps[99] <= 3.0 * np.delete(jumps, 99).max() + 1e-6


def test_in_place_block_rules_match_the_reference_rules():
    """The runtime's whole-block float32 path against the float64 reference function."""
    from shtools.runtime.self_shadow import apply_self_shadow_rules_inplace

    rng = np.random.default_rng(8)
    shape = (7, 9, 11)
    d = rng.normal(size=(*shape, 3))
    r = rng.uniform(0.05, 1.5, shape)
    nrm = rng.normal(size=(shape[0], shape[1], 1, 3))
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    want = apply_self_shadow_rules(d[..., 0], d[..., 1], d[..., 2], r,
                                   nrm[..., 0], nrm[..., 1], nrm[..., 2])
    f32 = [np.ascontiguousarray(a, dtype=np.float32) for a in (d[..., 0], d[..., 1], d[..., 2], r)]
    n32 = nrm.astype(np.float32)
    h = f32[0] * n32[..., 0] + f32[1] * n32[..., 1] + f32[2] * n32[..., 2]
    scratch = [np.empty(shape, np.float32) for _ in range(5)]
    masks = [np.empty(shape, bool) for _ in range(2)]
    count = apply_self_shadow_rules_inplace(*f32, h, n32[..., 0], n32[..., 1], n32[..., 2],
                                            scratch, masks)
    assert count == int((np.abs((d * nrm).sum(-1)) < r).sum())
    for got, exp_ in zip(f32, want, strict=True):
        np.testing.assert_allclose(got, exp_, atol=2e-5)  # float32 arithmetic
