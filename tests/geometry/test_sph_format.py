"""The spheretree .sph text format: round trip, real-tool layout, bad files."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.errors import InputError
from shtools.geometry.sph_format import read_sph, write_sph
from shtools.geometry.sphere_set import SphereSet


def test_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    spheres = SphereSet(rng.normal(size=(13, 3)), rng.uniform(0.01, 1.0, 13))
    path = tmp_path / "s.sph"
    write_sph(path, spheres)
    back = read_sph(path)
    np.testing.assert_array_equal(back.centers, spheres.centers)
    np.testing.assert_array_equal(back.radii, spheres.radii)
    # the root written at level 0 bounds every sphere
    root = read_sph(path, level=0)
    reach = np.linalg.norm(spheres.centers - root.centers[0], axis=1) + spheres.radii
    assert np.all(reach <= root.radii[0] * (1 + 1e-12))


def test_reads_spheretree_layout_with_unused_nodes(tmp_path):
    # 3 levels, branching 2: 1 + 2 + 4 nodes; spheretree marks unused nodes r <= 0
    text = """3 2
0 0 0 2 0.5
-1 0 0 1 0.1
1 0 0 1 0.1
-1.5 0 0 0.5 0.01
-0.5 0 0 0.5 0.01
0 0 0 -1 0
1.0 0.25 0 0.75 0.02
"""
    path = tmp_path / "tree.sph"
    path.write_text(text)
    leaves = read_sph(path)
    assert leaves.info["level"] == 2
    np.testing.assert_array_equal(leaves.radii, [0.5, 0.5, 0.75])
    np.testing.assert_array_equal(leaves.centers[2], [1.0, 0.25, 0.0])
    assert len(read_sph(path, level=1)) == 2


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "header"),
        ("two levels\n", "two integers"),
        ("2 4\n0 0 0 1 0\n0 0 0 1 0\n", "truncated"),
        ("1 1\n0 0 zero 1 0\n", "numbers"),
        ("1 1\n0 0 0 -1 0\n", "positive radius"),
    ],
)
def test_bad_files(tmp_path, text, fragment):
    path = tmp_path / "bad.sph"
    path.write_text(text)
    with pytest.raises(InputError, match=fragment):
        read_sph(path)
