"""Scenes with ``blocker = { field = ... }``: bake/eval against ray tracing, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from shtools.data_formats.bake import read_bake
from shtools.reference.metrics import relative_rmse

FIELD_ARGS = ("--shells", 12, "--resolution", 16, "--map", 24, "--min-resolution", 4)
ENV = "[[3,3,3],[0,0,0],[1.5,1.5,1.5]" + ",[0,0,0]" * 13 + "]"


def scene_text(field="box.field.h5", extra="", scale=None, order=4):
    obj_scale = f"scale = {scale}\n" if scale is not None else ""
    return f"""
[settings]
order = {order}
{extra}
[environment]
coeffs = {ENV if order == 4 else "[[3,3,3]" + ",[0,0,0]" * (order * order - 1) + "]"}
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [3.0, 3.0], subdivisions = 24 }}
role = "receiver"
[[objects]]
name = "box"
mesh = "box.obj"
role = "both"
translate = [0.1, 0.5, 0.0]
rotate = [10, 35, 0]
{obj_scale}blocker = {{ field = "{field}" }}
[[objects]]
name = "ball"
primitive = {{ type = "sphere", radius = 0.25 }}
role = "blocker"
translate = [0.9, 0.3, 0.6]
"""


@pytest.fixture(scope="module")
def field_dir(tmp_path_factory):
    from shtools.cli.main import main

    d = tmp_path_factory.mktemp("fieldscene")
    trimesh.creation.box(extents=(0.8, 0.5, 0.6)).export(d / "box.obj")
    assert main(["field", "sample", str(d / "box.obj"), "-o", str(d / "box.field.h5"),
                 *map(str, FIELD_ARGS)]) == 0
    assert main(["field", "sample", str(d / "box.obj"), "-o", str(d / "box3.field.h5"),
                 "--order", "3", *map(str, FIELD_ARGS)]) == 0
    return d


def test_bake_with_a_field_blocker_matches_ray_tracing(run_cli, field_dir):
    (field_dir / "scene.toml").write_text(scene_text())
    rad = {}
    for method in ("default", "product", "raytrace"):
        out = field_dir / f"{method}.h5"
        code, _, err = run_cli("bake", field_dir / "scene.toml", "-o", out, "--method", method)
        assert code == 0, err
        rad[method] = read_bake(out).radiance
    # R = 16 fields on 12 shells, order-4 truncation of two occluders' products:
    # measured 2.4 % (log space) and 2.0 % (product space) relative RMSE
    assert relative_rmse(rad["default"], rad["raytrace"]) < 0.04
    assert relative_rmse(rad["product"], rad["raytrace"]) < 0.04
    # and the field shadows at all: without the box the ground is brighter
    (field_dir / "nobox.toml").write_text(scene_text().replace('role = "both"',
                                                               'role = "receiver"').replace(
        'blocker = { field = "box.field.h5" }', ""))
    code, _, err = run_cli("bake", field_dir / "nobox.toml", "-o", field_dir / "nobox.h5")
    assert code == 0, err
    ground = slice(0, 625)
    assert rad["raytrace"][0, ground].mean() < 0.95 * read_bake(
        field_dir / "nobox.h5").radiance[0, ground].mean()


def test_field_space_setting_and_eval(run_cli, field_dir):
    (field_dir / "prod.toml").write_text(scene_text(extra='field_space = "product"'))
    code, out, err = run_cli("eval", field_dir / "prod.toml", "--methods", "auto,product@4",
                             "--n-dirs", 500, "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["fields"] == 1 and summary["field_space"] == "product"
    rows = {r["method"]: r for r in summary["methods"]}
    assert rows["auto"]["rmse_vs_mesh"] < 0.06  # same budget as the bake test + 500 rays


def test_uniform_scale_is_accepted(run_cli, field_dir):
    (field_dir / "scaled.toml").write_text(scene_text(scale=1.3))
    code, _, err = run_cli("bake", field_dir / "scaled.toml", "-o", field_dir / "s.h5")
    assert code == 0, err


@pytest.mark.parametrize("kwargs,needle", [
    ({"scale": "[1.0, 2.0, 1.0]"}, "uniform scale"),
    ({"field": "box3.field.h5"}, "order"),
    ({"field": "missing.h5"}, "not found"),
])
def test_bad_field_scenes_give_one_line(run_cli, field_dir, kwargs, needle):
    path = field_dir / "bad.toml"
    path.write_text(scene_text(**kwargs))
    out = field_dir / "bad_out.h5"
    code, _stdout, err = run_cli("bake", path, "-o", out)
    assert code != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0]
    assert not out.exists()


def test_field_evaluated_vertices_are_not_the_objects_own(field_dir):
    """The box's own vertices never look up its field (they sit inside its shells)."""
    from shtools.scene.bake import pose_frame, prepare_scene
    from shtools.scene.scene import load_scene

    (field_dir / "scene.toml").write_text(scene_text())
    prepared = prepare_scene(load_scene(field_dir / "scene.toml"))
    state = pose_frame(prepared, 0.0)
    from shtools.runtime import FieldBlocker

    fb = next(b for b in state.blockers if isinstance(b, FieldBlocker))
    n_ground = len(prepared.receivers[0].vertices)
    assert np.array_equal(fb.skip_rows, np.arange(n_ground, len(state.vertices)))
    assert not np.isin(fb.active_rows(state.vertices, state.normals), fb.skip_rows).any()
