"""``shtools field sample``: the asset through the real CLI, info/check/diff, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from shtools.data_formats.field import read_field

SMALL = ("--shells", 3, "--resolution", 8, "--map", 16, "--order", 3, "--min-resolution", 2)


@pytest.fixture
def box_obj(tmp_path):
    path = tmp_path / "box.obj"
    trimesh.creation.box(extents=(1.0, 0.6, 0.3)).export(path)
    return path


def test_sample_writes_a_valid_field(run_cli, tmp_path, box_obj):
    out = tmp_path / "box.field.h5"
    code, stdout, err = run_cli("field", "sample", box_obj, "-o", out, *SMALL, "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    fld = read_field(out)
    assert summary["resolution"] == fld.resolution.tolist()
    assert summary["bytes"] == sum(r * r for r in fld.resolution) * 9
    assert fld.order == 3 and fld.attrs["phi_wrap"] and fld.attrs["pole_axis"] == "+z"
    for cmd in ("check", "info"):
        code, _, err = run_cli(cmd, out)
        assert code == 0, err
    again = tmp_path / "again.h5"
    run_cli("field", "sample", box_obj, "-o", again, *SMALL)
    code, _, err = run_cli("diff", out, again, "--rtol", 0, "--atol", 0)
    assert code == 0, err  # deterministic


def test_open_mesh_is_reported(run_cli, tmp_path):
    mesh = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    mesh.faces = mesh.faces[:-2]  # a hole
    path = tmp_path / "open.obj"
    mesh.export(path)
    code, stdout, _ = run_cli("field", "sample", path, "-o", tmp_path / "o.h5", *SMALL)
    assert code == 0 and "leak" in stdout
    assert read_field(tmp_path / "o.h5").attrs["closed"] is False


def _nan_obj(path):
    path.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")


def _flat_obj(path):
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
                    [[0, 1, 2], [1, 3, 2]]).export(path)


def _empty_obj(path):
    path.write_text("# nothing\n")


@pytest.mark.parametrize("make,args,needle", [
    (_nan_obj, (), "NaN"),
    (_flat_obj, (), "flat"),
    (_empty_obj, (), ""),
    (None, ("--threshold", 0), "--threshold"),
    (None, ("--threshold", -1), "--threshold"),
    (None, ("--resolution", 48), "--resolution"),
    (None, ("--min-resolution", 3), "--min-resolution"),
    (None, ("--bits", 9), "--bits"),
    (None, ("--self-order", 2), "--self-order"),  # below --order 3
    (None, ("--self-order", 11), "--self-order"),
])
def test_bad_input_gives_one_line_and_no_file(run_cli, tmp_path, box_obj, make, args, needle):
    mesh = box_obj
    if make is not None:
        mesh = tmp_path / "bad.obj"
        make(mesh)
    out = tmp_path / "out.h5"
    code, stdout, err = run_cli("field", "sample", mesh, "-o", out, *SMALL, *args)
    assert code != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0]
    assert "Traceback" not in err and stdout == ""
    assert not out.exists()
    assert not list(tmp_path.glob(".out.h5*"))


def test_field_reader_refuses_a_broken_asset(run_cli, tmp_path, box_obj):
    import h5py

    out = tmp_path / "f.h5"
    run_cli("field", "sample", box_obj, "-o", out, *SMALL)
    with h5py.File(out, "a") as f:
        del f["shells/1/log"]
    code, _, err = run_cli("check", out)
    assert code == 1 and "shells/1/log" in err and len(err.strip().splitlines()) == 1
    with h5py.File(out, "a") as f:
        f["shell_resolution"][1] = 3
    code, _, err = run_cli("check", out)
    assert code == 1 and "power" in err
    # a self-visibility below the field's order, or not of m*m columns
    for cols in (4, 20):  # the field is order 3
        out = tmp_path / f"sv{cols}.h5"
        run_cli("field", "sample", box_obj, "-o", out, *SMALL)
        with h5py.File(out, "a") as f:
            v = f["self_visibility"].shape[0]
            del f["self_visibility"]
            f["self_visibility"] = np.zeros((v, cols), np.float32)
        code, _, err = run_cli("check", out)
        assert code == 1 and "self_visibility" in err and len(err.strip().splitlines()) == 1


def test_shells_as_tasks_give_the_same_bytes(run_cli, tmp_path, box_obj):
    # Shells are independent tasks: one process or two workers, the same file.
    import filecmp

    outs = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}.field.h5"
        code, _, err = run_cli("field", "sample", box_obj, "-o", out, *SMALL,
                              "--workers", workers, "--no-self-visibility")
        assert code == 0, err
        outs.append(out)
    assert filecmp.cmp(*outs, shallow=False)


def test_field_versions_1_and_2_read_and_a_newer_one_is_refused(run_cli, tmp_path, box_obj):
    """Version 2 may store O_v above the field's order; version-1 files (O_v at the
    field's order, written before) still read; an unknown version gets one line."""
    import h5py

    out = tmp_path / "f.h5"
    run_cli("field", "sample", box_obj, "-o", out, *SMALL, "--self-order", 3)
    with h5py.File(out, "r") as f:
        assert f.attrs["format_version"] == 2
        assert f["self_visibility"].shape[1] == 9  # O_v at the field's order, as in v1
    for version, expected in ((1, 0), (3, 1)):
        with h5py.File(out, "a") as f:
            f.attrs["format_version"] = np.int64(version)
        code, _, err = run_cli("check", out)
        assert code == expected, err
        if expected:
            assert "format version 3" in err and len(err.strip().splitlines()) == 1
