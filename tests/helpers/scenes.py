"""Scene files written from Python dicts, in the layout of docs/scenes.md.

A scene is a dict of its tables, e.g.::

    write_scene(folder / "scene.toml", settings={"order": 3},
                environment={"light": "sky.h5"},
                objects=[ground(size=2, subdivisions=2)])

``None`` values are left out, so a test can switch a key off by passing ``None``.
"""

from __future__ import annotations

from pathlib import Path

import tomli_w


def _drop_none(value):
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_drop_none(v) for v in value]
    return value


def scene_text(**tables) -> str:
    """TOML text of a scene with the given top-level tables (``settings``,
    ``environment``, ``objects``, ``lights``, ...)."""
    return tomli_w.dumps(_drop_none(tables))


def write_scene(path: Path, **tables) -> Path:
    """Write :func:`scene_text` of ``tables`` to ``path``; returns ``path``."""
    path = Path(path)
    path.write_text(scene_text(**tables))
    return path


def ground(name: str = "ground", *, size: float = 2.0, subdivisions: int = 2,
           role: str = "receiver", **keys) -> dict:
    """A square plane primitive object (``size`` x ``size``), receiver only by default."""
    return {"name": name, "role": role,
            "primitive": {"type": "plane", "size": [size, size],
                          "subdivisions": subdivisions}, **keys}
