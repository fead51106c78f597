"""A light asset records its window; the bake refuses to window it a second time."""

from __future__ import annotations

import math

import numpy as np
from helpers.scenes import ground, write_scene

from shtools.data_formats.light import write_light


def _scene(folder, window=None):
    """A ground under the light sky.h5, order 2, with ``window`` set or not."""
    return write_scene(folder / "scene.toml", settings={"order": 2, "window": window},
                       environment={"light": "sky.h5"}, objects=[ground()])


def _sky(path, window):
    coeffs = np.zeros((4, 3))
    coeffs[0] = math.sqrt(4 * math.pi)
    write_light(path, coeffs, source="image", parameters={"order": 2, "window": window})


def test_windowed_light_with_a_windowing_scene_is_refused(run_cli, tmp_path):
    _sky(tmp_path / "sky.h5", "cosine")
    _scene(tmp_path)
    out = tmp_path / "b.h5"
    code, _, stderr = run_cli("bake", tmp_path / "scene.toml", "-o", out)
    assert code == 1 and stderr.count("\n") == 1, stderr
    # names both windows and both ways out
    assert "--window cosine" in stderr and "settings.window is 'cosine'" in stderr
    assert "without --window" in stderr and 'window = "none"' in stderr
    assert not out.exists()


def test_unwindowed_light_or_unwindowed_scene_bakes(run_cli, tmp_path):
    _sky(tmp_path / "sky.h5", "none")
    _scene(tmp_path)
    code, _, stderr = run_cli("bake", tmp_path / "scene.toml", "-o", tmp_path / "a.h5")
    assert code == 0, stderr
    _sky(tmp_path / "sky.h5", "cosine")
    _scene(tmp_path, "none")
    code, _, stderr = run_cli("bake", tmp_path / "scene.toml", "-o", tmp_path / "b.h5")
    assert code == 0, stderr
