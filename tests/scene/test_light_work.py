"""A frame computes only what some light uses: no environment and only lights shadowed
by ``ssoc`` or ``raytrace`` evaluate neither the SHEXP visibility nor the traced
shadows that feed it, and give the same radiance as a bake that does."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.scenes import torus_and_ring

from shtools.scene.bake import bake_scene
from shtools.scene.scene import parse_scene

ZERO_SKY = "[environment]\ncoeffs = [" + ", ".join(["[0.0, 0.0, 0.0]"] * 9) + "]\n"


def _scene(folder, shadows: str, environment: str = "", extra_light: str = ""):
    torus_and_ring(folder, major=0.5, minor=0.2, sphere_radius=0.3, plane="xz")
    text = f"""
[settings]
order = 3
frames = 2
fps = 2
{environment}
[[lights]]
name = "lamp"
position = [0.3, 2.5, 0.2]
radius = 0.1
color = [40.0, 40.0, 40.0]
shadows = "{shadows}"
samples = 16
{extra_light}
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [2.0, 2.0], subdivisions = 24 }}
role = "receiver"

[[objects]]
name = "torus"
mesh = "torus.obj"
role = "blocker"
blocker = {{ spheres = "ring.h5" }}
[[objects.keyframes]]
time = 0
translate = [0.0, 0.6, 0.0]
[[objects.keyframes]]
time = 1
translate = [0.2, 0.7, 0.0]
rotate = [20.0, 0.0, 0.0]
"""
    return parse_scene(text, folder / "scene.toml")


@pytest.fixture
def counts(monkeypatch):
    """Calls of the runtime's visibility and of the traced ground shadows."""
    import shtools.scene.traced_shadows as traced_shadows
    from shtools.runtime import ShadowRuntime

    calls = {"visibility": 0, "traced": 0}
    visibility, traced = ShadowRuntime.visibility, traced_shadows.traced_ground

    def counting_visibility(self, *args, **kwargs):
        calls["visibility"] += 1
        return visibility(self, *args, **kwargs)

    def counting_traced(*args, **kwargs):
        calls["traced"] += 1
        return traced(*args, **kwargs)

    monkeypatch.setattr(ShadowRuntime, "visibility", counting_visibility)
    monkeypatch.setattr(traced_shadows, "traced_ground", counting_traced)
    return calls


def _radiance(scene):
    return np.stack([f.radiance for f in bake_scene(scene, processes=1, workers=1)])


@pytest.mark.parametrize("shadows", ["ssoc", "raytrace"])
def test_a_small_light_alone_skips_the_visibility_and_keeps_the_radiance(
        tmp_path, counts, shadows):
    skipped = _radiance(_scene(tmp_path, shadows))
    assert counts == {"visibility": 0, "traced": 0}
    # the same scene under a black sky: the visibility (and the ground's traced shadow)
    # is evaluated every frame and shades to exactly zero, so the light's radiance is
    # all there is -- bit for bit the same as the bake that skipped it
    full = _radiance(_scene(tmp_path, shadows, environment=ZERO_SKY))
    assert counts["visibility"] == 2 and counts["traced"] == 2
    np.testing.assert_array_equal(skipped, full)
    assert skipped.max() > 0  # the lamp lights the ground, the torus shadows part of it
    assert (skipped[0, :, 0] < 0.5 * np.median(skipped[0, :, 0])).any()


def test_a_light_that_shades_through_the_visibility_still_gets_it(tmp_path, counts):
    second = '[[lights]]\nname = "sky"\nposition = [0.0, 3.0, 0.0]\nradius = 1.0\n' \
             'color = [1.0, 1.0, 1.0]\n'  # shexp: through the SH visibility
    _radiance(_scene(tmp_path, "ssoc", extra_light=second))
    assert counts["visibility"] == 2 and counts["traced"] == 2


def test_stored_visibility_is_still_evaluated(tmp_path, counts):
    frames = list(bake_scene(_scene(tmp_path, "ssoc"), processes=1, workers=1,
                             store_visibility=True))
    assert counts["visibility"] == 2
    assert all(f.visibility is not None and np.abs(f.visibility).max() > 0 for f in frames)
