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
    assert box.blocker.kind == "fit" and box.blocker.count == 8 and box.blocker.method == "octree"
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
