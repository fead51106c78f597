"""The blocker-kind and light-shadow protocols: a new kind or way is one class + registration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers.scenes import ground, scene_text

from shtools import sh
from shtools.runtime import LogBlocker, ShadowRuntime, ShadowSettings
from shtools.scene import blockers, shadows
from shtools.scene.bake import bake_scene
from shtools.scene.scene import parse_scene

SCENE = scene_text(
    settings={"order": 3, "acc_order": 5, "exp_method": "exact", "hierarchy": False},
    environment={"coeffs": [[1.0, 1.0, 1.0], [0, 0.5, 0], *[[0, 0, 0]] * 7]},
    objects=[ground(),
             {"name": "cloud", "role": "blocker",
              "primitive": {"type": "box", "extents": [0.2, 0.2, 0.2], "subdivisions": 1,
                            "center": [0, 3, 0]},
              "blocker": {"capcloud": True, "half_angle_deg": 30}}])

HALF_ANGLE = math.radians(30)


class CapLog:
    """A LogBlocker: the log of a cap straight above every receiver."""

    def __init__(self, half_angle):
        self.half_angle = half_angle

    def log_visibility(self, points, normals, order):
        g = sh.cap(self.half_angle, [0.0, 1.0, 0.0], order)
        return np.broadcast_to(sh.log(g), (len(points), order * order)).astype(np.float32)


class CapCloud(blockers.BlockerKind):
    """A test kind: not a sphere set, options of its own, poses into a LogBlocker."""

    name, value, hint = "capcloud", "flag", "'capcloud = true'"

    def __init__(self):
        from typing import Annotated

        from pydantic import Field

        self.options = {"half_angle_deg": (Annotated[float, Field(gt=0, lt=90)], 10.0)}

    def prepare(self, spec, prep, ctx):
        prep.blocker_data = math.radians(spec.options["half_angle_deg"])

    def pose(self, prep, world, joints):
        return CapLog(prep.blocker_data)


class Constant(shadows.LightShadow):
    """A test way: each light adds a constant radiance."""

    name = "constant"

    def radiance(self, run, state, visibility, lights):
        return np.full((len(state.vertices), 3), 0.25 * len(lights))


@pytest.fixture
def registered(monkeypatch):
    monkeypatch.setitem(blockers.BLOCKER_KINDS, "capcloud", CapCloud())
    monkeypatch.setitem(shadows.LIGHT_SHADOWS, "constant", Constant())


def test_a_log_blocker_kind_bakes_through_the_runtime(registered, tmp_path):
    scene = parse_scene(SCENE, tmp_path / "scene.toml")
    assert scene.object("cloud").blocker.options == {"half_angle_deg": 30.0}
    (frame,) = bake_scene(scene, store_visibility=True, processes=1)
    # exact exp of the cap's log is the cap (closed form, sh.cap); the eigen-inversion
    # log and the exp round-trip in float32 at order 5 leave ~1e-4
    want = sh.cap(HALF_ANGLE, [0.0, 1.0, 0.0], 5)[:9]
    np.testing.assert_allclose(frame.visibility, np.broadcast_to(want, frame.visibility.shape),
                               atol=2e-4)


def test_unregistered_kind_is_an_unknown_key(tmp_path):
    from shtools.errors import InputError

    with pytest.raises(InputError, match=r"objects\[1\] \('cloud'\).blocker: unknown key "
                                         r"'capcloud'"):
        parse_scene(SCENE, tmp_path / "scene.toml")


def test_a_light_shadow_way_adds_its_radiance(registered, tmp_path):
    light = ('\n[[lights]]\nposition = [0, 2, 0]\nradius = 0.2\ncolor = [1, 1, 1]\n'
             'shadows = "constant"\n')
    scene = parse_scene(SCENE + light, tmp_path / "scene.toml")
    (with_light,) = bake_scene(scene, processes=1)
    (without,) = bake_scene(parse_scene(SCENE, tmp_path / "scene.toml"), processes=1)
    # the environment is shaded the same way; the constant way adds exactly 0.25
    # (float32 storage of the radiance)
    np.testing.assert_allclose(with_light.radiance, without.radiance + 0.25, atol=1e-6)


def test_runtime_sums_log_blockers_with_sphere_blockers():
    from shtools.runtime import SphereBlocker

    pts = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]])
    nrm = np.array([[0.0, 1.0, 0.0]] * 2)
    sphere = SphereBlocker([[2.0, 2.0, 0.0]], [0.5])
    settings = ShadowSettings(order=3, acc_order=5, exp_method="exact", hierarchy=False,
                              processes=1)
    assert isinstance(CapLog(HALF_ANGLE), LogBlocker)
    rt = ShadowRuntime(settings)
    both = rt.log_visibility(pts, nrm, [sphere, CapLog(HALF_ANGLE)])
    only_sphere = rt.log_visibility(pts, nrm, [sphere])
    cap_log = CapLog(HALF_ANGLE).log_visibility(pts, nrm, 5)
    # log space: the logs add (float32 sums)
    np.testing.assert_allclose(both, only_sphere + cap_log, atol=1e-6)
