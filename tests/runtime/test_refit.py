"""Runtime tree refit and skinned sphere posing (numpy only)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from shtools.geometry.sphere_tree import build_tree, check_tree
from shtools.runtime.spheres import plan_refit, refit_tree, sphere_pair_bound

#: children inside parents up to rounding of the radius recomputation
CONTAIN_RTOL = 1e-12


def _tree(n=120, seed=0):
    rng = np.random.default_rng(seed)
    centers = rng.normal(size=(n, 3)) * 2
    radii = rng.uniform(0.05, 0.4, size=n)
    return centers, radii, build_tree(centers, radii, seed=seed)


def _excess(parent, centers, radii):
    child = np.flatnonzero(parent >= 0)
    p = parent[child]
    gap = np.linalg.norm(centers[child] - centers[p], axis=1) + radii[child] - radii[p]
    return float(np.max(gap / radii[p]))


def test_refit_of_unmoved_leaves_bounds_and_stays_near_optimal():
    centers, radii, tree = _tree()
    c, r = refit_tree(tree.parent, tree.leaf, centers, radii)
    np.testing.assert_array_equal(c[: len(radii)], centers)
    assert _excess(tree.parent, c, r) <= CONTAIN_RTOL
    inner = tree.leaf < 0
    # the built tree's parents are optimal for their children, so refit radii can't be
    # smaller at the first level; upper levels see refit children, compare totals
    level1 = np.unique(tree.parent[: len(radii)])
    assert np.all(r[level1] >= tree.radii[level1] * (1 - 1e-9))
    assert np.mean(r[inner] / tree.radii[inner]) < 1.1


@pytest.mark.parametrize("seed", range(4))
def test_refit_after_leaves_move_keeps_invariants(seed):
    centers, radii, tree = _tree(seed=seed)
    rng = np.random.default_rng(100 + seed)
    moved = centers + rng.normal(size=centers.shape) * 0.8
    grown = radii * rng.uniform(0.5, 2.0, size=radii.shape)
    c, r = refit_tree(tree.parent, tree.leaf, moved, grown)
    assert _excess(tree.parent, c, r) <= CONTAIN_RTOL
    # every leaf inside every ancestor
    for leaf in range(len(radii)):
        node = tree.parent[leaf]
        while node >= 0:
            assert np.linalg.norm(moved[leaf] - c[node]) + grown[leaf] <= r[node] * (1 + 1e-12)
            node = tree.parent[node]


def test_two_children_get_the_exact_pair_bound():
    rng = np.random.default_rng(9)
    parent = np.array([4, 4, 5, 5, 6, 6, -1])
    leaf = np.array([0, 1, 2, 3, -1, -1, -1])
    lc = rng.normal(size=(4, 3))
    lr = rng.uniform(0.1, 1.0, size=4)
    c, r = refit_tree(parent, leaf, lc, lr)
    for node, (a, b) in ((4, (0, 1)), (5, (2, 3))):
        # closed form: r = (d + r_a + r_b) / 2 unless one contains the other
        d = np.linalg.norm(lc[a] - lc[b])
        want = max((d + lr[a] + lr[b]) / 2, lr[a], lr[b])
        assert r[node] == pytest.approx(want, rel=1e-14)
    _, pr = sphere_pair_bound(c[4], r[4], c[5], r[5])
    assert r[6] == pytest.approx(float(pr), rel=1e-14)


def test_refit_is_rigid_equivariant():
    centers, radii, tree = _tree(80, 3)
    rot = Rotation.random(random_state=1).as_matrix()
    shift = np.array([3.0, -1.0, 2.0])
    c0, r0 = refit_tree(tree.parent, tree.leaf, centers, radii)
    c1, r1 = refit_tree(tree.parent, tree.leaf, centers @ rot.T + shift, radii)
    np.testing.assert_allclose(r1, r0, rtol=1e-9)
    np.testing.assert_allclose(c1, c0 @ rot.T + shift, atol=1e-9)


def test_general_trees_with_uneven_depth():
    # leaves at different depths, node order not bottom-up
    parent = np.array([-1, 0, 0, 1, 1, 2, 2, 6, 6])
    leaf = np.array([-1, -1, -1, 0, 1, 2, -1, 3, 4])
    rng = np.random.default_rng(4)
    lc, lr = rng.normal(size=(5, 3)), rng.uniform(0.1, 0.5, size=5)
    c, r = refit_tree(parent, leaf, lc, lr)
    assert _excess(parent, c, r) <= CONTAIN_RTOL
    np.testing.assert_array_equal(c[[3, 4, 5, 7, 8]], lc)
    with pytest.raises(ValueError):
        plan_refit(np.array([-1, 0]), np.array([-1, -1]))  # inner node without children


def test_refit_of_built_tree_matches_tree_check():
    centers, radii, tree = _tree(64, 5)
    c, r = refit_tree(tree.parent, tree.leaf, centers, radii)
    tree.centers, tree.radii = c, r
    assert check_tree(tree) <= CONTAIN_RTOL


def test_runtime_module_imports_no_geometry_stack():
    code = ("import sys, shtools.runtime.spheres; "
            "bad = [m for m in ('trimesh', 'igl', 'pymeshlab', 'shtools.geometry', "
            "'scipy.optimize', 'scipy.spatial') if m in sys.modules]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"
