"""``shtools eval``: built-in blocker-over-ground form, JSON table, PNG, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.scenes import ground, scene_text

from shtools.data_formats.spheres import write_spheres
from shtools.geometry.sphere_set import SphereSet
from shtools.geometry.sphere_tree import build_tree
from shtools.reference.scenes import capsule_scene


@pytest.fixture
def capsule_assets(tmp_path):
    """A procedural capsule mesh (OBJ) with its bounding spheres and tree."""
    from shtools.data_formats.tree import write_tree

    sc = capsule_scene(grid=8)
    mesh = sc.meshes[0]
    mesh_path = tmp_path / "capsule.obj"
    mesh.export(mesh_path)
    centers, radii = sc.centers[:-1], sc.radii[:-1]  # the capsule's spheres only
    spheres = tmp_path / "spheres.h5"
    write_spheres(spheres, SphereSet(centers=centers, radii=radii, outside_volume_ratio=0.1,
                                     coverage=1.0, method="import", info={}))
    tree = tmp_path / "tree.h5"
    write_tree(tree, build_tree(centers, radii))
    return mesh_path, spheres, tree


def test_eval_builtin_form_json_and_png(run_cli, capsule_assets, tmp_path):
    mesh, spheres, tree = capsule_assets
    png = tmp_path / "cmp.png"
    code, out, err = run_cli("eval", "--mesh", mesh, "--spheres", spheres, "--tree", tree,
                             "--grid", 14, "--n-dirs", 600, "--methods", "auto,hyb@4,product@4",
                             "--json", "--png", png)
    assert code == 0, err
    summary = json.loads(out)
    assert [m["method"] for m in summary["methods"]] == ["auto", "hyb@4", "product@4"]
    assert summary["vertices"] == 14 * 14 and summary["spheres"] == 6
    by = {m["method"]: m for m in summary["methods"]}
    for m in summary["methods"]:
        # sanity bounds for a 14x14 grid with 600 ray directions (quadrature noise ~2-3 %):
        # any method should be well within 10 % of the spheres and 20 % of the mesh
        assert 0 <= m["rmse_vs_spheres"] < 0.1 and 0 <= m["rmse_vs_mesh"] < 0.2
        assert m["seconds"] > 0
    # accumulating at 6 (auto) is closer to the sphere set than at 4 (Fig. 7e)
    assert by["auto"]["rmse_vs_spheres"] < by["hyb@4"]["rmse_vs_spheres"]
    # log space at 4 is close to product space at 4 (Fig. 7d vs c)
    assert abs(by["hyb@4"]["rmse_vs_spheres"] - by["product@4"]["rmse_vs_spheres"]) < 0.02
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_eval_human_table(run_cli, capsule_assets):
    mesh, spheres, _ = capsule_assets
    code, out, err = run_cli("eval", "--mesh", mesh, "--spheres", spheres, "--grid", 6,
                             "--n-dirs", 200, "--methods", "ps*")
    assert code == 0, err
    assert "| ps* |" in out and "| spheres, ray traced |" in out


@pytest.mark.parametrize("args,message,want", [
    # a bad option value: a usage error (exit 2, as click's own); a bad output file: 1
    (["--methods", "magic"], "unknown method", 2),
    (["--methods", "hyb@x"], "accumulation order", 2),
    (["--png", "out.jpg"], ".png", 1),
])
def test_eval_rejects_bad_options(run_cli, capsule_assets, args, message, want):
    mesh, spheres, _ = capsule_assets
    code, _, err = run_cli("eval", "--mesh", mesh, "--spheres", spheres, *args)
    assert code == want
    assert message in err and "Traceback" not in err


def test_eval_needs_a_scene_or_mesh(run_cli):
    code, _, err = run_cli("eval")
    assert code == 1 and "--mesh" in err


def test_eval_scene_file(run_cli, tmp_path):
    """The scene form, with a procedural scene (primitives, no assets needed)."""
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE_TOML)
    code, out, err = run_cli("eval", scene, "--n-dirs", 300, "--methods", "auto,product@4",
                             "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["vertices"] > 0 and len(summary["methods"]) == 2
    assert all(np.isfinite(m["rmse_vs_mesh"]) for m in summary["methods"])


SCENE_TOML = scene_text(
    settings={"order": 2},
    environment={"coeffs": [[3.0, 3.0, 3.0], [0.0, 0.0, 0.0], [1.5, 1.5, 1.4], [0.0, 0.0, 0.0]]},
    objects=[ground(size=3.0, subdivisions=10),
             {"name": "ball", "primitive": {"type": "sphere", "radius": 0.4, "subdivisions": 2},
              "role": "blocker", "translate": [0.0, 0.6, 0.0], "blocker": {"exact": True}}])


def test_eval_maps_have_a_colour_bar_per_row_with_units():
    from types import SimpleNamespace

    from shtools.reference.maps import ERROR_LABEL, RADIANCE_LABEL, comparison_figure

    rng = np.random.default_rng(0)
    verts = rng.uniform(-1, 1, (50, 3))
    ref = rng.uniform(0, 2, (50, 3))
    out = {"mesh_radiance": ref, "spheres_radiance": ref * 0.9,
           "results": [SimpleNamespace(method="auto", radiance=ref * 1.1)]}
    fig = comparison_figure(verts, out)
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert [b.get_ylabel() for b in bars] == [RADIANCE_LABEL, ERROR_LABEL]
    assert "units" in RADIANCE_LABEL and "units" in ERROR_LABEL
    # the bars span the rows' shared scales: radiance from 0, error symmetric
    lo, hi = bars[0].get_ylim()
    assert lo == 0 and hi > 0
    lo, hi = bars[1].get_ylim()
    assert lo == -hi
    import matplotlib.pyplot as plt

    plt.close(fig)
