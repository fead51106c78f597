"""The look measures (smoothness ratio, shadowed-vertex and near-blocker errors) against
hand computations on tiny meshes."""

from __future__ import annotations

import math

import numpy as np

from shtools.reference.look import (
    graph_laplacian,
    laplacian_energy,
    look_metrics,
    luminance,
    near_blockers,
    shadowed,
    smoothness_ratio,
)

#: a unit square split along its diagonal 0-2: vertex 0 and 2 have three neighbours,
#: 1 and 3 two
SQUARE = np.array([[0, 1, 2], [0, 2, 3]])


def _grid_faces(n: int) -> np.ndarray:
    """Faces of an n x n vertex grid, every cell split along the same diagonal."""
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                           np.stack([a, c, d], -1).reshape(-1, 3)])


def test_laplacian_of_a_spike_on_the_square():
    # x = (1, 0, 0, 0): vertex 0 minus the mean of {1, 2, 3} = 1; vertex 1: 0 - mean{0, 2}
    # = -1/2; vertex 2: 0 - mean{0, 1, 3} = -1/3; vertex 3: 0 - mean{0, 2} = -1/2
    lap = graph_laplacian([1.0, 0.0, 0.0, 0.0], SQUARE)
    np.testing.assert_allclose(lap, [1.0, -0.5, -1.0 / 3.0, -0.5], rtol=0, atol=1e-15)
    np.testing.assert_allclose(laplacian_energy(np.array([1.0, 0, 0, 0]), SQUARE),
                               (1 + 0.5 + 1 / 3 + 0.5) / 4, rtol=1e-15)


def test_linear_field_is_smooth_inside_a_regular_grid():
    # each interior vertex of the grid has six neighbours in point-symmetric pairs, so the
    # mean of a linear function over them is its value: zero Laplacian inside
    n = 6
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    x = (2.0 * i + 3.0 * j).ravel()
    lap = graph_laplacian(x, _grid_faces(n)).reshape(n, n)
    np.testing.assert_allclose(lap[1:-1, 1:-1], 0.0, atol=1e-12)
    assert np.abs(lap[0]).max() > 0.1  # the border is not symmetric: the measure sees it


def test_smoothness_ratio_of_added_checkerboard_noise():
    # reference: linear ramp (zero Laplacian inside); bake: ramp + eps (-1)^(i+j).  An
    # interior vertex's six neighbours on this diagonal split: four of the other colour,
    # two (the diagonal pair) of its own, so L = eps (1 - (2 - 4)/6) ... = 4/3 eps in size
    n = 8
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    faces = _grid_faces(n)
    ramp = (i + j).ravel().astype(float)
    eps = 0.01
    noisy = ramp + eps * ((-1.0) ** (i + j)).ravel()
    lap = graph_laplacian(noisy, faces).reshape(n, n)
    np.testing.assert_allclose(np.abs(lap[1:-1, 1:-1]), 4.0 / 3.0 * eps, rtol=1e-9)
    assert smoothness_ratio(noisy, noisy, faces) == 1.0
    assert smoothness_ratio(noisy, ramp, faces) > 1.0


def test_luminance_weights_and_shadowed_threshold():
    rgb = np.array([[1.0, 1.0, 1.0], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(luminance(rgb), [1.0, 0.2126], rtol=1e-12)
    ref = np.array([[0.99, 0.99, 0.99], [0.97, 0.97, 0.97], [0.5, 0.5, 0.5]])
    free = np.ones((3, 3))
    np.testing.assert_array_equal(shadowed(ref, free), [False, True, True])


def test_look_metrics_by_hand():
    # four vertices of the square, one shadowed (ref 0.5 of unshadowed 1) and near the
    # blocker; the bake is 10 % off on the shadowed vertex only
    ref = np.array([[0.5] * 3, [1.0] * 3, [1.0] * 3, [1.0] * 3])
    bake = ref.copy()
    bake[0] *= 1.1
    points = np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]])
    out = look_metrics(bake, ref, np.ones((4, 3)), SQUARE, points=points,
                       blocker_spheres=[(np.array([0.0, 0.5, 0.0]), 0.3)])
    assert out["shadowed_vertices"] == 1 and out["near_vertices"] == 1
    np.testing.assert_allclose(out["shadowed_error"], 0.1, rtol=1e-12)
    np.testing.assert_allclose(out["near_error"], 0.1, rtol=1e-12)
    # whole: |0.05|^2 * 3 over 3 (0.25 + 1 + 1 + 1)
    np.testing.assert_allclose(out["error"], math.sqrt(0.0025 / 3.25), rtol=1e-12)
    # Laplacians by hand (luminance = the grey value): ref (0.5, 1, 1, 1) gives
    # (0.5 - 1, 1 - 0.75, 1 - 5/6, 1 - 0.75); the bake's first value is 0.55
    lap_ref = np.abs([-0.5, 0.25, 1 / 6, 0.25]).mean()
    lap_bake = np.abs([0.55 - 1, 1 - 0.775, 1 - 2.55 / 3, 1 - 0.775]).mean()
    np.testing.assert_allclose(out["smoothness"], lap_bake / lap_ref, rtol=1e-12)


def test_near_blockers_is_a_ball_per_blocker():
    pts = np.array([[0.0, 0, 0], [2.1, 0, 0], [5.0, 0, 0]])
    near = near_blockers(pts, [(np.zeros(3), 1.0), (np.array([5.0, 0, 0]), 0.1)])
    np.testing.assert_array_equal(near, [True, False, True])


def test_eval_reports_the_look_per_receiver(run_cli, tmp_path):
    """``shtools eval --json`` carries the first method's look measures for the ground:
    the ground grid's own faces (its Laplacian is finite and positive under a shadow),
    the vertices the capsule darkens, and those within 2 bounding radii of it."""
    import json

    from shtools.data_formats.spheres import write_spheres
    from shtools.geometry.sphere_set import SphereSet
    from shtools.reference.scenes import capsule_scene

    sc = capsule_scene(grid=8)
    sc.meshes[0].export(tmp_path / "capsule.obj")
    write_spheres(tmp_path / "s.h5", SphereSet(centers=sc.centers[:-1], radii=sc.radii[:-1],
                                               outside_volume_ratio=0.1, coverage=1.0,
                                               method="import", info={}))
    code, out, err = run_cli("eval", "--mesh", tmp_path / "capsule.obj", "--spheres",
                             tmp_path / "s.h5", "--grid", 16, "--n-dirs", 400, "--methods",
                             "auto", "--json")
    assert code == 0, err
    (look,) = json.loads(out)["look"]
    assert look["receiver"] == "ground"
    assert 0.0 < look["smoothness"] < 10.0
    assert 0 < look["shadowed_vertices"] < 16 * 16 and 0 < look["near_vertices"] <= 16 * 16
    # over the shadowed vertices the error is not diluted by the unshadowed ones
    assert look["shadowed_error"] >= 0.5 * look["error"]
