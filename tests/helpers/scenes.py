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


def torus_and_ring(folder: Path, *, major: float, minor: float, sphere_radius: float,
                   plane: str = "xy", sections: tuple[int, int] = (16, 8), spheres: int = 8,
                   name: str = "ring.h5") -> None:
    """Write ``torus.obj`` (a trimesh torus about +z of ``sections`` = (major, minor)
    sections) and the sphere set ``name``: ``spheres`` spheres of ``sphere_radius``
    evenly on a circle of radius ``major`` about the origin in the ``plane`` (``"xy"``,
    the torus's own, or ``"xz"``)."""
    import numpy as np
    import trimesh

    from shtools.data_formats.spheres import write_spheres
    from shtools.geometry.sphere_set import SphereSet

    folder = Path(folder)
    trimesh.creation.torus(major_radius=major, minor_radius=minor, major_sections=sections[0],
                           minor_sections=sections[1]).export(folder / "torus.obj")
    phi = np.linspace(0.0, 2 * np.pi, spheres, endpoint=False)
    circle = {"xy": (np.cos(phi), np.sin(phi), np.zeros_like(phi)),
              "xz": (np.cos(phi), np.zeros_like(phi), np.sin(phi))}[plane]
    centers = major * np.stack(circle, axis=1)
    write_spheres(folder / name,
                  SphereSet(centers, np.full(spheres, sphere_radius), 0.0, 1.0, "ring"))


def bounded_torus(folder: Path) -> None:
    """Write ``torus.obj`` (major radius 0.6, tube 0.25, 32 x 16 sections) and its ring
    of 12 spheres ``torus_spheres.h5`` bounding the tube: radius hypot(0.25, 0.16), so
    they bulge about 0.05 out of it between the sections (spacing 2 * 0.6 sin(pi/12) =
    0.31), where a linked torus passes through."""
    import math

    torus_and_ring(folder, major=0.6, minor=0.25, sphere_radius=math.hypot(0.25, 0.16),
                   sections=(32, 16), spheres=12, name="torus_spheres.h5")
