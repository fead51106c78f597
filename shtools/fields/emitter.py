r"""A local light's geometry and emission: the input of a source radiance field.

A lamp is a **closed emitter mesh** (the bulb, the glowing part) of uniform RGB
radiance, emitted from its outside (the side its faces' normals point to),
plus an optional opaque, non-emissive **fixture** (a lampshade, a base) that
blocks part of it.  Closed, because "outside" must mean something: an open
emitter (a lone quad) has no inside, and whether its back emits is a guess.

Emission is given as a small TOML table (``--radiance EMISSION``)::

    radiance = [12.0, 10.0, 8.0]      # RGB radiance of the emitter's surface
    fixture = ["shade.obj"]           # optional: opaque meshes, relative to the table

A table rather than glTF ``emissiveFactor``: radiance is in the scene's units
and unbounded (``emissiveFactor`` is clamped to [0, 1] and needs the
``KHR_materials_emissive_strength`` extension for anything brighter), it works
for every mesh format :func:`shtools.geometry.mesh.load_mesh` reads, and each
part keeps that function's validation (per-face material groups do not
survive its merging and cleaning).

:func:`emitted_radiance` is the incoming radiance at points along directions:
the emitter's radiance where the nearest hit is an emitter face seen from its
front, zero elsewhere (the fixture, the emitter's back, nothing).
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.runtime.settings import MAX_RADIANCE

#: Keys of an emission table.
EMISSION_KEYS = ("radiance", "fixture")


@dataclass
class Emitter:
    """A lamp: triangles, which are emissive, and their radiance.

    Attributes
    ----------
    vertices : ndarray, shape (P, 3)
    faces : ndarray, shape (F, 3)
        Emitter faces first, then the fixture's.
    emissive : ndarray of bool, shape (F,)
    radiance : ndarray, shape (3,)
        RGB radiance of the emitter's outside.
    normals : ndarray, shape (F, 3)
        Unit face normals (outward on the emitter).
    areas : ndarray, shape (F,)
    """

    vertices: np.ndarray
    faces: np.ndarray
    emissive: np.ndarray
    radiance: np.ndarray
    normals: np.ndarray
    areas: np.ndarray

    @property
    def emitter_faces(self) -> np.ndarray:
        """Indices of the emissive faces, shape (E,)."""
        return np.flatnonzero(self.emissive)

    def power(self) -> float:
        """Emitted flux per unit radiance summed over channels: ``pi * area * sum(L)``."""
        return float(math.pi * self.areas[self.emissive].sum() * self.radiance.sum())


def _radiance_value(value, path) -> np.ndarray:
    ok = (isinstance(value, list) and len(value) == 3
          and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value))
    if not ok:
        raise InputError("'radiance' must be three numbers [r, g, b]", path)
    rad = np.asarray(value, dtype=np.float64)
    if not np.isfinite(rad).all() or (rad < 0).any() or (rad > MAX_RADIANCE).any():
        raise InputError(f"'radiance' must be finite, >= 0 and <= {MAX_RADIANCE:g} in every "
                         "channel", path)
    if not rad.max() > 0:
        raise InputError("'radiance' is zero: the lamp emits nothing; give the emitter's "
                         "RGB radiance, e.g. radiance = [10, 9, 8]", path)
    return rad


def read_emission(path: str | os.PathLike) -> tuple[np.ndarray, list[Path]]:
    """Read an emission table.

    Returns
    -------
    radiance : ndarray, shape (3,)
    fixture : list of Path
        Fixture meshes, resolved against the table's folder.

    Raises
    ------
    InputError
        Missing or unparsable file, unknown key, zero or negative radiance.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("emission table not found; give a TOML file with "
                         "radiance = [r, g, b]", path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not a valid TOML table ({' '.join(str(exc).split())[:100]})",
                         path) from None
    for key in table:
        if key not in EMISSION_KEYS:
            raise InputError(f"unknown key '{key}'; allowed: {', '.join(EMISSION_KEYS)}", path)
    if "radiance" not in table:
        raise InputError("missing key 'radiance' (the emitter's RGB radiance)", path)
    rad = _radiance_value(table["radiance"], path)
    fixture = table.get("fixture", [])
    if isinstance(fixture, str):
        fixture = [fixture]
    if not isinstance(fixture, list) or not all(isinstance(f, str) and f for f in fixture):
        raise InputError("'fixture' must be a mesh path or a list of mesh paths", path)
    return rad, [path.parent / f for f in fixture]


def make_emitter(emitter_mesh, radiance, fixture=(), *, path=None) -> Emitter:
    """Assemble an :class:`Emitter` from a closed emitter mesh and fixture meshes.

    Parameters
    ----------
    emitter_mesh : trimesh.Trimesh
        Closed, outward-facing.
    radiance : array_like, shape (3,)
    fixture : sequence of trimesh.Trimesh
    path : path-like, optional
        Named in errors about the emitter mesh.

    Raises
    ------
    InputError
        Zero emission, an open emitter, an inward-facing emitter.
    """
    from shtools.geometry.mesh import boundary_edges

    rad = _radiance_value([float(x) for x in np.ravel(np.asarray(radiance, dtype=float))],
                          path)
    n_open = len(boundary_edges(emitter_mesh))
    if n_open:
        raise InputError(f"the emitter is open ({n_open} boundary edges): emission is defined "
                         "on the outside of a closed surface; close its holes, or give the "
                         "open part as a 'fixture' and a closed bulb as the emitter", path)
    if not emitter_mesh.volume > 0:
        raise InputError("the emitter's faces point inward (negative volume); flip them so "
                         "that the normals point to where it emits", path)
    parts = [emitter_mesh, *fixture]
    vertices, faces, base = [], [], 0
    for mesh in parts:
        vertices.append(np.asarray(mesh.vertices, dtype=np.float64))
        faces.append(np.asarray(mesh.faces, dtype=np.int64) + base)
        base += len(mesh.vertices)
    v = np.concatenate(vertices)
    f = np.concatenate(faces)
    emissive = np.zeros(len(f), dtype=bool)
    emissive[:len(emitter_mesh.faces)] = True
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    norm = np.linalg.norm(cross, axis=1)
    return Emitter(v, f, emissive, rad, cross / np.maximum(norm, 1e-300)[:, None], 0.5 * norm)


def load_emitter(mesh_path, emission_path) -> Emitter:
    """Read the emitter mesh and its emission table (``shtools field sample --radiance``)."""
    from shtools.geometry.mesh import load_mesh

    rad, fixture = read_emission(emission_path)
    mesh = load_mesh(mesh_path)
    return make_emitter(mesh, rad, [load_mesh(p) for p in fixture], path=mesh_path)


def emitted_radiance(caster, emitter: Emitter, origins, directions) -> np.ndarray:
    """Incoming radiance along rays, shape ``(R, 3)``.

    Parameters
    ----------
    caster : shtools.geometry.raycast.RayCaster
        Over ``emitter.vertices`` / ``emitter.faces``.
    emitter : Emitter
    origins, directions : array_like, shape (R, 3)
        Unit directions.

    Returns
    -------
    ndarray, shape (R, 3)
        ``emitter.radiance`` where the nearest hit is an emitter face hit from
        its front, else 0.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    _, face = caster.first_hit(origins, d)
    lit = face >= 0
    lit[lit] = emitter.emissive[face[lit]]
    lit[lit] = np.einsum("ij,ij->i", emitter.normals[face[lit]], d[lit]) < 0
    return lit[:, None] * emitter.radiance[None, :]
