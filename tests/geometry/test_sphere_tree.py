"""Sphere hierarchies: invariants, minimal parents, branching, determinism, CLI."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from shtools.data_formats.tree import read_tree
from shtools.geometry.sphere_tree import build_tree, check_tree, tree_statistics

#: a child counts as inside its parent up to this fraction of the parent radius
#: (the parent radius is recomputed from its centre, so only rounding remains)
CONTAIN_RTOL = 1e-12


def random_spheres(n, seed):
    rng = np.random.default_rng(seed)
    # clumpy: a few blobs, like sphere sets of limbs
    blobs = rng.normal(size=(max(2, n // 20), 3)) * 3
    centers = blobs[rng.integers(len(blobs), size=n)] + rng.normal(size=(n, 3)) * 0.6
    return centers, rng.uniform(0.05, 0.5, size=n)


@pytest.mark.parametrize("n", [1, 2, 7, 64, 200])
def test_invariants(n):
    centers, radii = random_spheres(n, n)
    tree = build_tree(centers, radii, branching=4, seed=1)
    m = len(tree)
    assert np.count_nonzero(tree.parent == -1) == 1 and tree.parent[-1] == -1
    # leaves are the set, in order
    np.testing.assert_array_equal(tree.leaf[:n], np.arange(n))
    assert np.all(tree.leaf[n:] == -1)
    np.testing.assert_array_equal(tree.centers[:n], centers)
    np.testing.assert_array_equal(tree.radii[:n], radii)
    assert np.all(tree.parent[: m - 1] > np.arange(m - 1))  # children before parents
    # every child inside its parent, hence every leaf inside all its ancestors
    assert check_tree(tree) <= CONTAIN_RTOL
    for leaf in range(n):
        node = tree.parent[leaf]
        while node >= 0:
            gap = np.linalg.norm(centers[leaf] - tree.centers[node]) + radii[leaf]
            assert gap <= tree.radii[node] * (1 + 1e-9)
            node = tree.parent[node]


@pytest.mark.parametrize("n", [64, 128, 250])
def test_branching_is_about_four(n):
    centers, radii = random_spheres(n, 7)
    stats = tree_statistics(build_tree(centers, radii, branching=4))
    # levels of ceil(n/4) clusters: n = 250 -> 63, 16, 4, 1 gives 333/84 = 3.96
    assert 3.5 <= stats["average_branching"] <= 4.0 + 1e-12
    assert stats["levels"] == int(np.ceil(np.log(n) / np.log(4))) + 1


def test_parents_are_minimal_bounds_of_child_spheres():
    centers, radii = random_spheres(80, 3)
    tree = build_tree(centers, radii)
    for node in range(80, len(tree)):
        kids = np.flatnonzero(tree.parent == node)
        kc, kr = tree.centers[kids], tree.radii[kids]

        def reach(c, kc=kc, kr=kr):
            return np.max(np.linalg.norm(kc - c, axis=1) + kr)

        # independent optimum: Nelder–Mead on max reach from the centroid, restarted
        best = np.inf
        for start in (kc.mean(0), kc[np.argmax(kr)]):
            res = minimize(reach, start, method="Nelder-Mead",
                           options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 4000})
            res = minimize(reach, res.x, method="Nelder-Mead",
                           options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 4000})
            best = min(best, res.fun)
        # Nelder–Mead on a non-smooth max stalls slightly above the optimum, never below
        assert tree.radii[node] <= best * (1 + 1e-7)
        # and no sphere can be smaller than the bound of its farthest-apart pair
        pair = max((np.linalg.norm(kc[i] - kc[j]) + kr[i] + kr[j]) / 2
                   for i in range(len(kids)) for j in range(len(kids)))
        assert tree.radii[node] >= max(pair, kr.max()) * (1 - 1e-12)


def test_parent_bounds_spheres_not_centres():
    # a big and a small sphere: the bound of centres would miss the big sphere's far side
    centers = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    radii = np.array([2.0, 0.1])
    tree = build_tree(centers, radii)
    assert tree.radii[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(tree.centers[-1], [0, 0, 0], atol=1e-12)


def test_same_seed_same_tree():
    centers, radii = random_spheres(100, 11)
    a = build_tree(centers, radii, seed=4)
    b = build_tree(centers, radii, seed=4)
    for name in ("centers", "radii", "parent", "leaf"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_bad_arguments():
    with pytest.raises(ValueError):
        build_tree(np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(ValueError):
        build_tree(np.zeros((3, 3)), -np.ones(3))
    with pytest.raises(ValueError):
        build_tree(np.zeros((3, 3)), np.ones(3), branching=1)


def test_cli_tree(tmp_path, run_cli):
    from shtools.data_formats import write_asset

    centers, radii = random_spheres(40, 2)
    spheres = tmp_path / "spheres.h5"
    write_asset(spheres, "spheres", {"centers": centers, "radii": radii},
                attrs={"outside_volume_ratio": 0.0})
    out = tmp_path / "tree.h5"
    code, stdout, stderr = run_cli("spheres", "tree", spheres, "-o", out, "--json", "--seed", 3)
    assert code == 0, stderr
    tree = read_tree(out)
    assert check_tree(tree) <= CONTAIN_RTOL
    leaves = np.flatnonzero(tree.leaf >= 0)
    np.testing.assert_array_equal(tree.centers[leaves[np.argsort(tree.leaf[leaves])]], centers)
    assert '"average_branching"' in stdout
    # same input and seed: identical datasets
    out2 = tmp_path / "tree2.h5"
    assert run_cli("spheres", "tree", spheres, "-o", out2, "--seed", 3)[0] == 0
    tree2 = read_tree(out2)
    np.testing.assert_array_equal(tree.parent, tree2.parent)
    np.testing.assert_array_equal(tree.centers, tree2.centers)
    # bad input: one line, exit != 0, no output
    for bad in (tmp_path / "missing.h5", out):  # a tree is not a sphere set
        target = tmp_path / "never.h5"
        code, _, stderr = run_cli("spheres", "tree", bad, "-o", target)
        assert code != 0 and stderr.startswith("error:")
        assert len(stderr.strip().splitlines()) == 1 and not target.exists()
