"""A traced object's shadow on the ground (shtools.scene.traced_shadows): the shared
direction set against closed forms, the hand-over weights, the surface filter."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from helpers.skies import sun_sky

from shtools.geometry.raycast import RayCaster
from shtools.scene.receiver_filter import FILTER_NEIGHBOURS, neighbours, surface_filter
from shtools.scene.traced_shadows import (
    HANDOVER_RAYS,
    cone_rays,
    handover_weights,
    set_visibility,
    traced_ground,
    world_directions,
)


def _unit_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    v = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1)[:, None]
    return v, sphere.faces, RayCaster(v, sphere.faces)


def test_world_directions_are_an_equal_area_set():
    d = world_directions(512)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    # equal-area bands about +Y: the mean of y over the set is exactly 0, of y^2 is 1/3 up to
    # the midpoint rule's O(1/n^2)
    assert abs(d[:, 1].mean()) < 1e-12
    assert abs((d[:, 1] ** 2).mean() - 1.0 / 3.0) < 1e-5


def test_set_visibility_of_a_sphere_is_its_cap_in_closed_form():
    """From distance D the unit sphere blocks the cap of half-angle a = asin(1/D) about
    the direction to it: g_00 = (4 pi - 2 pi (1 - cos a)) / sqrt(4 pi) and, along the
    axis, the band-1 coefficient -sqrt(3 / 4 pi) * pi sin^2 a (the integral of
    cos over the cap)."""
    from shtools.geometry.visibility import bounding_cones

    _, _, caster = _unit_sphere()
    dist = np.array([1.5, 2.5, 4.0])
    pts = np.column_stack([np.zeros(3), np.zeros(3), -dist])
    nrm = np.tile([0.0, 0.0, 1.0], (3, 1))  # facing the sphere: the cap is above
    axis, cos_half = bounding_cones(pts, nrm, np.zeros(3), 1.0)
    g = set_visibility(pts, nrm, caster, axis, cos_half, 2, 4096)
    a = np.arcsin(1.0 / dist)
    g00 = (4 * math.pi - 2 * math.pi * (1 - np.cos(a))) / math.sqrt(4 * math.pi)
    # real SH y_1,0 = sqrt(3 / 4 pi) z (index 2 of order 2)
    g10 = -math.sqrt(3 / (4 * math.pi)) * math.pi * np.sin(a) ** 2
    # 8,192 directions of 1.5e-3 sr each: the cap's rim cuts ~ sqrt(k) of them
    np.testing.assert_allclose(g[:, 0], g00, rtol=0, atol=4e-3)
    np.testing.assert_allclose(g[:, 2], g10, rtol=0, atol=4e-3)


def test_handover_weights_and_the_receivers_traced():
    """The cone of the unit sphere from distance D holds n (1 - sqrt(1 - 1/D^2)) rays at
    hemisphere density n (closed form): weight 0 at or below HANDOVER_RAYS[0] rays (not
    traced: those receivers keep the blocker), 1 at or above HANDOVER_RAYS[1], a
    smoothstep between."""
    v, f, caster = _unit_sphere()
    d = np.array([1.2, 2.0, 2.6, 3.0, 3.4, 3.6, 6.0])
    pts = np.column_stack([np.zeros_like(d), np.zeros_like(d), -d])
    nrm = np.tile([0.0, 0.0, 1.0], (len(d), 1))
    rays = 96 * (1.0 - np.sqrt(1.0 - 1.0 / d ** 2))
    want = np.clip((rays - HANDOVER_RAYS[0]) / (HANDOVER_RAYS[1] - HANDOVER_RAYS[0]), 0, 1)
    want = want * want * (3 - 2 * want)
    rows, w, g = traced_ground(pts, nrm, v, f, caster, 3, 96)
    assert rows.tolist() == np.flatnonzero(want > 0).tolist() == [0, 1, 2, 3, 4, 5]
    np.testing.assert_allclose(w, want[rows], rtol=1e-12)
    assert w[0] == 1.0 and 0 < w[-1] < 1 and np.all(np.diff(w) <= 0) and g.shape == (6, 9)
    np.testing.assert_allclose(handover_weights([0.0, 100.0]), [0.0, 1.0])


def test_surface_filter_keeps_linear_fields_and_zero_widths():
    """A symmetric Gaussian average of a linear field on a regular grid is the field
    (inside, where every neighbour has its mirror image); a receiver of width 0 keeps
    its value; receivers facing away are no neighbours."""
    n = 15
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    pts = np.column_stack([i.ravel() * 0.1, np.zeros(n * n), j.ravel() * 0.1])
    nrm = np.tile([0.0, 1.0, 0.0], (n * n, 1))
    x = np.column_stack([1.0 + 2.0 * pts[:, 0] - pts[:, 2], pts[:, 0] * 0 + 3.0])
    idx, dist = neighbours(pts, nrm)
    assert idx.shape == (n * n, FILTER_NEIGHBOURS) and np.all(idx[:, 0] == np.arange(n * n))
    width = np.full(n * n, 0.1)
    width[0] = 0.0
    y = surface_filter(x, width, idx, dist)
    inside = (i.ravel() >= 3) & (i.ravel() < n - 3) & (j.ravel() >= 3) & (j.ravel() < n - 3)
    np.testing.assert_allclose(y[inside], x[inside], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(y[0], x[0])
    noisy = x + np.random.default_rng(0).normal(0, 0.1, x.shape)
    flipped = nrm.copy()
    flipped[::2] *= -1.0  # every other receiver faces away: only the others are averaged
    idx, dist = neighbours(pts, flipped)
    assert np.all((idx < 0) | (idx % 2 == np.arange(n * n)[:, None] % 2))
    y = surface_filter(noisy, np.full(n * n, 0.1), idx, dist)
    k = 7 * n + 8  # an inside receiver facing up (odd index)
    up = np.flatnonzero(flipped[:, 1] > 0)
    assert k in up
    d2 = ((pts[up] - pts[k]) ** 2).sum(axis=1)
    # the nearest FILTER_NEIGHBOURS of k hold every same-facing receiver within 2 widths
    near = d2 <= (2 * 0.1) ** 2 + 1e-12
    wts = np.exp(-0.5 * d2[near] / 0.01) - math.exp(-2.0)
    want = (wts[:, None] * noisy[up][near]).sum(axis=0) / wts.sum()
    np.testing.assert_allclose(y[k], want, rtol=1e-6)  # weights in float32


def test_runtime_splits_a_cluster_whose_rows_skip_different_blockers():
    """Only the receivers of weight above 0 skip the traced object's blocker, so one
    receiver cluster may hold rows that skip it and rows that do not: the runtime
    splits it, each row getting what it would alone."""
    from shtools.runtime import SelfVisibility, ShadowRuntime, ShadowSettings, SphereBlocker
    from shtools.runtime.clusters import ReceiverClusters

    pts = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0], [0.3, 0.0, 0.0]])
    nrm = np.tile([0.0, 1.0, 0.0], (4, 1))
    a = SphereBlocker(centers=np.array([[0.1, 1.0, 0.0]]), radii=np.array([0.5]))
    given = np.zeros((2, 16), dtype=np.float32)
    given[:, 0] = 3.0
    given[:, 2] = 0.5
    rt = ShadowRuntime(ShadowSettings(order=4, processes=1))
    one = ReceiverClusters.from_labels([0, 0, 0, 0])
    g = rt.visibility(pts, nrm, [a], clusters=one, self_visibility=[
        SelfVisibility(None, np.array([0, 1]), blocker=0, visibility=given)])
    plain = rt.visibility(pts, nrm, [a], clusters=one)
    # rows 0, 1 skip the sphere: the given visibility times exp(0) (float32 product)
    np.testing.assert_allclose(g[:2], given, rtol=0, atol=2e-6)
    np.testing.assert_allclose(g[2:], plain[2:], rtol=0, atol=1e-6)
    assert one.split([0, 0, 0, 0]) is one
    split = one.split([1, 1, 0, 0])
    assert split.n_clusters == 2 and split.labels[0] == split.labels[1] != split.labels[2]


def test_a_static_object_is_traced_once_and_a_moved_one_again(monkeypatch):
    """The same caster over the same receivers gives the kept result (no ray cast); any
    input that changes (the receivers, the mesh, a light) traces again, and the caller
    may change what it got without changing what is kept."""
    import shtools.scene.traced_shadows as ts

    v, f, caster = _unit_sphere()
    x = np.linspace(-3.0, 3.0, 25)
    X, Z = np.meshgrid(x, x)
    pts = np.column_stack([X.ravel(), np.full(X.size, -1.05), Z.ravel()])
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    first = traced_ground(pts, nrm, v, f, caster, 3, 96)
    assert first[0].size > 100 and (first[2][:, 0] < math.sqrt(4 * math.pi) - 0.1).any()
    first[2][:] = 0.0  # the caller's copy
    traced = []
    real = ts.set_visibility
    monkeypatch.setattr(ts, "set_visibility", lambda *a, **k: traced.append(1) or real(*a, **k))
    again = traced_ground(pts.copy(), nrm.copy(), v.copy(), f, caster, 3, 96)
    assert not traced
    fresh = traced_ground(pts, nrm, v, f, RayCaster(v, f), 3, 96)  # an independent trace
    # one trace: the shared set, and the denser set near the contact (the receivers are
    # sparser than the filter there)
    per_trace = len(traced)
    assert per_trace in (1, 2)
    for a, b in zip(again, fresh, strict=True):
        np.testing.assert_array_equal(a, b)
    moved = pts + np.array([0.0, -0.2, 0.0])
    lower = traced_ground(moved, nrm, v, f, caster, 3, 96)
    assert len(traced) > per_trace and not np.array_equal(lower[2][:, 0], fresh[2][:, 0])
    before = len(traced)
    traced_ground(moved, nrm, v, f, caster, 3, 96, lights=[((0.0, 5.0, 0.0), 0.1)])
    assert len(traced) > before


def test_receiver_spacing_of_a_grid_and_the_refine_weights():
    """On a regular grid of spacing h the fourth nearest neighbour is an edge neighbour
    at h (a coincident duplicate vertex does not count); the denser set's weight is 0
    where the filter is at least one spacing wide, 1 where at most half of it (or 0
    wide: a contact) and the smoothstep of spacing / width - 1 between."""
    from shtools.scene.receiver_filter import receiver_spacing
    from shtools.scene.traced_shadows import refine_weights

    h, n = 0.3, 9
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    pts = np.column_stack([i.ravel() * h, np.zeros(n * n), j.ravel() * h])
    pts = np.concatenate([pts, pts[40:41]])  # a duplicate of the middle vertex
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    idx, dist = neighbours(pts, nrm)
    s = receiver_spacing(idx, dist)
    inside = (i.ravel() > 0) & (i.ravel() < n - 1) & (j.ravel() > 0) & (j.ravel() < n - 1)
    np.testing.assert_allclose(s[:-1][inside], h, rtol=1e-12)
    assert s[40] == s[-1] == pytest.approx(h)
    width = np.array([2 * h, h, 0.75 * h, 0.5 * h, 0.1 * h, 0.0])
    t = np.clip(h / np.where(width > 0, width, 1e-300) - 1.0, 0.0, 1.0)
    want = t * t * (3 - 2 * t)
    np.testing.assert_allclose(refine_weights(width, np.full(6, h)), want, rtol=1e-12)
    assert refine_weights(width, np.full(6, h)).tolist()[:2] == [0.0, 0.0]
    assert refine_weights(width, np.full(6, h)).tolist()[3:] == [1.0, 1.0, 1.0]
    assert refine_weights([0.0], [np.inf]).tolist() == [0.0]  # no neighbour at all


def test_a_coarse_ground_near_its_object_is_traced_closer_to_the_closed_form():
    """A unit sphere over a coarse grid (spacing 0.5, so the filter finds no neighbour
    near the contact): from a receiver at distance D it blocks the cap of half-angle
    asin(1/D) about the direction to its centre, wholly above the receiver's tangent
    plane here, whose SH projection is closed form (``shtools.sh.cap``).  The denser
    set where the filter cannot average brings the traced visibility closer to it
    than the shared set alone."""
    import shtools.scene.traced_shadows as ts
    from shtools.sh import cap

    v, f, caster = _unit_sphere()
    x = np.arange(-1.0, 1.01, 0.5)
    X, Z = np.meshgrid(x, x)
    pts = np.column_stack([X.ravel(), np.full(X.size, -1.05), Z.ravel()])
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    dist = np.linalg.norm(pts, axis=1)
    axis = -pts / dist[:, None]
    # the cap lies above the tangent plane: the angle of its axis to the normal plus its
    # half-angle below 90 degrees (so the ray tracer's "below the plane is visible"
    # convention does not cut it)
    assert np.all(np.arccos(axis[:, 1]) + np.arcsin(1.0 / dist) < 0.5 * math.pi)
    want = cap(np.arcsin(1.0 / dist), axis, 3)

    def error(factor):
        ts._GROUND.clear()
        old = ts.REFINE_FACTOR
        ts.REFINE_FACTOR = factor
        try:
            rows, _, g = traced_ground(pts, nrm, v, f, caster, 3, 96)
        finally:
            ts.REFINE_FACTOR = old
            ts._GROUND.clear()
        assert rows.tolist() == list(range(len(pts)))
        return float(np.sqrt(np.mean((g - want) ** 2)))

    shared, refined = error(1), error(ts.REFINE_FACTOR)
    # each of the shared set's 192 directions is 4 pi / 192 = 0.065 sr, 0.018 in g_00
    # (times 1 / sqrt(4 pi)): a cap rim cutting a few of them leaves ~0.02-0.04;
    # REFINE_FACTOR (8) times the rays at least halve that (the rim's error falls as the
    # rays' angular spacing, 1 / sqrt(8), or faster where the steps cancel)
    assert refined < 0.6 * shared
    assert refined < 0.015


def test_a_far_shadow_is_smoothed_into_the_closed_form():
    """A unit sphere 2.05 above a dense grid (spacing 0.05): every receiver is 1-2.2 from
    its surface, where a silhouette crosses each of the shared set's directions once per
    0.25-0.55 of receiver motion (5-11 receiver spacings, wider than the nearest
    FILTER_NEIGHBOURS reach).  The filtered traced visibility follows the closed-form
    cap (``shtools.sh.cap``; wholly above every tangent plane here) with its steps
    smoothed away: the grid Laplacian of g_00 (4 neighbours, computed here) stays small
    against one direction's step."""
    from shtools.sh import cap

    v, f, caster = _unit_sphere()
    h = 0.05
    x = np.arange(-2.4, 2.4001, h)
    n = len(x)
    X, Z = np.meshgrid(x, x, indexing="ij")
    pts = np.column_stack([X.ravel(), np.full(X.size, -2.05), Z.ravel()])
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    dist = np.linalg.norm(pts, axis=1)
    axis = -pts / dist[:, None]
    assert np.all(np.arccos(axis[:, 1]) + np.arcsin(1.0 / dist) < 0.5 * math.pi)
    want = cap(np.arcsin(1.0 / dist), axis, 3)
    rows, _, g = traced_ground(pts, nrm, v, f, caster, 3, 96)
    assert rows.tolist() == list(range(len(pts)))

    def laplacian(a):
        a = a.reshape(n, n)
        return a[1:-1, 1:-1] - 0.25 * (a[2:, 1:-1] + a[:-2, 1:-1] + a[1:-1, 2:] + a[1:-1, :-2])

    step = 4.0 * math.pi / 192 / math.sqrt(4.0 * math.pi)  # one direction's weight in g_00
    rough = float(np.abs(laplacian(g[:, 0])).mean())
    # the cap itself is smooth (its mean |Laplacian| is 0.0012 of a step); the staircase
    # filtered in one pass over the nearest neighbours (cut short of its width here)
    # leaves 0.042 of a step, in FILTER_PASSES passes (the full width) 0.019: bound 0.03
    assert float(np.abs(laplacian(want[:, 0])).mean()) < 0.002 * step
    assert rough < 0.03 * step
    # and closer to the closed form (0.0101 in one pass, 0.0074 in three; each direction
    # is 0.018 in g_00)
    assert float(np.sqrt(np.mean((g - want) ** 2))) < 0.0085


def test_the_filter_distance_is_the_meshs_near_a_loose_bound_and_continuous(monkeypatch):
    """A thin rod in fat spheres: the spheres' distance is far short of the rod's next to
    it (the filter would be that much too narrow), so near the spheres mesh_distance is
    the exact distance to the triangles, far from them the spheres', and it is
    continuous in between; both checked against closed forms."""
    import igl

    from shtools.scene.receiver_filter import EXACT_REACH, mesh_distance

    rod = trimesh.creation.cylinder(radius=0.02, height=1.0, sections=16)
    centers = np.stack([np.zeros(6), np.zeros(6), np.linspace(-0.5, 0.5, 6)], axis=1)
    radii = np.full(6, 0.15)  # 7.5x the rod: a loose bound
    # points along x from the rod's side out past the blend, level with a sphere's centre
    # (z = 0.1): that sphere is the nearest, so the spheres' distance is x - 0.15
    x = np.linspace(0.03, (EXACT_REACH[1] + 1.0) * 0.15 + 0.15, 4001)
    pts = np.stack([x, np.zeros_like(x), np.full_like(x, 0.1)], axis=1)
    # a second rod far away: its triangles cannot hold a nearest point, and libigl is
    # not given them (its tree costs about 1 us a triangle)
    far = rod.copy()
    far.apply_translation([50.0, 0.0, 0.0])
    mesh = trimesh.util.concatenate([rod, far])
    given = []
    real = igl.point_mesh_squared_distance

    def spy(q, v, f):
        given.append(len(f))
        return real(q, v, f)

    monkeypatch.setattr(igl, "point_mesh_squared_distance", spy)
    d = mesh_distance(pts, mesh.vertices, mesh.faces, (centers, radii))
    assert given and given[0] <= len(rod.faces) < len(mesh.faces)
    spheres = np.maximum(x - 0.15, 0.0)
    # the rod's side is a 16-gon prism and every point is level with its middle: the
    # distance is the plane distance to the polygon's edges (point-segment)
    ring = rod.vertices[np.isclose(rod.vertices[:, 2], 0.5)][:, :2]
    ring = ring[np.argsort(np.arctan2(ring[:, 1], ring[:, 0]))]
    a, b = ring, np.roll(ring, -1, axis=0)
    rel = pts[:, None, :2] - a[None]
    t = np.clip(np.einsum("pek,ek->pe", rel, b - a) / np.einsum("ek,ek->e", b - a, b - a),
                0.0, 1.0)
    exact = np.linalg.norm(rel - t[..., None] * (b - a)[None], axis=2).min(axis=1)
    inside = spheres <= EXACT_REACH[0] * 0.15
    beyond = spheres >= EXACT_REACH[1] * 0.15
    band = ~inside & ~beyond
    assert inside.sum() > 100 and beyond.sum() > 100 and band.sum() > 100
    # next to the rod the spheres' distance is a fraction of the true one
    assert np.all(spheres[inside] < 0.8 * exact[inside])
    # 1e-9: float64 distances to the same facets (the 16-gon, not the circle); the
    # spheres' distance is computed in float32 (a filter width needs no more): 5e-7 is
    # a few of its rounding steps at distances up to 0.56 (6e-8 each)
    np.testing.assert_allclose(d[inside], exact[inside], rtol=0, atol=1e-9)
    np.testing.assert_allclose(d[beyond], spheres[beyond], rtol=0, atol=5e-7)
    # continuous: d = w e + (1 - w) s has slope at most 1 + max S' |e - s| / band width
    # (both distances 1-Lipschitz along x, S' <= 3/2; here 1.9); a hard switch steps by
    # |e - s| (slope 1300 at these steps), a blend over under 0.3 of the band exceeds it
    width = (EXACT_REACH[1] - EXACT_REACH[0]) * 0.15
    slope = 1.0 + 1.5 * float(np.max(np.abs(exact - spheres)[band])) / width
    steps = np.abs(np.diff(d)) / (x[1] - x[0])
    assert np.max(steps) <= slope * (1 + 1e-6)


def test_the_ground_filters_with_the_mesh_distance_and_objects_with_the_spheres(monkeypatch):
    """Which distance sets the filter's width: a ground's receivers (no strata) take
    mesh_distance (exact near a loose bound), object receivers in contact (strata) the
    spheres' alone, as traced_ground documents."""
    import shtools.scene.traced_shadows as ts

    v, f, caster = _unit_sphere()
    x = np.linspace(-1.5, 1.5, 13)
    X, Z = np.meshgrid(x, x)
    pts = np.column_stack([X.ravel(), np.full(X.size, -1.05), Z.ravel()])
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    spheres = (np.zeros((1, 3)), np.array([1.3]))  # loose: 1.3 about a unit sphere
    calls = []
    real_mesh, real_spheres = ts.mesh_distance, ts.sphere_distance
    monkeypatch.setattr(ts, "mesh_distance",
                        lambda *a: calls.append("mesh") or real_mesh(*a))
    monkeypatch.setattr(ts, "sphere_distance",
                        lambda *a: calls.append("spheres") or real_spheres(*a))
    for strata in (False, True):
        ts._GROUND.clear()
        traced_ground(pts, nrm, v, f, caster, 3, 96, spheres=spheres, strata=strata)
    ts._GROUND.clear()
    assert calls == ["mesh", "spheres"]


def test_sky_gain_is_one_under_a_uniform_sky_and_the_sun_over_the_mean_radiance():
    """Under a uniform sky nothing changes (gain 1).  A narrow cone pointing at a sun
    gains the sun's cosine-weighted radiance over the receiver's cosine-weighted mean
    radiance E / pi, here integrated by quadrature over the directions above the
    receiver (not with the clamped-cosine SH the code uses)."""
    from shtools.scene.traced_shadows import SKY_GAIN_MAX, sky_gain
    from shtools.sh import basis

    up = np.array([[0.0, 1.0, 0.0]])
    sun = np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0)), 0.0])
    flat = np.zeros(16)
    flat[0] = 1.0
    axes = np.array([sun, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert np.all(sky_gain(axes, np.repeat(up, 3, axis=0), np.full(3, 0.9), flat) == 1.0)
    lum = sun_sky(sun, 4, floor=0.05)
    d = world_directions(20000)
    mean = (4.0 / len(d)) * float(np.maximum(basis(d, 4) @ lum, 0.0) @ np.maximum(d[:, 1], 0))
    want = float((basis(sun[None], 4) @ lum)[0]) * sun[1] / mean
    got = sky_gain(sun[None], up, np.array([math.cos(1e-3)]), lum)
    # the order-4 reconstruction is clamped at 0 in the quadrature (it barely dips below):
    # a few 1e-3 relative between the two means
    assert 1.5 < float(got[0]) < SKY_GAIN_MAX  # the gain, not its clip, is compared
    np.testing.assert_allclose(got, want, rtol=1e-2)
    # a cone away from the sun (toward the dim floor) keeps the count
    assert sky_gain(np.array([[-sun[0], sun[1], 0.0]]), up, np.array([0.99]), lum) == 1.0


def test_sky_gain_moves_smoothly_as_the_cone_sweeps_past_the_sun():
    """A 15-degree cone swept from the horizon over a sun 60 degrees up (and around it
    in azimuth) changes its gain by small steps: no sample that jumps where the cone's
    frame would turn (a fixed helper axis jumped 14 % at |a_y| = 0.9)."""
    from shtools.scene.traced_shadows import sky_gain

    sun = np.array([math.cos(math.radians(60.0)), math.sin(math.radians(60.0)), 0.0])
    lum = sun_sky(sun, 4, floor=0.05)
    for azimuth in (0.0, 7.0, 30.0):
        elev = np.radians(np.linspace(0.0, 90.0, 3601))
        az = math.radians(azimuth)
        axes = np.column_stack([np.cos(elev) * math.cos(az), np.sin(elev),
                                np.cos(elev) * math.sin(az)])
        up = np.tile([0.0, 1.0, 0.0], (len(axes), 1))
        g = sky_gain(axes, up, np.full(len(axes), math.cos(math.radians(15.0))), lum)
        assert g.max() - g.min() > 0.5  # the sun does lengthen the count
        # 0.025 degree steps: the smooth gain moves by a few 1e-3 at most (its slope
        # peaks near 0.1 a degree); a jump of the sample point is a step of 0.1 or more
        assert np.abs(np.diff(g)).max() < 0.01, (azimuth, np.abs(np.diff(g)).max())


def test_a_sun_behind_the_object_keeps_its_long_shadow_traced():
    """Receivers on a ground beyond the hand-over (cones of at most HANDOVER_RAYS[0]
    rays: spheres only) see a unit sphere 45 degrees up, against a sun: their shadow is
    traced there, and it is the sphere's cap as a 4,096-ray trace finds it; a sun on
    the other side leaves them to the spheres, as does a uniform sky."""
    v, f, caster = _unit_sphere()
    d = np.array([5.2, 5.5, 6.0]) / math.sqrt(2.0)
    pts = np.column_stack([-d, -d, np.zeros(3)])
    nrm = np.tile([0.0, 1.0, 0.0], (3, 1))
    # beyond the hand-over under a uniform sky: the code's own cones, counts and weights
    assert np.all(handover_weights(cone_rays(_cones(pts, nrm)[1], 96)) == 0.0)
    toward = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)  # the sphere, from each receiver
    flat = np.zeros(16)
    flat[0] = 1.0
    for sky in (None, flat, sun_sky(toward * np.array([-1.0, 1.0, 1.0]), 4, floor=0.05)):
        rows, _, _ = traced_ground(pts, nrm, v, f, caster, 4, 96, sky=sky)
        assert rows.size == 0
    rows, w, g = traced_ground(pts, nrm, v, f, caster, 4, 96, sky=sun_sky(toward, 4, floor=0.05))
    assert rows.tolist() == [0, 1, 2] and np.all(w > 0)
    # the traced part is the sphere's cap: against a 4,096-ray trace, within two of the
    # shared set's directions (4 pi / 192 sr each, 0.018 in g_00; the cap is about one)
    want = set_visibility(pts, nrm, caster, *_cones(pts, nrm), 4, 4096)
    np.testing.assert_allclose(g[:, 0], want[:, 0], atol=0.04)


def _cones(pts, nrm):
    from shtools.geometry.visibility import bounding_cones

    return bounding_cones(pts, nrm, np.zeros(3), 1.0)
