"""Vertex-coloured binary glTF (GLB) of one baked frame: one named node and mesh per object.

Each receiver object of the bake becomes a node and a mesh named after it (the
scene's object names), with one triangle primitive whose attributes are:

* ``POSITION``, ``NORMAL`` (float32, world space: the nodes carry no transform);
* ``COLOR_0`` (float32 RGB): the display colour.  glTF defines vertex colours
  as *linear* and viewers sRGB-encode on output, so ``COLOR_0`` holds the
  tone-mapped value before sRGB encoding; what the viewer shows equals the PLY
  and PNG exports;
* ``_RADIANCE`` / ``_IRRADIANCE`` (float32 VEC3) or ``_VISIBILITY`` (float32
  SCALAR): the raw exported quantity, before albedo (application-specific
  attributes start with ``_`` in glTF 2.0);
* ``TEXCOORD_1`` (optional, float32 VEC2): the vertex-animation-texture
  coordinates (:mod:`shtools.export.vat`); glTF needs a first UV set before a
  second, so ``TEXCOORD_0`` then refers to the same data.

The material is unlit (``KHR_materials_unlit``) so viewers do not light the
already-lit colours a second time.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import pygltflib

from shtools.data_formats import atomic_path

_FLOAT, _UINT32 = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
UNLIT = "KHR_materials_unlit"


@dataclass
class GlbObject:
    """One object of a GLB.

    Attributes
    ----------
    name : str
    vertices, normals : ndarray, shape (V, 3)
    faces : ndarray, shape (F, 3)
        Indices into this object's vertices.
    colors_linear : ndarray, shape (V, 3)
        Display colours in [0, 1], linear (not sRGB-encoded).
    raw : ndarray, shape (V, 3) or (V,)
        The raw exported quantity.
    raw_name : str
        Its attribute name, e.g. ``"_RADIANCE"``.
    uv1 : ndarray, shape (V, 2), optional
        ``TEXCOORD_1`` (vertex animation texture lookup).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    colors_linear: np.ndarray
    normals: np.ndarray
    raw: np.ndarray
    raw_name: str = "_RADIANCE"
    uv1: np.ndarray | None = None


class _Buffer:
    """Accumulates the binary chunk, buffer views and accessors of a GLB."""

    def __init__(self):
        self.blob = bytearray()
        self.views: list = []
        self.accessors: list = []

    def add(self, arr: np.ndarray, *, kind: str, target: int, bounds: bool = False) -> int:
        data = np.ascontiguousarray(arr).tobytes()
        self.views.append(pygltflib.BufferView(buffer=0, byteOffset=len(self.blob),
                                               byteLength=len(data), target=target))
        self.blob += data + b"\0" * (-len(data) % 4)  # 4-byte alignment
        comp = _UINT32 if arr.dtype == np.uint32 else _FLOAT
        acc = pygltflib.Accessor(bufferView=len(self.views) - 1, componentType=comp,
                                 count=len(arr), type=kind)
        if bounds and len(arr):
            flat = arr.reshape(len(arr), -1)
            lo, hi = flat.min(axis=0), flat.max(axis=0)
            cast = int if comp == _UINT32 else float
            acc.min = [cast(x) for x in lo]
            acc.max = [cast(x) for x in hi]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def write_glb_objects(path: str | os.PathLike, objects: list[GlbObject],
                      extras: dict | None = None) -> None:
    """Write a GLB with one named node + mesh per object, atomically.

    ``extras`` (JSON-able) goes into ``asset.extras``.
    """
    buf = _Buffer()
    nodes, meshes = [], []
    for k, obj in enumerate(objects):
        attrs = pygltflib.Attributes(
            POSITION=buf.add(np.asarray(obj.vertices, np.float32), kind="VEC3",
                             target=_ARRAY_BUFFER, bounds=True),
            NORMAL=buf.add(np.asarray(obj.normals, np.float32), kind="VEC3",
                           target=_ARRAY_BUFFER),
            COLOR_0=buf.add(np.clip(np.asarray(obj.colors_linear, np.float32), 0, 1),
                            kind="VEC3", target=_ARRAY_BUFFER),
        )
        if obj.uv1 is not None:
            # glTF numbers UV sets without gaps: the first set repeats the second
            attrs.TEXCOORD_0 = attrs.TEXCOORD_1 = buf.add(
                np.asarray(obj.uv1, np.float32), kind="VEC2", target=_ARRAY_BUFFER)
        raw = np.asarray(obj.raw, np.float32)
        setattr(attrs, obj.raw_name, buf.add(raw, kind="VEC3" if raw.ndim == 2 else "SCALAR",
                                             target=_ARRAY_BUFFER))
        indices = buf.add(np.asarray(obj.faces, np.uint32).reshape(-1), kind="SCALAR",
                          target=_ELEMENT_ARRAY_BUFFER, bounds=True)
        meshes.append(pygltflib.Mesh(name=obj.name, primitives=[pygltflib.Primitive(
            attributes=attrs, indices=indices, material=0)]))
        nodes.append(pygltflib.Node(mesh=k, name=obj.name))
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(generator="shtools export", version="2.0", extras=extras or {}),
        scene=0,
        scenes=[pygltflib.Scene(nodes=list(range(len(nodes))))],
        nodes=nodes,
        meshes=meshes,
        materials=[_unlit_material()],
        extensionsUsed=[UNLIT],
        accessors=buf.accessors,
        bufferViews=buf.views,
        buffers=[pygltflib.Buffer(byteLength=len(buf.blob))],
    )
    gltf.set_binary_blob(bytes(buf.blob))
    with atomic_path(path) as tmp:
        gltf.save_binary(str(tmp))


def _unlit_material() -> pygltflib.Material:
    return pygltflib.Material(
        name="baked_radiance",
        pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
            baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=1.0),
        extensions={UNLIT: {}},
    )


def write_glb(
    path: str | os.PathLike,
    vertices: np.ndarray,
    faces: np.ndarray,
    colors_linear: np.ndarray,
    normals: np.ndarray,
    radiance: np.ndarray,
    *,
    name: str = "baked",
) -> None:
    """Write one object as a GLB with ``COLOR_0`` and ``_RADIANCE`` (see the module doc).

    Parameters
    ----------
    vertices, normals : ndarray, shape (V, 3)
    faces : ndarray, shape (F, 3)
    colors_linear : ndarray, shape (V, 3)
        Tone-mapped display colours in [0, 1], linear (not sRGB-encoded).
    radiance : ndarray, shape (V, 3)
        Raw linear radiance.
    """
    write_glb_objects(path, [GlbObject(name, vertices, faces, colors_linear, normals,
                                       radiance)])
