"""Scenes: TOML files parsed into dataclasses, animation, and the baker.

- :mod:`shtools.scene.scene` — ``load_scene(path) -> Scene`` (validation, errors),
  into the data classes of :mod:`shtools.scene.specs`;
- :mod:`shtools.scene.kinds` — the complete registries of blocker kinds, visibility
  methods and light-shadow ways (protocols in :mod:`shtools.scene.blockers` and
  :mod:`shtools.scene.shadows`);
- :mod:`shtools.scene.primitives` — procedural meshes (plane, sphere, box, capsule, cylinder);
- :mod:`shtools.scene.animation` — keyframes (lerp/slerp), parent chains, skinning;
- :mod:`shtools.scene.bake` — ``prepare_scene``, ``pose_frame``, ``bake_scene`` (a
  generator of per-frame results that streams the ``bake`` asset), ``bake_to_file``.

See ``docs/scenes.md``.
"""

from shtools.scene.scene import Scene, load_scene, parse_scene

__all__ = ["Scene", "load_scene", "parse_scene"]
