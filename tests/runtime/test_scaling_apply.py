"""Runtime SH scaling: interpolation in k, D^T M D about any axis, mid-range lighting."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shtools.lighting import latlong_directions, project_latlong
from shtools.runtime.scaling import ScalingTable, midrange_lighting, rotation_to_z
from shtools.sh import basis, project, sphere_quadrature
from shtools.sh.scaling import angular_map, build_scaling_table, scaling_values


@pytest.fixture(scope="module")
def cone_table():
    return ScalingTable(build_scaling_table(4, "cone", samples=40))


@pytest.fixture(scope="module")
def mid_table():
    return ScalingTable(build_scaling_table(4, "midrange", samples=40))


def warped_projection(f, k, axis, function, order, energy=False, degree=300):
    """Brute force: project s -> f(s') Lambda/sin(theta) with s' the direction at angle
    phi_k(theta) from ``axis`` in the plane of (axis, s); no rotation matrices involved."""
    dirs, w = sphere_quadrature(degree)
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    cos_t = np.clip(dirs @ a, -1, 1)
    theta = np.arccos(cos_t)
    perp = dirs - cos_t[:, None] * a
    perp /= np.maximum(np.linalg.norm(perp, axis=1, keepdims=True), 1e-300)
    phi, dphi = angular_map(theta, [k], function)
    phi, dphi = phi[0], dphi[0]
    warped = np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * perp
    vals = basis(warped, order) @ f
    if energy:
        vals = vals * np.sin(phi) * dphi / np.maximum(np.sin(theta), 1e-300)
    return project(vals, dirs, w, order)


def test_interpolated_m_against_direct_at_midpoints(cone_table, mid_table):
    # recorded bound (spec 2.5, measured here at n = 4 with 40 samples): max entry
    # error 0.0082 for the cone over [1/8, 8] and 0.0016 for mid-range over [0, 0.95]
    for table, fn, bound in [(cone_table, "cone", 0.009), (mid_table, "midrange", 0.0018)]:
        k = table.k
        mid = np.sqrt(k[:-1] * k[1:]) if fn == "cone" else 0.5 * (k[:-1] + k[1:])
        err = np.abs(table.values_at(mid) - scaling_values(mid, 4, fn)).max()
        assert 1e-4 < err < bound  # > 1e-4: the midpoints are really between samples
        # at the samples themselves the interpolation is exact
        np.testing.assert_allclose(table.values_at(k), table.values, atol=1e-14)


def test_log_k_rule_is_honoured():
    t = build_scaling_table(3, "cone", samples=7, interpolation="linear-log-k")
    table = ScalingTable(t)
    k = np.sqrt(t["k"][2] * t["k"][3])  # geometric midpoint: log-k weights are 1/2, 1/2
    np.testing.assert_allclose(table.values_at([k])[0], 0.5 * (t["values"][2] + t["values"][3]),
                               atol=1e-14)


def test_out_of_range_policies(cone_table, mid_table):
    np.testing.assert_array_equal(cone_table.values_at([100.0, 1e-3]),
                                  cone_table.values[[-1, 0]])  # clamp
    with pytest.raises(ValueError, match="outside the scaling table"):
        mid_table.values_at([0.97])


@pytest.mark.parametrize("function,k", [("cone", 1.0), ("cone", 0.125), ("cone", 8.0),
                                        ("midrange", 0.95)])
def test_apply_about_arbitrary_axes_against_brute_force(cone_table, mid_table, function, k):
    table = cone_table if function == "cone" else mid_table
    assert np.any(np.abs(table.k - k) < 1e-12)  # a sampled k: no interpolation error
    rng = np.random.default_rng(3)
    f = rng.normal(size=(3, 16))
    axes = rng.normal(size=(3, 3))
    axes[2] = [0, 0, -1]  # the half-turn branch of rotation_to_z
    ours = table.apply(f, np.full(3, k), axes)
    for i in range(3):
        ref = warped_projection(f[i], k, axes[i], function, 4)
        # degree-300 quadrature of an analytic (non-polynomial, steep at k = 1/8) warped
        # function: ~1e-9
        np.testing.assert_allclose(ours[i], ref, atol=1e-7 * np.abs(f[i]).sum())


def test_axis_frame_passes_and_scale_against_closed_forms(cone_table):
    """The three passes the deformable lookup composes (to_axis_frame, scale,
    from_axis_frame), each against an independent result, in float64 and float32."""
    rng = np.random.default_rng(5)
    axes = rng.normal(size=(4, 3))
    axes[3] = [0, 0, -1]  # the half-turn branch
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    ls = np.floor(np.sqrt(np.arange(16))).astype(int)
    # a function zonal about each axis, 1 in every band: by the addition theorem its
    # coefficients are sqrt(4 pi / (2l + 1)) Y_lm(axis); in the axis' frame it is 1 on
    # every m = 0 coefficient (index l*l + l) and 0 elsewhere, whatever the frame's azimuth
    zonal = basis(axes, 4) * np.sqrt(4.0 * math.pi / (2 * ls + 1))
    want = np.zeros((4, 16))
    want[:, ls * ls + ls] = 1.0
    np.testing.assert_allclose(cone_table.to_axis_frame(zonal, axes), want, atol=1e-12)
    # from_axis_frame is its inverse (SH rotations are orthogonal) for any vectors
    f = rng.normal(size=(4, 16))
    back = cone_table.from_axis_frame(cone_table.to_axis_frame(f, axes), axes)
    np.testing.assert_allclose(back, f, atol=1e-12)
    # scale is the warp about +z (brute force, no rotation); sampled k: exact M(k)
    k = cone_table.k[[0, 13, 26, 39]]
    got = cone_table.scale(f, k)
    for i in range(4):
        ref = warped_projection(f[i], k[i], [0, 0, 1], "cone", 4)
        # degree-300 quadrature, as in the arbitrary-axes test above
        np.testing.assert_allclose(got[i], ref, atol=1e-7 * np.abs(f[i]).sum())
    # float32 rows stay float32 (the runtime's log sum); float32 rounding of order-4
    # rotations and of M(k): ~1e-6 relative
    f32 = f.astype(np.float32)
    for out, ref in ((cone_table.to_axis_frame(f32, axes), cone_table.to_axis_frame(f, axes)),
                     (cone_table.from_axis_frame(f32, axes), cone_table.from_axis_frame(f, axes)),
                     (cone_table.scale(f32, k), got)):
        assert out.dtype == np.float32
        np.testing.assert_allclose(out, ref, atol=1e-5 * np.abs(f).max())


def test_apply_shared_rgb_matches_per_channel(mid_table):
    rng = np.random.default_rng(4)
    env = rng.normal(size=(16, 3))
    axes = rng.normal(size=(5, 3))
    k = rng.uniform(0, 0.9, 5)
    rgb = mid_table.apply(env, k, axes, shared=True)
    for c in range(3):
        one = mid_table.apply(np.broadcast_to(env[:, c], (5, 16)), k, axes)
        np.testing.assert_allclose(rgb[:, :, c], one, atol=1e-13)
    with pytest.raises(ValueError, match="order 4"):
        mid_table.apply(np.zeros((5, 9)), k, axes)


def test_rotation_to_z():
    rng = np.random.default_rng(5)
    a = rng.normal(size=(50, 3))
    a = np.vstack([a / np.linalg.norm(a, axis=1, keepdims=True), [[0, 0, -1], [0, 0, 1]]])
    r = rotation_to_z(a)
    np.testing.assert_allclose(np.einsum("vij,vj->vi", r, a), np.tile([0, 0, 1.0], (52, 1)),
                               atol=1e-13)  # round-off of a 3x3 product
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-14)


# -- mid-range environment lighting against ray-sphere tracing --------------------


def procedural_probe(height=96):
    """A small HDR lat-long probe: sky gradient, a bright sun, a coloured patch."""
    d = latlong_directions(height, 2 * height)
    sun = np.array([0.5, 0.7, -0.5]) / np.linalg.norm([0.5, 0.7, -0.5])
    patch = np.array([-0.8, 0.1, 0.6]) / np.linalg.norm([-0.8, 0.1, 0.6])
    sky = 0.5 + 0.4 * d[..., 1:2]
    img = sky * np.array([0.6, 0.8, 1.0])
    img = img + 8.0 * np.exp(6.0 * (d @ sun - 1))[..., None] * np.array([1.0, 0.9, 0.7])
    img = img + 2.0 * np.exp(3.0 * (d @ patch - 1))[..., None] * np.array([0.2, 1.0, 0.3])
    return img


def lookup(img, dirs):
    """Nearest pixel of a lat-long image in direction ``dirs`` (docs/conventions.md)."""
    h, w = img.shape[:2]
    theta = np.arccos(np.clip(dirs[:, 1], -1, 1))
    phi = np.mod(np.arctan2(-dirs[:, 0], dirs[:, 2]), 2 * math.pi)
    i = np.minimum((theta / math.pi * h).astype(int), h - 1)
    j = np.minimum((phi / (2 * math.pi) * w).astype(int), w - 1)
    return img[i, j]


def traced_radiance_sh(img, point, center, radius, order, degree=160):
    """SH of the radiance seen from ``point``: each ray is intersected with the
    environment sphere and looks the probe up in the hit point's direction."""
    dirs, w = sphere_quadrature(degree)
    p = np.asarray(point, float) - center
    b = dirs @ p
    t = -b + np.sqrt(b * b - (p @ p - radius**2))
    hit = (p + t[:, None] * dirs) / radius
    return project(lookup(img, hit).T, dirs, w, order).T  # (n^2, 3)


@pytest.fixture(scope="module")
def mid_table8():
    return ScalingTable(build_scaling_table(8, "midrange", samples=40))


@pytest.mark.parametrize("k", [0.25, 0.5, 0.75, 0.9])
def test_midrange_lighting_against_ray_sphere_tracing(mid_table, mid_table8, k):
    img = procedural_probe()
    center, radius = np.array([1.0, 2.0, -0.5]), 3.0
    u = np.array([0.3, -0.4, 0.85])
    point = center + k * radius * u / np.linalg.norm(u)
    truth = traced_radiance_sh(img, point, center, radius, 4)
    scale = np.linalg.norm(truth)
    # scaled at order 8, truncated to 4: what is left is the table's interpolation,
    # the probe's bands >= 8 and the traced rule's pixel sampling -- measured
    # 0.04 / 0.09 / 0.34 / 0.43 % at k = 0.25 / 0.5 / 0.75 / 0.9
    ours = midrange_lighting(project_latlong(img, 8), point[None], center, radius,
                             mid_table8, out_order=4)[0]
    assert np.linalg.norm(ours - truth) / scale < {0.25: 0.002, 0.5: 0.003, 0.75: 0.005,
                                                   0.9: 0.008}[k]
    # scaled at the shading order the probe's bands 4..7 are missing from the warp
    # (measured 8 / 13 / 15 / 19 %), still far better than assuming a distant
    # environment (26 / 55 / 90 / 114 %)
    env4 = project_latlong(img, 4)
    at4 = np.linalg.norm(midrange_lighting(env4, point[None], center, radius, mid_table)[0]
                         - truth) / scale
    distant = np.linalg.norm(env4 - truth) / scale
    assert at4 < 0.22 and at4 < distant / 3


def test_midrange_refuses_receivers_outside(mid_table):
    env = np.zeros((16, 3))
    with pytest.raises(ValueError, match="outside the sphere"):
        midrange_lighting(env, [[0, 0, 0], [0, 4.0, 0]], [0, 0, 0], 3.0, mid_table)
    with pytest.raises(ValueError, match="outside the scaling table"):
        midrange_lighting(env, [[0, 2.97, 0]], [0, 0, 0], 3.0, mid_table)
    cone = ScalingTable(build_scaling_table(4, "cone", samples=5))
    with pytest.raises(ValueError, match="'midrange' scaling table"):
        midrange_lighting(env, [[0, 0, 0]], [0, 0, 0], 3.0, cone)


def test_shading_with_a_per_vertex_environment():
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.runtime.shading import band_window, cosine_transfer
    from shtools.sh import triple

    rng = np.random.default_rng(6)
    nrm = rng.normal(size=(7, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pts = rng.normal(size=(7, 3))
    g = rng.normal(size=(7, 16)) * 0.3
    g[:, 0] += 3.0
    env = rng.normal(size=(7, 16, 3))
    env[:, 0] += 5.0
    with ShadowRuntime(ShadowSettings(order=4, processes=1)) as rt:
        ours = rt.shade(g, pts, nrm, env)
        # identical rows: the shared-light path
        shared = rt.shade(g, pts, nrm, np.broadcast_to(env[0], (7, 16, 3)))
        np.testing.assert_allclose(shared, rt.shade(g, pts, nrm, env[0]), rtol=1e-5)
    # independent: the exact triple product (H(N), w L_v, w g), float32 inputs -> 1e-5
    win = band_window(4, "cosine", None)
    h = cosine_transfer(nrm, 4).astype(np.float64)
    for v in range(7):
        for c in range(3):
            ref = triple(h[v], env[v, :, c] * win, g[v] * win)
            assert ours[v, c] == pytest.approx(ref, rel=1e-4, abs=1e-5)


@pytest.mark.parametrize("order", [1, 2, 4, 6])
def test_factored_apply_equals_dense_operator(order):
    # apply() factors the rotation (z-rotations and a fixed quarter-turn); operator()
    # builds D^T M D from rotation_matrix's quadrature: two independent routes
    table = ScalingTable(build_scaling_table(order, "cone", samples=9))
    rng = np.random.default_rng(order)
    axes = rng.normal(size=(40, 3))
    axes[:4] = [[0, 0, 1], [0, 0, -1], [1e-9, 0, 1], [0, 1, 0]]
    k = np.exp(rng.uniform(-2, 2, 40))
    f = rng.normal(size=(40, order * order))
    dense = np.einsum("vij,vj->vi", table.operator(k, axes), f)
    np.testing.assert_allclose(table.apply(f, k, axes), dense, atol=1e-12 * order**2)
