"""Scenes baked in memory, for tests that compare the radiance of several bakes."""

from __future__ import annotations

import numpy as np


def baked_radiance(scene, **kwargs) -> np.ndarray:
    """The radiance ``(F, V, 3)`` of every frame of ``scene`` (a loaded scene), baked
    in this process (``processes=1``); ``kwargs`` go to
    :func:`shtools.scene.bake.bake_scene`."""
    from shtools.scene.bake import bake_scene, prepare_scene

    prepared = prepare_scene(scene)
    return np.stack([f.radiance for f in bake_scene(scene, prepared=prepared, processes=1,
                                                    **kwargs)])
