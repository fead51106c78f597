"""The ``haar`` asset: ``field sample --basis haar`` writes it deterministically, the runtime
reads it with numpy + h5py only, bad input gets one line."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import trimesh
from helpers.processes import forbidden_imports

ARGS = ("--basis", "haar", "--shells", 3, "--resolution", 8, "--map", 16, "--min-resolution", 4)


@pytest.fixture(scope="module")
def box_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("haarasset")
    trimesh.creation.box(extents=(0.8, 0.5, 0.6)).export(d / "box.obj")
    return d


def test_sampled_asset_is_deterministic_and_reads_back(box_dir, run_cli):
    from shtools.fields.haar import build_haar_field
    from shtools.runtime.haar import HaarField

    outs = []
    for k in range(2):
        out = box_dir / f"b{k}.haar.h5"
        code, stdout, err = run_cli("field", "sample", box_dir / "box.obj", "-o", out, *ARGS,
                                    "--json")
        assert code == 0, err
        outs.append(out)
    assert outs[0].read_bytes() == outs[1].read_bytes()
    summary = json.loads(stdout)
    assert summary["kept"] == round(0.05 * 256) and summary["basis"] == "haar"
    fld = HaarField.from_asset(outs[0])
    mem, _ = build_haar_field(trimesh.load(box_dir / "box.obj"), shells=3, resolution=8,
                              map_size=16, min_resolution=4)
    assert fld.map_size == 16 and list(fld.resolution) == list(mem.resolution)
    for c in range(3):
        np.testing.assert_array_equal(fld.index[c], mem.index[c])
        np.testing.assert_array_equal(fld.q[c], mem.q[c])
    np.testing.assert_array_equal(fld.offset, mem.offset)
    pts = np.array([[0.0, 0.0, 0.9], [1.2, -0.3, 0.2]])
    np.testing.assert_allclose(fld.visibility_maps(pts), mem.visibility_maps(pts), atol=1e-6)
    code, out, err = run_cli("check", outs[0])
    assert code == 0 and "shtools/haar version 1" in out + err


def test_runtime_reads_the_asset_without_the_geometry_stack(box_dir, run_cli):
    out = box_dir / "rt.haar.h5"
    code, _, err = run_cli("field", "sample", box_dir / "box.obj", "-o", out, *ARGS)
    assert code == 0, err
    code = (
        "import numpy as np\n"
        "from shtools.runtime.haar import HaarField\n"
        "from shtools.runtime.haar_shading import HaarBlocker, combined_maps\n"
        f"f = HaarField.from_asset({str(out)!r})\n"
        "b = HaarBlocker.from_matrix(f, np.eye(4))\n"
        "combined_maps([b], np.array([[0.0, 0.0, 1.0]]))\n"
    )
    assert forbidden_imports(code) == []


@pytest.mark.parametrize("extra,needle", [
    (("--keep", "0"), "--keep"),
    (("--map", "24"), "--map"),
    (("--bits", "6"), "--bits"),
    (("--self-order", "6"), "--self-order"),
])
def test_bad_haar_options_give_one_line(box_dir, run_cli, extra, needle):
    out = box_dir / "bad.haar.h5"
    code, _, err = run_cli("field", "sample", box_dir / "box.obj", "-o", out, *ARGS, *extra)
    assert code not in (0, 3) and len(err.strip().splitlines()) == 1 and needle in err, err
    assert not out.exists()
    assert not [p for p in box_dir.iterdir() if ".tmp" in p.name or p.name.startswith(".")]


def test_corrupt_asset_is_refused_in_one_line(box_dir, run_cli):
    good = box_dir / "c.haar.h5"
    code, _, err = run_cli("field", "sample", box_dir / "box.obj", "-o", good, *ARGS)
    assert code == 0, err
    bad = box_dir / "c_bad.haar.h5"
    bad.write_bytes(good.read_bytes())
    with h5py.File(bad, "r+") as f:
        idx = f["shells/0/index"][()]
        idx[0, 0, -1] = 16 * 16  # past the map
        f["shells/0/index"][...] = idx
    before = bad.read_bytes()
    code, out, err = run_cli("check", bad)
    assert code not in (0, 3) and "past the 16x16 map" in out + err
    assert bad.read_bytes() == before
