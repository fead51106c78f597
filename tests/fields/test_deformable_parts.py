"""Deformable fields evaluated per part of a frame: ``field_space = "product"`` (their
visibility multiplied in after the exp) and the runtime's worker processes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.fields.deformable import sample_deformable_field
from shtools.reference import raytrace_visibility, relative_rmse
from shtools.reference.scenes import ground_grid, sky_light
from shtools.runtime import SelfVisibility, ShadowRuntime, ShadowSettings, SphereBlocker, evaluator
from shtools.runtime.deformable import DeformableBlocker
from shtools.runtime.scaling import ScalingTable
from shtools.sh import product
from shtools.sh.scaling import build_scaling_table

ACC = 6


@pytest.fixture(scope="module")
def torus_and_ball(standing_torus):
    """A torus standing on its rim over a 16 x 16 ground, a sphere beside it, its field."""
    torus = standing_torus
    ground, gnorm = ground_grid(16, [0.0, 0.0], 4.0, y=0.0)
    field = sample_deformable_field(torus.vertices, torus.faces, ACC)
    blocker = DeformableBlocker(field, ScalingTable(build_scaling_table(ACC, "cone")))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.35)
    ball.apply_translation([1.6, 0.6, 0.4])
    spheres = SphereBlocker([[1.6, 0.6, 0.4]], [0.35])
    return torus, ball, blocker, spheres, ground, gnorm


def _runtime(space: str, processes: int = 1) -> ShadowRuntime:
    return ShadowRuntime(ShadowSettings(order=4, acc_order=ACC, processes=processes,
                                        field_space=space))


def test_product_space_multiplies_the_scaled_visibility(torus_and_ball):
    torus, ball, blocker, spheres, pts, nrm = torus_and_ball
    rt = _runtime("product")
    got = rt.visibility(pts, nrm, [spheres, blocker])
    # independent composition: the sphere's visibility (its own exp) times the field's
    # scaled visibility with shtools.sh.product's triple tensor at the accumulation order
    alone = _runtime("log").visibility(pts, nrm, [spheres]).astype(np.float64)
    base = np.zeros((len(pts), ACC * ACC))
    base[:, :16] = alone
    want = product(base, blocker.visibility(pts, nrm, ACC), ACC)[:, :16]
    np.testing.assert_allclose(got, want, atol=2e-5)  # float32 result of float64 products
    # against ray tracing of the real meshes (another method altogether): the ground
    env = sky_light(4)
    ref = rt.shade(raytrace_visibility(pts, nrm, [torus, ball], 4, 3000), pts, nrm, env)
    err_product = relative_rmse(rt.shade(got, pts, nrm, env), ref)
    err_log = relative_rmse(rt.shade(_runtime("log").visibility(pts, nrm, [spheres, blocker]),
                                     pts, nrm, env), ref)
    # measured 2.2 % (product) and 2.8 % (log): the cone model and the lookup between
    # samples; the log space loses a little more to the log/exp of dark samples
    assert err_product < 0.05
    assert err_log < 0.06
    # without the field the torus' shadow is missing (measured 15.7 %)
    missing = relative_rmse(rt.shade(alone, pts, nrm, env), ref)
    assert missing > 3 * err_product


@pytest.mark.parametrize("space", ["log", "product"])
def test_parts_on_worker_processes_give_the_same_bytes(torus_and_ball, monkeypatch, space):
    torus, _, blocker, spheres, ground, gnorm = torus_and_ball
    pts = np.concatenate([ground, torus.vertices])
    nrm = np.concatenate([gnorm, torus.vertex_normals])
    n_g = len(ground)
    own = np.zeros((len(torus.vertices), 16))
    own[:, 0] = math.sqrt(4 * math.pi)  # an unoccluded self-visibility: skips the field
    sv = [SelfVisibility(None, slice(n_g, None), blocker=1, visibility=own)]
    whole = _runtime(space).visibility(pts, nrm, [spheres, blocker], self_visibility=sv)
    # any frame is split into parts now (the same parts for any process count)
    monkeypatch.setattr(evaluator, "MIN_PARALLEL_PAIRS", 1)
    one = _runtime(space).visibility(pts, nrm, [spheres, blocker], self_visibility=sv)
    with _runtime(space, processes=2) as rt:
        two = rt.visibility(pts, nrm, [spheres, blocker], self_visibility=sv)
        assert rt.last_stats["processes"] == 2
    np.testing.assert_array_equal(two, one)
    # the parts' rows assembled in another order than the whole frame's: float32 sums
    np.testing.assert_allclose(one, whole, rtol=0, atol=2e-5)
    # the torus' rows skip its field: only the sphere there
    alone = _runtime(space).visibility(pts, nrm, [spheres])
    np.testing.assert_allclose(one[n_g:], alone[n_g:], rtol=0, atol=2e-5)
