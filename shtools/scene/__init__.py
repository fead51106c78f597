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

__all__ = ["Scene", "load_scene", "parse_scene"]


def __getattr__(name: str):
    # on first use: the parser imports pydantic and every registered kind, which a
    # module of this package that reads no scene (``relight`` without lights) needs not
    if name in __all__:
        from shtools.scene import scene

        return getattr(scene, name)
    raise AttributeError(f"module 'shtools.scene' has no attribute {name!r}")
