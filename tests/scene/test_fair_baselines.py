"""Baselines at equal order: ``bake --method product`` accumulates at the runtime's order."""

from __future__ import annotations

import math

import numpy as np

from shtools.data_formats.bake import read_bake
from shtools.reference import product_space_visibility
from shtools.scene.bake import bake_to_file, prepare_scene
from shtools.scene.pose import pose_frame
from shtools.scene.scene import load_scene

SCENE = f"""
[settings]
order = 3
[environment]
coeffs = [[{math.sqrt(4 * math.pi)}, 1.0, 1.0]{", [0.0, 0.0, 0.0]" * 8}]
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [3, 3], subdivisions = 6 }}
role = "receiver"
[[objects]]
name = "ball"
primitive = {{ type = "sphere", radius = 0.4 }}
role = "blocker"
translate = [0.2, 0.7, 0.0]
[[objects]]
name = "ball2"
primitive = {{ type = "sphere", radius = 0.35 }}
role = "blocker"
translate = [-0.3, 0.6, 0.2]
"""


def test_product_accumulates_at_the_runtime_order(tmp_path):
    (tmp_path / "scene.toml").write_text(SCENE)
    scene = load_scene(tmp_path / "scene.toml")
    out = tmp_path / "product.h5"
    bake_to_file(scene, out, method="product", store_visibility=True)
    bake = read_bake(out)
    acc = scene.settings.resolved_acc_order()
    assert acc == 5 and bake.parameters["acc_order"] == acc  # order 3 -> min(3 + 2, 6)
    state = pose_frame(prepare_scene(scene), 0.0)
    at_acc = product_space_visibility(state.vertices, state.normals, state.blockers, 3, acc)
    at_order = product_space_visibility(state.vertices, state.normals, state.blockers, 3, 3)
    vis = np.asarray(bake.visibility[0], dtype=np.float64)
    np.testing.assert_allclose(vis, at_acc, atol=1e-5)  # stored as float32
    # two overlapping caps: products at order 5 and at 3 differ (one cap would not)
    assert np.abs(at_acc - at_order).max() > 1e-3
