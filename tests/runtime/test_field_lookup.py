"""Shadow-field lookup and combination (runtime) against ray tracing and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.data_formats.field import ShadowField
from shtools.errors import InputError
from shtools.fields import FieldParameters, l1_error, quantize, sample_field
from shtools.fields.sampling import grid_directions
from shtools.reference import raytrace_visibility
from shtools.runtime import FieldBlocker, ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.fields import FieldTable
from shtools.sh import exp as sh_exp
from shtools.sh import rotate

SQRT_4PI = math.sqrt(4 * math.pi)


def random_rotation(seed):
    q = np.random.default_rng(seed).normal(size=4)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.fixture(scope="module")
def box():
    return trimesh.creation.box(extents=(1.0, 0.6, 0.4))


@pytest.fixture(scope="module")
def box_field(box):
    fld, _ = sample_field(box, FieldParameters(shells=8, resolution=16, map_size=24, order=4,
                                               min_resolution=4))
    return fld


def synthetic_field(order=3, res=(8, 4, 16), seed=0):
    """A field with random float grids; returns it and the float grids."""
    rng = np.random.default_rng(seed)
    K = order * order
    grids = [rng.normal(size=(r, r, K)) for r in res]
    qs = [quantize(g) for g in grids]
    logs = [quantize(0.1 * g) for g in grids]
    fld = ShadowField(
        center=np.array([0.1, -0.2, 0.3]), bounding_radius=1.0,
        shell_radii=0.2 * (1 + np.arange(len(res))) + 1.0, resolution=np.array(res),
        ocv=[q[0] for q in qs], offset=np.stack([q[1] for q in qs]),
        step=np.stack([q[2] for q in qs]), log_ocv=[q[0] for q in logs],
        log_offset=np.stack([q[1] for q in logs]), log_step=np.stack([q[2] for q in logs]),
        order=order)
    return fld, grids, np.stack([q[2] for q in qs])


def test_lookup_at_sample_positions_returns_the_sample_within_half_a_step():
    fld, grids, steps = synthetic_field()
    table = FieldTable(fld)
    for c, g in enumerate(grids):
        R = g.shape[0]
        pts = fld.center + fld.shell_radii[c] * grid_directions(R).reshape(-1, 3)
        got = table.lookup(pts)
        # quantization (step/2) plus float32 arithmetic on values of size ~3
        assert np.all(np.abs(got - g.reshape(-1, g.shape[2])) <= steps[c] / 2 + 2e-6)


def test_lookup_is_continuous_across_phi_zero_and_shell_boundaries():
    fld, _, _ = synthetic_field()
    table = FieldTable(fld)
    eps = 1e-7
    for theta in (0.3, 1.2, 2.9):
        r = 1.3  # between shells 1 and 2
        a = [r * math.sin(theta) * math.cos(-eps), r * math.sin(theta) * math.sin(-eps),
             r * math.cos(theta)]
        b = [r * math.sin(theta) * math.cos(eps), r * math.sin(theta) * math.sin(eps),
             r * math.cos(theta)]
        va, vb = table.lookup(fld.center + np.array([a, b]))
        assert np.abs(va - vb).max() < 1e-4  # two points 2e-7 rad apart
    d = np.array([0.48, -0.6, 0.64])
    for r in [*list(fld.shell_radii), fld.shell_radii[-1] + 0.2]:  # shells, fade end
        va, vb = table.lookup(fld.center + np.array([(r - 1e-9) * d, (r + 1e-9) * d]))
        assert np.abs(va - vb).max() < 1e-4
    far = table.lookup(fld.center + np.array([(fld.shell_radii[-1] + 0.2) * d,
                                              (fld.shell_radii[-1] + 5) * d]))
    one = np.zeros(9)
    one[0] = SQRT_4PI
    assert np.allclose(far, one, atol=1e-6)  # exactly unoccluded past the fade
    inner = table.lookup(fld.center + np.array([0.01 * d, 0.9 * d, fld.shell_radii[0] * d]))
    assert np.allclose(inner[0], inner[2], atol=1e-6) and np.allclose(inner[1], inner[2],
                                                                       atol=1e-6)


def test_rotating_object_and_receiver_together_keeps_world_visibility(box_field):
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(50, 3)) * 1.5
    R = random_rotation(1)
    t = np.array([0.3, -1.0, 2.0])
    still = FieldBlocker(box_field).world_vectors(pts)
    moved = FieldBlocker(box_field, R, t).world_vectors(pts @ R.T + t)
    # the world visibility of the moved pair is the still one rotated by R
    assert np.allclose(moved, rotate(still.astype(np.float64), R), atol=2e-5)  # float32


def full_sphere_raytrace(points, meshes, n_dirs=8000):
    """Visibility over the whole sphere from the reference (which counts directions below
    the tangent plane as visible): V = V_up(n) + V_up(-n) - 1."""
    rng = np.random.default_rng(0)
    n = rng.normal(size=points.shape)
    n /= np.linalg.norm(n, axis=1)[:, None]
    up = raytrace_visibility(points, n, meshes, 4, n_dirs=n_dirs)
    down = raytrace_visibility(points, -n, meshes, 4, n_dirs=n_dirs)
    up[:, 0] -= SQRT_4PI
    return up + down


def between_shells(fld, count, seed, lo=1.0, hi=1.5):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    r = rng.uniform(lo, hi, count) * fld.bounding_radius
    return fld.center + d * r[:, None]


def test_lookup_between_samples_matches_ray_tracing_of_the_mesh(box, box_field):
    pts = between_shells(box_field, 200, 1)
    got = FieldBlocker(box_field).world_vectors(pts)
    err = l1_error(got, full_sphere_raytrace(pts, [box]))
    # R = 16 bilinear interpolation, the 24 x 24 map's quadrature and 8-bit steps, at
    # 1.0-1.5 V_r (close to the box, where the field varies fastest): measured max 0.10,
    # mean 0.015 (eq. 1 units; an unoccluded sky is 1); 0.045 / 0.011 at 1.2-1.5 V_r
    assert err.max() < 0.15 and err.mean() < 0.025


def test_log_and_product_space_against_each_other_and_ray_tracing(box, box_field):
    R = random_rotation(7)
    t = np.array([1.1, 0.0, 0.0])
    other = box.copy()
    other.apply_transform(np.block([[R, t[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))
    blockers = [FieldBlocker(box_field), FieldBlocker(box_field, R, t)]
    pts = np.array([[0.55, 0.9, 0.1], [0.5, -0.8, 0.3], [0.6, 0.2, -0.9], [0.4, 0.1, 0.95]])
    pts = np.concatenate([pts, pts * 1.2 + 0.05])
    # +x normals: both boxes are partly above every tangent plane, so neither is culled
    nrm = np.tile([1.0, 0.0, 0.0], (len(pts), 1))
    ref = full_sphere_raytrace(pts, [box, other])
    out = {}
    for space in ("log", "product"):
        with ShadowRuntime(ShadowSettings(order=4, field_space=space, processes=1)) as rt:
            out[space] = rt.visibility(pts, nrm, blockers)
    e_log = l1_error(out["log"], ref)
    e_prod = l1_error(out["product"], ref)
    # two overlapping occluders: each field's interpolation error (~0.05) plus the
    # order-4 truncation of the product / log-exp of two OCVs
    assert e_log.max() < 0.12 and e_prod.max() < 0.12
    assert l1_error(out["log"], out["product"]).max() < 0.08


def test_log_space_mixes_with_sphere_blockers(box_field):
    pts = np.array([[0.0, -1.5, 0.0], [0.3, -1.2, 0.2]])
    nrm = np.tile([0.0, 1.0, 0.0], (2, 1))
    sphere = SphereBlocker([[0.0, -0.9, 1.2]], [0.3])
    with ShadowRuntime(ShadowSettings(order=4, processes=1, hierarchy=False)) as rt:
        both = rt.log_visibility(pts, nrm, [FieldBlocker(box_field), sphere])
        only_s = rt.log_visibility(pts, nrm, [sphere])
        only_f = rt.log_visibility(pts, nrm, [FieldBlocker(box_field)])
        g = rt.visibility(pts, nrm, [sphere, FieldBlocker(box_field)])
        g_exp = rt.exponentiate(both)
    assert np.allclose(both, only_s + only_f, atol=1e-5)  # logs add
    assert np.allclose(g, g_exp, atol=1e-5)


def test_non_uniform_scale_and_order_mismatch_are_refused(box_field):
    with pytest.raises(InputError, match="uniform scale"):
        FieldBlocker.from_matrix(box_field, np.diag([1.0, 2.0, 1.0, 1.0]))
    shear = np.eye(4)
    shear[0, 1] = 0.5
    with pytest.raises(InputError):
        FieldBlocker.from_matrix(box_field, shear)
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    with pytest.raises(InputError, match="mirror"):
        FieldBlocker.from_matrix(box_field, mirror)
    scaled = FieldBlocker.from_matrix(box_field, np.diag([2.0, 2.0, 2.0, 1.0]))
    assert scaled.scale == pytest.approx(2.0)
    with ShadowRuntime(ShadowSettings(order=3, processes=1)) as rt, \
            pytest.raises(InputError, match="order"):
        rt.visibility(np.zeros((1, 3)) + 2, np.array([[0.0, 1.0, 0.0]]),
                      [FieldBlocker(box_field)])


def test_uniform_scale_matches_a_field_of_the_scaled_mesh(box, box_field):
    scaled_mesh = box.copy()
    scaled_mesh.apply_scale(2.0)
    pts = between_shells(box_field, 60, 3) * 2.0
    got = FieldBlocker(box_field, scale=2.0).world_vectors(pts)
    err = l1_error(got, full_sphere_raytrace(pts, [scaled_mesh]))
    assert err.max() < 0.15 and err.mean() < 0.025  # same budget as the unscaled test


def test_exp_of_interpolated_logs_is_as_accurate_as_interpolated_visibility(box, box_field):
    pts = between_shells(box_field, 150, 9)
    fb = FieldBlocker(box_field)
    ref = full_sphere_raytrace(pts, [box])
    e_vis = l1_error(fb.world_vectors(pts, "ocv"), ref)
    e_log = l1_error(sh_exp(fb.world_vectors(pts, "log").astype(np.float64), "ps*"), ref)
    # measured: mean 0.011 (visibility) vs 0.012 (logs); a geometric mean between
    # samples differs from the arithmetic one by second-order terms
    assert e_log.mean() < 1.5 * e_vis.mean() + 0.005


@pytest.mark.skipif(not __import__("shtools.runtime.parallel", fromlist=["x"]).workers_supported(),
                    reason="this platform cannot start workers, so the runtime runs in one process "
                    "(nothing to compare)")
@pytest.mark.parametrize("space", ["log", "product"])
def test_two_processes_give_the_one_process_result(box_field, space):
    rng = np.random.default_rng(4)
    v = rng.uniform(-3, 3, (60000, 3))  # 60k x 4 fields >= MIN_PARALLEL_PAIRS: split
    v[:, 1] = -0.5
    n = np.tile([0.0, 1.0, 0.0], (len(v), 1))
    blockers = [FieldBlocker(box_field, random_rotation(k), [k * 0.7 - 1, 0.2, 0.0],
                             skip_rows=np.arange(k * 100, k * 100 + 50)) for k in range(4)]
    out = {}
    for processes in (1, 2):
        with ShadowRuntime(ShadowSettings(order=4, processes=processes,
                                          field_space=space)) as rt:
            out[processes] = rt.visibility(v, n, blockers)
            used = rt.last_stats["processes"]
        assert used == processes
    assert np.allclose(out[1], out[2], atol=1e-5)  # float32 arithmetic, same rows
