"""Scene TOML parsing: valid files become dataclasses; every kind of mistake is one line."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from shtools.errors import InputError
from shtools.scene.scene import load_scene, parse_scene

MINIMAL = """
[environment]
coeffs = [[1.0, 1.0, 1.0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]

[settings]
order = 2

[[objects]]
name = "ground"
primitive = { type = "plane", size = [4, 4], subdivisions = 8 }
role = "receiver"
"""


def parse(text, tmp_path):
    return parse_scene(text, tmp_path / "scene.toml")


def test_minimal_scene(tmp_path):
    scene = parse(MINIMAL, tmp_path)
    assert scene.settings.order == 2
    assert scene.objects[0].primitive == ("plane", {"size": [4, 4], "subdivisions": 8})
    assert scene.environment.kind == "coeffs"
    assert scene.environment.coeffs.shape == (4, 3)


def test_full_scene(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "box.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "sky.h5").write_bytes(b"")  # existence is checked at parse time only
    text = """
[settings]
order = 3
acc_order = 5
exp_method = "ps*"
window = "none"
theta_max_deg = 20
frames = 10
fps = 10

[environment]
light = "sky.h5"
intensity = 2.0
rotate_deg = 90

[[lights]]
position = [0, 3, 0]
radius = 0.5
color = [1, 2, 3]
[[lights.keyframes]]
frame = 0
[[lights.keyframes]]
frame = 9
position = [3, 3, 0]

[[objects]]
name = "box"
mesh = "meshes/box.obj"
role = "both"
translate = [1, 2, 3]
rotate = [0, 90, 0]
scale = 2
blocker = { fit = 8, method = "octree" }
[[objects.keyframes]]
time = 0.5
translate = [0, 0, 0]
[[objects.keyframes]]
time = 0.0

[[objects]]
name = "lid"
primitive = "sphere"
role = "blocker"
parent = "box"
"""
    scene = parse(text, tmp_path)
    st = scene.settings
    assert (st.order, st.acc_order, st.exp_method, st.window) == (3, 5, "ps*", None)
    assert math.isclose(st.theta_max, math.radians(20))
    box = scene.object("box")
    assert box.mesh == tmp_path / "meshes" / "box.obj"
    assert box.blocker.kind == "fit" and box.blocker.count == 8
    assert box.blocker.options["method"] == "octree"
    # keyframes are sorted by time and inherit the object's static transform
    assert [k.time for k in box.keyframes] == [0.0, 0.5]
    np.testing.assert_allclose(box.keyframes[0].pose.translate, [1, 2, 3])
    np.testing.assert_allclose(box.keyframes[1].pose.translate, [0, 0, 0])
    np.testing.assert_allclose(box.keyframes[1].pose.scale, [2, 2, 2])
    # rotate = [0, 90, 0]: quaternion of 90 degrees about +Y
    s = math.sqrt(0.5)
    np.testing.assert_allclose(box.pose.quaternion, [0, s, 0, s], atol=1e-12)
    lid = scene.object("lid")
    assert lid.blocker.kind == "exact" and lid.parent == "box"
    light = scene.lights[0]
    assert [k.time for k in light.keys] == [0.0, 0.9]
    np.testing.assert_allclose(light.keys[1].position, [3, 3, 0])
    np.testing.assert_allclose(light.keys[1].color, [1, 2, 3])
    assert scene.environment.kind == "light" and scene.environment.intensity == 2.0


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("[settings]\norder = 2", "[settings]\norder = 2\nordr = 3"),
         "settings: unknown key 'ordr'; did you mean 'order'?"),
        (('role = "receiver"', 'role = "receiver"\nrotaton = [0, 1, 0]'),
         "objects[0] ('ground'): unknown key 'rotaton'; did you mean 'rotate'?"),
        (('role = "receiver"', 'role = "reciever"'), "did you mean 'receiver'?"),
        (("subdivisions = 8", "subdivisons = 8"),
         "unknown key 'subdivisons'; did you mean 'subdivisions'?"),
        (('type = "plane"', 'type = "plan"'), "did you mean 'plane'?"),
        (("order = 2", "order = 0"), "settings.order: must be >= 1"),
        (("order = 2", "order = 3"), "environment.coeffs: is order 2 but settings.order is 3"),
        (('role = "receiver"', 'role = "blocker"'), "a blocker needs a representation"),
        (('role = "receiver"', 'role = "receiver"\nparent = "grund"'),
         "no object named 'grund'"),
        (('role = "receiver"', 'role = "receiver"\nscale = "big"'),
         "scale: must be a number or a list of 3 numbers, got 'big'"),
    ],
)
def test_invalid_scenes_give_one_line(tmp_path, edit, message):
    old, new = edit
    assert old in MINIMAL
    with pytest.raises(InputError) as info:
        parse(MINIMAL.replace(old, new, 1), tmp_path)
    line = info.value.one_line()
    assert "\n" not in line
    assert message in line
    assert line.startswith(str(tmp_path / "scene.toml"))


def test_toml_syntax_error_has_line_and_column(tmp_path):
    with pytest.raises(InputError) as info:
        parse(MINIMAL.replace("order = 2", "order = = 2"), tmp_path)
    line = info.value.one_line()
    assert "invalid TOML" in line and "line 6" in line and "column" in line


def test_missing_files_are_named(tmp_path):
    text = MINIMAL.replace('primitive = { type = "plane", size = [4, 4], subdivisions = 8 }',
                           'mesh = "nope.obj"')
    with pytest.raises(InputError, match=re.escape(
            "objects[0] ('ground').mesh: file 'nope.obj' not found")):
        parse(text, tmp_path)
    with pytest.raises(InputError, match="scene file not found"):
        load_scene(tmp_path / "missing.toml")


def test_zero_radius_light_and_cycles(tmp_path):
    light = "\n[[lights]]\nposition = [0, 1, 0]\nradius = 0.0\ncolor = [1, 1, 1]\n"
    with pytest.raises(InputError, match="zero-area"):
        parse(MINIMAL + light, tmp_path)
    cyc = MINIMAL + """
[[objects]]
name = "a"
primitive = "sphere"
role = "blocker"
parent = "b"
[[objects]]
name = "b"
primitive = "sphere"
role = "blocker"
parent = "a"
"""
    with pytest.raises(InputError, match="cycle"):
        parse(cyc, tmp_path)


def test_skin_needs_gltf(tmp_path):
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    text = MINIMAL + '\n[[objects]]\nname = "c"\nmesh = "m.obj"\nrole = "receiver"\nskin = {}\n'
    with pytest.raises(InputError, match="skinned animation needs a glTF mesh"):
        parse(text, tmp_path)


BALL = """
[[objects]]
name = "ball"
primitive = { type = "sphere", radius = 0.5 }
role = "blocker"
"""


@pytest.mark.parametrize(
    ("addition", "message"),
    [
        # the whole line after the file name is pinned: TOML path, what is wrong, the fix
        ("[settings]\nacc_order = 1\n", None),
        ('\n[[lights]]\nposition = [0, 1, 0]\nradius = 0.1\ncolor = [1, 1, 1]\ncolour = 1\n',
         "lights[0]: unknown key 'colour'; did you mean 'color'?"),
        ('\n[[lights]]\nposition = [0, 1]\nradius = 0.1\ncolor = [1, 1, 1]\n',
         "lights[0].position: must be a list of 3 numbers, got [0, 1]"),
        ('\n[[lights]]\nposition = [0, 1, 0]\nradius = 0.1\n', "lights[0]: missing key 'color'"),
        ('\n[[lights]]\nposition = [0, 1, 0]\nradius = 0.1\ncolor = [1, 1, 1]\n'
         'shadows = "shexpp"\n',
         "lights[0].shadows: must be one of shexp, ssoc, raytrace, auto; did you mean 'shexp'? "
         "got 'shexpp'"),
        ('\n[[lights]]\nposition = [0, 1, 0]\nradius = 0.1\ncolor = [1, -1, 1]\n',
         "lights[0].color: must not be negative, got [1, -1, 1]"),
        ('\n[[lights]]\nposition = [0, 1, 0]\nradius = 0.1\ncolor = [1, 1, 1]\n'
         'intensity = -2\n', "lights[0].intensity: must be >= 0, got -2"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { fit = 0 }'),
         "objects[1] ('ball').blocker.fit: must be >= 1, got 0"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { fit = 8, sed = 1 }'),
         "objects[1] ('ball').blocker: unknown key 'sed'; did you mean 'seed'?"),
        # a key no blocker kind has ('race', a removed option) is refused with the allowed keys
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { fit = 8, race = true }'),
         "objects[1] ('ball').blocker: unknown key 'race'; allowed: spheres, tree, bound, fit, "
         "method, seed, branching, exact, deformable, alpha_deg, samples, rays, log, field"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { exact = true, '
                      'seed = 1 }'),
         "objects[1] ('ball').blocker.seed: only applies with 'fit = ...'"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { fit = 8, '
                      'method = "kmean" }'),
         "objects[1] ('ball').blocker.method: must be one of variational, octree, kmeans; "
         "did you mean 'kmeans'? got 'kmean'"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { fit = 8, exact = true }'),
         "objects[1] ('ball').blocker: give exactly one of 'spheres', 'tree', 'bound', 'fit', "
         "'exact', 'deformable', 'field' (see docs/scenes.md)"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nblocker = { exact = false }'),
         "objects[1] ('ball').blocker.exact: must be true (or leave it out)"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nscale = [1, 0, 1]'),
         "objects[1] ('ball').scale: must be positive, got [1, 0, 1]"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nrotate = [0, 1, 0]\n'
                      'quaternion = [0, 0, 0, 1]'),
         "objects[1] ('ball'): give either 'rotate' (Euler degrees) or 'quaternion', not both"),
        (BALL.replace('role = "blocker"', 'role = "blocker"\nloop = 1'),
         "objects[1] ('ball').loop: must be true or false, got 1"),
        (BALL + "[[objects.keyframes]]\ntime = 0\nframe = 1\n",
         "objects[1] ('ball').keyframes[0]: give exactly one of 'time' (seconds) or 'frame'"),
        (BALL + "[[objects.keyframes]]\ntime = 0\n[[objects.keyframes]]\ntime = 0.0\n",
         "objects[1] ('ball').keyframes: two keyframes have the same time"),
        (BALL + "[[objects.keyframes]]\ntime = inf\n",
         "objects[1] ('ball').keyframes[0].time: must be finite, got inf"),
        (BALL.replace('name = "ball"', 'name = "ground"'),
         "two objects are named 'ground'; names must be unique"),
    ],
)
def test_more_mistakes_give_one_pinned_line(tmp_path, addition, message):
    if message is None:  # the settings cross-check: acc_order below order
        text = MINIMAL.replace("order = 2", "order = 2\nacc_order = 1")
        message = ("settings: acc_order must be an integer in order (2)..10 (or None: "
                   "min(order + 2, 6)), got 1")
    else:
        text = MINIMAL + addition
    with pytest.raises(InputError) as info:
        parse(text, tmp_path)
    assert info.value.one_line() == f"{tmp_path / 'scene.toml'}: {message}"


@pytest.mark.parametrize(("setting", "message"), [
    ("order = 9", "settings.order: must be <= 8, got 9"),
    ("order = 2.0", "settings.order: must be an integer, got 2.0"),
    ("acc_order = 11", "settings.acc_order: must be <= 10, got 11"),
    ("theta_max_deg = 90", "settings.theta_max_deg: must be < 90, got 90"),
    ("theta_min_deg = -1", "settings.theta_min_deg: must be >= 0, got -1"),
    ("fps = nan", "settings.fps: must be finite, got nan"),
    ("frames = 0", "settings.frames: must be >= 1, got 0"),
    ("hierarchy = 1", "settings.hierarchy: must be true or false, got 1"),
    ('exp_method = "ps+"', "settings.exp_method: must be one of auto, hyb, ps*, ps, ol, exact, "
                           "volterra; did you mean 'ps'? got 'ps+'"),
    ('window = "han"', "settings.window: must be one of cosine, hann, lanczos, none; did you "
                       "mean 'hann'? got 'han'"),
    ('method = "raytrac"', "settings.method: must be one of default, hyb, ps*, ps, ol, exact, "
                           "volterra, product, raytrace; did you mean 'raytrace'? got 'raytrac'"),
    ("procesess = 2", "settings: unknown key 'procesess'; allowed: order, acc_order, "
                      "exp_method, exp_degree, exp_margin, window, window_h, theta_max_deg, "
                      "theta_min_deg, hierarchy, vertices_per_cluster, cluster_blend, "
                      "self_shadow, deringing, "
                      "field_space, frames, fps, tables, method, self_visibility, "
                      "self_visibility_directions, traced_shadows, traced_shadow_directions, "
                      "local_visibility"),
    ("vertices_per_clustr = 2", "settings: unknown key 'vertices_per_clustr'; did you mean "
                                "'vertices_per_cluster'?"),
    ('tables = "t.h5"', "settings.tables: file 't.h5' not found (paths are relative to the "
                        "scene file)"),
])
def test_settings_errors_come_from_the_schema(tmp_path, setting, message):
    with pytest.raises(InputError) as info:
        parse(MINIMAL.replace("order = 2", f"order = 2\n{setting}").replace(
            "order = 2\norder", "order"), tmp_path)
    assert info.value.one_line() == f"{tmp_path / 'scene.toml'}: {message}"


def test_order_limits_agree_with_the_runtime(tmp_path):
    """A scene accepts exactly the orders the runtime runs (an order the runtime refuses must
    fail at parse time, not late in the bake)."""
    from shtools.runtime.settings import MAX_ACC_ORDER, MAX_ORDER

    text = MINIMAL.replace("order = 2", f"order = {MAX_ORDER}\nacc_order = {MAX_ACC_ORDER}")
    text = text.replace("coeffs = [[1.0, 1.0, 1.0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]",
                        "coeffs = [" + ", ".join(["[1.0, 1.0, 1.0]"] * MAX_ORDER ** 2) + "]")
    scene = parse(text, tmp_path)
    from shtools.scene.bake import runtime_settings

    rs = runtime_settings(scene, "default")
    assert (rs.order, rs.resolved_acc_order()) == (MAX_ORDER, MAX_ACC_ORDER)
