"""Library stages behind the CLI write the same bytes as the commands (one code path)."""

from __future__ import annotations

import numpy as np
import trimesh

from shtools.cli._common import one_blas_thread
from shtools.data_formats.spheres import read_spheres
from shtools.data_formats.tree import read_tree
from shtools.geometry.assets import fit_to_file, tree_to_file


def test_fit_and_tree_stages_match_the_commands(tmp_path, run_cli):
    """The CLI runs with one BLAS thread unless the user set a count
    (``one_blas_thread``), and SLSQP's last bits depend on BLAS's thread count:
    the library stages run under the same limit here, as a pipeline calling
    them should to get the commands' bytes."""
    mesh = trimesh.creation.capsule(height=1.0, radius=0.3, count=[12, 12])
    mesh_path = tmp_path / "capsule.obj"
    mesh_path.write_text(mesh.export(file_type="obj"))
    lib, cli = tmp_path / "lib.h5", tmp_path / "cli.h5"
    with one_blas_thread():
        result = fit_to_file(mesh_path, 6, lib, method="kmeans", seed=3)
    assert run_cli("spheres", "fit", mesh_path, "-n", 6, "--method", "kmeans", "--seed", 3,
                   "-o", cli)[0] == 0
    assert lib.read_bytes() == cli.read_bytes()
    # the asset holds what the fit returned
    np.testing.assert_array_equal(read_spheres(lib).centers, result.centers)
    with one_blas_thread():
        tree = tree_to_file(lib, tmp_path / "lib_tree.h5")
    assert run_cli("spheres", "tree", lib, "-o", tmp_path / "cli_tree.h5")[0] == 0
    assert (tmp_path / "lib_tree.h5").read_bytes() == (tmp_path / "cli_tree.h5").read_bytes()
    # every sphere is a leaf of the tree, once
    t = read_tree(tmp_path / "lib_tree.h5")
    assert sorted(t.leaf[t.leaf >= 0].tolist()) == list(range(6))
    assert len(tree.parent) == len(t.parent)
