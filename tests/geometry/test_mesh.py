"""load_mesh: validation errors (one line, naming the file) and repairs."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shtools.errors import InputError
from shtools.geometry.mesh import boundary_edges, load_mesh, thicken


def test_loads_and_merges_duplicate_vertices(tmp_path):
    # two triangles sharing an edge, written with split (duplicate) vertices
    # plus one zero-area triangle
    path = tmp_path / "quad.obj"
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 2\n"
        "f 1 2 3\nf 4 5 6\nf 1 4 2\n"
    )
    mesh = load_mesh(path)
    assert len(mesh.vertices) == 4  # duplicates merged, unreferenced (2,2,2) dropped
    assert len(mesh.faces) == 2  # the degenerate (1 4 2 = 1 1 2) face removed
    assert len(boundary_edges(mesh)) == 4  # shared diagonal recognised as interior


def test_open_boundary_kept(write_mesh, open_mesh):
    mesh = load_mesh(write_mesh(open_mesh))
    assert len(mesh.faces) == len(open_mesh.faces)
    assert len(boundary_edges(mesh)) > 0


@pytest.mark.parametrize(
    ("name", "content", "fragment"),
    [
        ("empty.obj", "# nothing\n", "empty"),
        ("nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "NaN"),
        ("inf.obj", "v 0 0 0\nv 1 0 0\nv inf 1 0\nf 1 2 3\n", "NaN or inf"),
        ("mesh.xyz", "0 0 0\n", "unsupported mesh format"),
        ("garbage.ply", "\x00\x01 this is not a ply file", "cannot read"),
    ],
)
def test_bad_files_raise_one_line_input_error(tmp_path, name, content, fragment):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(InputError) as info:
        load_mesh(path)
    text = info.value.one_line()
    assert fragment in text
    assert str(path) in text and "\n" not in text


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_mesh(tmp_path / "missing.obj")


def test_thicken_flat_sheet_encloses_area_times_thickness(flat_sheet_mesh):
    shell = thicken(flat_sheet_mesh, 0.05)
    assert shell.is_watertight
    # closed form: a 1 x 1 slab of thickness 0.05 (normals are exactly ±z)
    assert shell.volume == pytest.approx(0.05, rel=1e-9)


def test_thicken_rejects_nonpositive(flat_sheet_mesh):
    with pytest.raises(InputError, match="thickness"):
        thicken(flat_sheet_mesh, 0.0)


def test_multi_object_scene_is_flattened(tmp_path):
    a = trimesh.creation.box()
    b = trimesh.creation.box()
    b.apply_translation([3, 0, 0])
    path = tmp_path / "two.glb"
    trimesh.Scene([a, b]).export(path)
    mesh = load_mesh(path)
    assert len(mesh.faces) == 24
    assert np.isclose(mesh.volume, 2.0)
