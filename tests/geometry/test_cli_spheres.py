"""``shtools spheres fit | import | export`` from the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from shtools.data_formats.spheres import read_spheres


@pytest.fixture(scope="module")
def coarse_torus():
    return trimesh.creation.torus(1.0, 0.35, major_sections=24, minor_sections=12)


def test_fit_writes_asset_and_json(run_cli, write_mesh, coarse_torus, tmp_path):
    mesh_path = write_mesh(coarse_torus, "torus.obj")
    out = tmp_path / "spheres.h5"
    code, stdout, stderr = run_cli("spheres", "fit", mesh_path, "-n", 6, "-o", out,
                                   "--iterations", 3, "--json")
    assert code == 0, stderr
    summary = json.loads(stdout)
    spheres = read_spheres(out)
    assert summary["spheres"] == len(spheres) == 6
    assert summary["coverage"] == 1.0
    assert summary["outside_volume_ratio"] == pytest.approx(spheres.outside_volume_ratio)
    assert spheres.outside_volume_ratio > 0


def test_same_seed_gives_identical_bytes(run_cli, write_mesh, coarse_torus, tmp_path):
    mesh_path = write_mesh(coarse_torus, "torus.obj")
    outs = [tmp_path / "a.h5", tmp_path / "b.h5"]
    for out in outs:
        code, _, stderr = run_cli("spheres", "fit", mesh_path, "-n", 4, "-o", out,
                                  "--iterations", 2, "--seed", 5)
        assert code == 0, stderr
    assert outs[0].read_bytes() == outs[1].read_bytes()


def test_export_import_round_trip(run_cli, write_mesh, coarse_torus, tmp_path):
    mesh_path = write_mesh(coarse_torus, "torus.obj")
    fitted = tmp_path / "fit.h5"
    assert run_cli("spheres", "fit", mesh_path, "-n", 5, "-o", fitted,
                   "--method", "octree")[0] == 0
    sph = tmp_path / "fit.sph"
    code, _, stderr = run_cli("spheres", "export", fitted, "-o", sph)
    assert code == 0, stderr
    back = tmp_path / "back.h5"
    code, _, stderr = run_cli("spheres", "import", sph, "-o", back, "--mesh", mesh_path)
    assert code == 0, stderr
    a, b = read_spheres(fitted), read_spheres(back)
    np.testing.assert_array_equal(a.centers, b.centers)
    np.testing.assert_array_equal(a.radii, b.radii)
    # E recomputed from the mesh on import agrees with the fit's own value
    assert b.outside_volume_ratio == pytest.approx(a.outside_volume_ratio, rel=1e-9)


@pytest.mark.parametrize(
    ("case", "fragment"),
    [
        ("missing", "not found"),
        ("unsupported", "unsupported mesh format"),
        ("empty", "empty"),
        ("nan", "NaN"),
        ("flat", "--thickness"),
        ("zero", "0 is not in the range x>=1"),
        ("too_many", "sample points"),
    ],
)
def test_errors_are_one_line_without_output(run_cli, tmp_path, write_mesh, coarse_torus,
                                            flat_sheet_mesh, case, fragment):
    n = 4
    if case == "missing":
        mesh_path = tmp_path / "nope.obj"
    elif case == "unsupported":
        mesh_path = tmp_path / "mesh.dat"
        mesh_path.write_text("1 2 3")
    elif case == "empty":
        mesh_path = tmp_path / "empty.obj"
        mesh_path.write_text("# no faces\n")
    elif case == "nan":
        mesh_path = tmp_path / "nan.obj"
        mesh_path.write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n")
    elif case == "flat":
        mesh_path = write_mesh(flat_sheet_mesh, "flat.obj")
    else:
        mesh_path = write_mesh(coarse_torus, "torus.obj")
        n = 0 if case == "zero" else 10**6
    out = tmp_path / "out.h5"
    code, _, stderr = run_cli("spheres", "fit", mesh_path, "-n", n, "-o", out)
    assert code != 0
    assert stderr.startswith("error: ") and stderr.count("\n") == 1, stderr
    assert fragment in stderr
    assert not out.exists()
    assert not list(tmp_path.glob(".out.h5*"))  # no temporary left behind


def test_thickness_makes_a_sheet_fittable(run_cli, write_mesh, flat_sheet_mesh, tmp_path):
    out = tmp_path / "sheet.h5"
    code, _, stderr = run_cli("spheres", "fit", write_mesh(flat_sheet_mesh, "flat.obj"),
                              "-n", 4, "-o", out, "--thickness", 0.05, "--iterations", 2)
    assert code == 0, stderr
    assert len(read_spheres(out)) == 4


def test_import_rejects_bad_sph(run_cli, tmp_path):
    bad = tmp_path / "bad.sph"
    bad.write_text("3 8\n0 0 0 1 0\n")
    out = tmp_path / "x.h5"
    code, _, stderr = run_cli("spheres", "import", bad, "-o", out)
    assert code != 0 and "truncated" in stderr
    assert not out.exists()
