"""Procedural meshes a scene can name instead of a mesh file (Y is up).

Every primitive is centred on its ``center`` parameter (default the origin) and
returns a :class:`Primitive`: the triangle mesh and, where the solid is exactly a
union of spheres (``sphere``), those spheres, so a scene needs no fitted set for it.

==========  ===========================================================  ==============
type        parameters (defaults)                                        vertices
==========  ===========================================================  ==============
plane       ``size=[10, 10]`` (x, z), ``subdivisions=64`` cells per side  (s+1)^2, +Y up
sphere      ``radius=0.5``, ``subdivisions=3`` (icosphere)               10*4^s+2
box         ``extents=[1, 1, 1]``, ``subdivisions=8`` cells per edge      6*(s+1)^2
capsule     ``radius=0.25``, ``length=1.0`` (cylinder part, along Y),     ~ count^2
            ``count=24``
cylinder    ``radius=0.25``, ``height=1.0`` (along Y), ``sections=32``,   4*sections*(s+1)
            ``subdivisions=4`` rings
==========  ===========================================================  ==============
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from shtools.errors import InputError

if TYPE_CHECKING:  # imported where a mesh is made: parsing a scene needs only the tables
    import trimesh

#: primitive type -> {parameter: default}
PRIMITIVES: dict[str, dict] = {
    "plane": {"size": [10.0, 10.0], "subdivisions": 64, "center": [0.0, 0.0, 0.0]},
    "sphere": {"radius": 0.5, "subdivisions": 3, "center": [0.0, 0.0, 0.0]},
    "box": {"extents": [1.0, 1.0, 1.0], "subdivisions": 8, "center": [0.0, 0.0, 0.0]},
    "capsule": {"radius": 0.25, "length": 1.0, "count": 24, "center": [0.0, 0.0, 0.0]},
    "cylinder": {"radius": 0.25, "height": 1.0, "sections": 32, "subdivisions": 4,
                 "center": [0.0, 0.0, 0.0]},
}


#: Smallest integer of each integer parameter (default 1).
INT_MINIMUM = {("sphere", "subdivisions"): 0, ("capsule", "count"): 4,
               ("cylinder", "sections"): 3}
#: Most vertices a primitive may have: a 2000 x 2000 plane.  Per baked frame every
#: receiver vertex costs ~100 bytes of working memory and 12-24 bytes of output.
MAX_PRIMITIVE_VERTICES = 4_000_000


def vertex_count(kind: str, p: dict) -> int:
    """Vertices the primitive ``kind`` with full parameters ``p`` will have (table above)."""
    if kind == "plane":
        return (p["subdivisions"] + 1) ** 2
    if kind == "sphere":
        return 10 * 4 ** min(p["subdivisions"], 64) + 2
    if kind == "box":
        return 6 * (p["subdivisions"] + 1) ** 2
    if kind == "capsule":
        return p["count"] ** 2
    return 4 * p["sections"] * (p["subdivisions"] + 1)


def check_parameters(kind: str, params: dict) -> dict:
    """Check the parameters of a primitive and its size; the full parameter set.

    Each parameter takes the type of its default: a list of that many finite
    numbers (positive, except ``center``), an integer at least its minimum
    (:data:`INT_MINIMUM`, else 1), or a positive finite number.  The vertex count
    (:func:`vertex_count`) must stay within :data:`MAX_PRIMITIVE_VERTICES`.

    Raises
    ------
    InputError
        The message starts with the parameter name (the scene parser adds the
        file and the TOML path).
    """
    import math

    p = dict(PRIMITIVES[kind])
    for key, value in params.items():
        default = p[key]
        if isinstance(default, list):
            n = len(default)
            if (not isinstance(value, list) or len(value) != n
                    or not all(isinstance(x, int | float) and not isinstance(x, bool)
                               for x in value)):
                raise InputError(f"'{key}' must be a list of {n} numbers, got {value!r}")
            if not all(math.isfinite(x) for x in value):
                raise InputError(f"'{key}' must be finite, got {value!r}")
            if key != "center" and any(x <= 0 for x in value):
                raise InputError(f"'{key}' must be positive, got {value!r}")
        elif isinstance(default, int):
            lo = INT_MINIMUM.get((kind, key), 1)
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise InputError(f"'{key}' must be an integer >= {lo}, got {value!r}")
        elif (isinstance(value, bool) or not isinstance(value, int | float)
              or not math.isfinite(value) or value <= 0):
            raise InputError(f"'{key}' must be a positive number, got {value!r}")
        p[key] = value
    count = vertex_count(kind, p)
    if count > MAX_PRIMITIVE_VERTICES:
        raise InputError(f"'{kind}' with these parameters would have {count:,} vertices, above "
                         f"the limit of {MAX_PRIMITIVE_VERTICES:,}; lower the subdivisions "
                         "(or use a mesh file)")
    return p


@dataclass
class Primitive:
    """A generated mesh with its vertex normals and, if exact, its sphere set.

    Attributes
    ----------
    mesh : trimesh.Trimesh
    normals : ndarray, shape (V, 3)
        Unit vertex normals (analytic where the shape has them).
    spheres : tuple of (centers (N,3), radii (N,)) or None
        Exact sphere representation of the solid (only ``sphere``).
    """

    mesh: trimesh.Trimesh
    normals: np.ndarray
    spheres: tuple[np.ndarray, np.ndarray] | None = None


def _grid(u_axis, v_axis, origin, nu, nv, normal):
    """A (nu+1) x (nv+1) vertex grid spanning origin + [0,1]u + [0,1]v."""
    s = np.linspace(0.0, 1.0, nu + 1)
    t = np.linspace(0.0, 1.0, nv + 1)
    ss, tt = np.meshgrid(s, t, indexing="ij")
    verts = origin + ss[..., None] * u_axis + tt[..., None] * v_axis
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])
    # orient faces so their normal matches `normal`
    v = verts.reshape(-1, 3)
    n_face = np.cross(v[faces[0, 1]] - v[faces[0, 0]], v[faces[0, 2]] - v[faces[0, 0]])
    if np.dot(n_face, normal) < 0:
        faces = faces[:, ::-1]
    return v, faces, np.broadcast_to(np.asarray(normal, float), v.shape).copy()


def _positive_int(name, value, lo=1):
    if not isinstance(value, int) or isinstance(value, bool) or value < lo:
        raise InputError(f"primitive parameter '{name}' must be an integer >= {lo}, got {value!r}")
    return value


def _positive(name, value):
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise InputError(f"primitive parameter '{name}' must be positive, got {value!r}")
    return arr


def make_primitive(kind: str, params: dict) -> Primitive:
    """Build the primitive ``kind`` with ``params`` (missing ones take defaults).

    Raises
    ------
    InputError
        Unknown type or parameter, or a non-positive size.
    """
    import difflib

    import trimesh

    if kind not in PRIMITIVES:
        close = difflib.get_close_matches(kind, PRIMITIVES, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        raise InputError(f"unknown primitive type '{kind}'; {hint}known: {', '.join(PRIMITIVES)}")
    for key in params:
        if key not in PRIMITIVES[kind]:
            close = difflib.get_close_matches(key, PRIMITIVES[kind], n=1)
            hint = (f"; did you mean '{close[0]}'?" if close
                    else f"; known: {', '.join(PRIMITIVES[kind])}")
            raise InputError(f"unknown parameter '{key}' for primitive '{kind}'{hint}")
    p = check_parameters(kind, params)
    center = np.asarray(p["center"], dtype=float).reshape(3)
    spheres = None
    if kind == "plane":
        sx, sz = _positive("size", p["size"]).reshape(2)
        n = _positive_int("subdivisions", p["subdivisions"])
        v, f, nrm = _grid(np.array([sx, 0, 0]), np.array([0, 0, sz]),
                          np.array([-sx / 2, 0, -sz / 2]), n, n, [0.0, 1.0, 0.0])
    elif kind == "sphere":
        r = float(_positive("radius", p["radius"]))
        s = _positive_int("subdivisions", p["subdivisions"], lo=0)
        m = trimesh.creation.icosphere(subdivisions=s, radius=r)
        v, f = np.asarray(m.vertices), np.asarray(m.faces)
        nrm = v / np.linalg.norm(v, axis=1, keepdims=True)
        spheres = (center[None, :].copy(), np.array([r]))
    elif kind == "box":
        ext = _positive("extents", p["extents"]).reshape(3)
        n = _positive_int("subdivisions", p["subdivisions"])
        parts = []
        h = ext / 2
        for axis in range(3):
            u, w = (axis + 1) % 3, (axis + 2) % 3
            for sign in (-1.0, 1.0):
                normal = np.zeros(3)
                normal[axis] = sign
                origin = np.zeros(3)
                origin[axis] = sign * h[axis]
                origin[u], origin[w] = -h[u], -h[w]
                eu, ew = np.zeros(3), np.zeros(3)
                eu[u], ew[w] = ext[u], ext[w]
                parts.append(_grid(eu, ew, origin, n, n, normal))
        v, f, nrm = _concat(parts)
    elif kind == "capsule":
        r = float(_positive("radius", p["radius"]))
        length = float(_positive("length", p["length"]))
        count = _positive_int("count", p["count"], lo=4)
        m = trimesh.creation.capsule(height=length, radius=r, count=[count, count])
        # trimesh's capsule runs along Z with its cylinder centred at the origin
        v = np.asarray(m.vertices)[:, [0, 2, 1]] * np.array([1, 1, -1])
        f = np.asarray(m.faces)
        axis_point = np.zeros_like(v)
        axis_point[:, 1] = np.clip(v[:, 1], -length / 2, length / 2)
        nrm = v - axis_point
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    else:  # cylinder
        r = float(_positive("radius", p["radius"]))
        height = float(_positive("height", p["height"]))
        sections = _positive_int("sections", p["sections"], lo=3)
        rings = _positive_int("subdivisions", p["subdivisions"])
        v, f, nrm = _cylinder(r, height, sections, rings)
    v = np.asarray(v, dtype=float) + center
    mesh = trimesh.Trimesh(v, np.asarray(f, dtype=np.int64), process=False)
    if kind != "plane" and mesh.volume < 0:
        mesh.invert()
    return Primitive(mesh, np.asarray(nrm, dtype=float), spheres)


def _concat(parts):
    verts, faces, normals, offset = [], [], [], 0
    for v, f, n in parts:
        verts.append(v)
        faces.append(f + offset)
        normals.append(n)
        offset += len(v)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(normals)


def _cylinder(r, height, sections, rings):
    """Open side grid plus two fan-free capped disks, each with its own normals."""
    phi = np.linspace(0, 2 * np.pi, sections + 1)
    y = np.linspace(-height / 2, height / 2, rings + 1)
    pp, yy = np.meshgrid(phi, y, indexing="ij")
    side = np.stack([r * np.cos(pp), yy, -r * np.sin(pp)], -1).reshape(-1, 3)
    side_n = np.stack([np.cos(pp), 0 * pp, -np.sin(pp)], -1).reshape(-1, 3)
    idx = np.arange(len(side)).reshape(sections + 1, rings + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    side_f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    parts = [(side, side_f, side_n)]
    ang = phi[:-1]
    for sign in (-1.0, 1.0):
        ring = np.stack([r * np.cos(ang), np.full_like(ang, sign * height / 2), -r * np.sin(ang)],
                        -1)
        verts = np.concatenate([[[0.0, sign * height / 2, 0.0]], ring])
        k = np.arange(sections)
        faces = np.stack([np.zeros(sections, int), 1 + k, 1 + (k + 1) % sections], 1)
        if sign < 0:
            faces = faces[:, ::-1]
        parts.append((verts, faces, np.tile([0.0, sign, 0.0], (len(verts), 1))))
    return _concat(parts)
