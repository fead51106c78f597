"""Deformable shadow fields: sampling on the bounding sphere, lookup, scaling to radii."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from helpers.rig import write_bending_tube

from shtools.fields.deformable import bounding_sphere, hemisphere_rule, sample_deformable_field
from shtools.geometry.raycast import RayCaster
from shtools.geometry.skin import load_skinned_gltf
from shtools.runtime.deformable import (
    deformable_visibility,
    interpolate_samples,
    layout_directions,
)
from shtools.runtime.scaling import ScalingTable
from shtools.sh import cap, exp, project, sphere_quadrature
from shtools.sh.scaling import build_scaling_table

ORDER = 4


@pytest.fixture(scope="module")
def cone_table():
    return ScalingTable(build_scaling_table(ORDER, "cone"))


@pytest.fixture(scope="module")
def posed_tube(tmp_path_factory):
    """The test rig bent by 90 degrees (t = 1 s): a posed skinned mesh (~550 triangles)."""
    path = tmp_path_factory.mktemp("rig") / "rig.glb"
    write_bending_tube(path, 90.0)
    model = load_skinned_gltf(path)
    return model.skin(model.joint_matrices(1.0)), model.faces


def traced(vertices, faces, points, order, degree=40):
    """Ray-traced binary visibility of the mesh at points, projected to SH."""
    dirs, w = sphere_quadrature(degree)
    vis = RayCaster(vertices, faces).visibility(points, dirs).astype(float)
    return project(vis, dirs, w, order)


def test_hemisphere_rule():
    rule = hemisphere_rule(8, 16)
    assert np.all(rule.directions[:, 2] > 0)
    assert rule.weights.sum() == pytest.approx(2 * math.pi, rel=1e-14)
    # exact for low-degree polynomials over the hemisphere: int z = pi, int z^3 = pi/2
    assert rule.weights @ rule.directions[:, 2] == pytest.approx(math.pi, rel=1e-13)
    assert rule.weights @ rule.directions[:, 2] ** 3 == pytest.approx(math.pi / 2, rel=1e-13)


def test_sampled_sphere_is_a_cap():
    # a sphere blocker: from a point at distance r it occludes a cap of half-angle
    # asin(rho / r) about the direction to the centre (closed form, shtools.sh.cap)
    ball = trimesh.creation.icosphere(4, radius=0.5)
    field = sample_deformable_field(ball.vertices, ball.faces, ORDER, layout=(6, 8),
                                    rays=(24, 48), log=False)
    assert np.linalg.norm(field.center) < 1e-3 and field.radius == pytest.approx(0.5, rel=2e-3)
    w = layout_directions(6, 8)
    want = cap(math.asin(0.5 / field.radius), -w[0], ORDER)
    for s in range(len(w)):
        want = cap(math.asin(0.5 / field.radius), -w[s], ORDER)
        # binary occlusion on a 24 x 48 hemisphere rule and a faceted sphere: 1 %
        np.testing.assert_allclose(field.visibility[s], want, atol=0.01 * math.sqrt(4 * math.pi))


def test_outward_hemisphere_is_unoccluded(posed_tube):
    # the sampled vector equals a full-sphere ray trace at the sample points (which
    # also casts the outward hemisphere): nothing is lost by casting half the rays
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER, layout=(4, 6), rays=(32, 64),
                                    log=False)
    points = field.center + field.radius * layout_directions(4, 6)
    ref = traced(verts, faces, points, ORDER, degree=90)
    # two different rules for a binary function: 2 % of the constant
    np.testing.assert_allclose(field.visibility, ref, atol=0.02 * math.sqrt(4 * math.pi))


def test_interpolation_reproduces_samples_and_is_continuous_at_the_poles():
    rng = np.random.default_rng(0)
    samples = rng.normal(size=(5 * 7, 3))
    w = layout_directions(5, 7)
    np.testing.assert_allclose(interpolate_samples(samples, (5, 7), w), samples, atol=1e-12)
    eps = 1e-7
    near_pole = np.array([[eps, 0, 1], [-eps, eps, 1], [0, -eps, 1.0]])
    near_pole /= np.linalg.norm(near_pole, axis=1, keepdims=True)
    vals = interpolate_samples(samples, (5, 7), near_pole)
    np.testing.assert_allclose(vals, np.tile(samples[:7].mean(axis=0), (3, 1)), atol=1e-5)


def test_lookup_at_the_samples_scales_each_sample_about_its_axis(posed_tube, cone_table):
    # the lookup interpolates in the samples' axis frames; at a sample's own direction
    # it is the scaling of that sample about its axis, D^T M(k) D S (apply, tested
    # against a brute-force projection of the warped function)
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER, layout=(6, 8), rays=(8, 16))
    w = layout_directions(6, 8)
    for k in (0.4, 1.0, 2.5):
        got = deformable_visibility(field, cone_table, field.center + k * field.radius * w)
        want = cone_table.apply(field.visibility, np.full(len(w), k), -w)
        # the lookup runs in float32 (as the runtime's log sum): ~1e-6 of sqrt(4 pi)
        np.testing.assert_allclose(got, want, atol=2e-5)


def test_lookup_is_continuous_across_the_poles(posed_tube, cone_table):
    # near a pole every azimuth gives the same world-frame vector: the nearest ring's
    # mean scaled about the pole axis
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER, layout=(6, 8), rays=(8, 16))
    eps = 1e-7
    for sign, ring in ((1.0, slice(0, 8)), (-1.0, slice(40, 48))):
        d = np.array([[eps, 0, sign], [-eps, eps, sign], [0, -eps, sign], [eps, eps, sign]])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        got = deformable_visibility(field, cone_table, field.center + 1.7 * field.radius * d,
                                    log=True)
        mean = field.log_visibility[ring].mean(axis=0)
        want = cone_table.apply(mean[None], [1.7], [[0.0, 0.0, -sign]])[0]
        np.testing.assert_allclose(got, np.tile(want, (4, 1)), atol=1e-5)


#: Relative error of the scaled field (alpha = 45 deg, order 4) against ray tracing of
#: the posed tube: mean ||S_d - V_true|| / mean ||1 - V_true|| over receivers at k r.
RADII = (0.5, 0.7, 0.9, 1.0, 1.3, 2.0)
#: measured 0.62 / 0.40 / 0.19 / (0.075) / 0.34 / 0.81 (unscaled: 0.78 / 0.57 / 0.26 / -
#: / 0.65 / 2.5; no blocker: 1.0); bounds are the measurements plus 15-30 %.  Below 1 at
#: 2r means better than ignoring the blocker.
BOUNDS = {0.5: 0.75, 0.7: 0.5, 0.9: 0.25, 1.3: 0.4, 2.0: 0.95}


@pytest.mark.parametrize("k", RADII)
def test_scaled_field_against_ray_traced_posed_mesh(posed_tube, cone_table, k):
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER, log=False)
    rng = np.random.default_rng(int(k * 10))
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    points = field.center + k * field.radius * u
    points = points[~trimesh.Trimesh(verts, faces).contains(points)]
    truth = traced(verts, faces, points, ORDER)
    occlusion = np.linalg.norm(truth - cap(0.0, [0, 0, 1], ORDER), axis=1).mean()
    ours = deformable_visibility(field, cone_table, points)
    err = np.linalg.norm(ours - truth, axis=1).mean() / occlusion
    identity = ScalingTable(build_scaling_table(ORDER, "cone", samples=3))
    identity.values[:] = identity.values[1]  # M = I at every k: the unscaled sample
    unscaled = np.linalg.norm(deformable_visibility(field, identity, points) - truth,
                              axis=1).mean() / occlusion
    if k == 1.0:
        # only the interpolation between samples and the two rules differ
        assert err < 0.1
    else:
        # the cone model is an approximation (seed: "slight discrepancies"; a thin
        # bent tube is a hard case for it); it must beat the bounding-sphere sample
        # unscaled and stay within the measured BOUNDS
        assert err < unscaled
        assert err < BOUNDS[k]


def test_log_space_field_exponentiates_to_the_product_space_field(posed_tube, cone_table):
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER)
    points = field.center + np.array([[0.0, 0.0, 1.5], [1.2, 0.3, 0.0], [0.0, -1.1, 0.4]]) \
        * field.radius
    vis = deformable_visibility(field, cone_table, points)
    via_log = exp(deformable_visibility(field, cone_table, points, log=True), "exact")
    # scaling commutes with the pointwise log only up to truncation: measured < 6 % of
    # the constant at order 4 (bench_scaling reports it in full)
    np.testing.assert_allclose(via_log, vis, atol=0.06 * math.sqrt(4 * math.pi))
    # at the samples themselves (k = 1) the log round-trips (eigen log, exact exp) up to
    # the eigen log's floor on near-zero eigenvalues (measured 8e-5)
    samples = field.center + field.radius * layout_directions(*field.layout)[:5]
    np.testing.assert_allclose(
        exp(deformable_visibility(field, cone_table, samples, log=True), "exact"),
        field.visibility[:5], atol=1e-3)


def test_far_receivers_are_culled(posed_tube, cone_table):
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER)
    far = field.center + np.array([[0.0, 9.0 * field.radius, 0.0]])
    np.testing.assert_array_equal(deformable_visibility(field, cone_table, far, log=True), 0)
    one = cap(0.0, [0, 0, 1], ORDER)  # unoccluded
    np.testing.assert_allclose(deformable_visibility(field, cone_table, far)[0], one,
                               atol=1e-15)


def test_bad_inputs(posed_tube, cone_table):
    verts, faces = posed_tube
    field = sample_deformable_field(verts, faces, ORDER, layout=(4, 6), log=False)
    with pytest.raises(ValueError, match="without its log"):
        deformable_visibility(field, cone_table, [[3.0, 0, 0]], log=True)
    with pytest.raises(ValueError, match="order"):
        deformable_visibility(field, ScalingTable(build_scaling_table(3, "cone", samples=5)),
                              [[3.0, 0, 0]])
    with pytest.raises(ValueError, match="'cone'"):
        deformable_visibility(field, ScalingTable(build_scaling_table(ORDER, "midrange",
                                                                      samples=5)), [[3.0, 0, 0]])
    c, r = bounding_sphere(verts)
    assert np.all(np.linalg.norm(verts - c, axis=1) <= r)
