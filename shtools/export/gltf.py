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
#: glTF accessor component types of the NumPy dtypes the exports write
COMPONENT_TYPES = {np.dtype(np.int16): 5122, np.dtype(np.uint16): 5123,
                   np.dtype(np.uint32): _UINT32, np.dtype(np.float32): _FLOAT}
_KINDS = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


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

    def view(self, data: bytes, target: int | None = None, stride: int | None = None) -> int:
        """Append ``data`` as a buffer view (4-byte aligned); returns its index."""
        self.views.append(pygltflib.BufferView(buffer=0, byteOffset=len(self.blob),
                                               byteLength=len(data), target=target,
                                               byteStride=stride))
        self.blob += data + b"\0" * (-len(data) % 4)
        return len(self.views) - 1

    def add(self, arr: np.ndarray, *, kind: str, target: int | None, bounds: bool = False,
            normalized: bool = False) -> int:
        """Append ``arr`` (rows = elements) as a tightly packed accessor; returns its index.

        Rows of 2-byte components whose size is not a multiple of 4 are padded
        to the next one (a byte stride): glTF aligns every vertex attribute
        element to 4 bytes.
        """
        arr = np.ascontiguousarray(arr)
        flat = arr.reshape(len(arr), -1)
        stride = None
        if target == _ARRAY_BUFFER and flat.shape[1] * arr.itemsize % 4:
            width = -(-flat.shape[1] * arr.itemsize // 4) * 4 // arr.itemsize
            padded = np.zeros((len(flat), width), arr.dtype)
            padded[:, :flat.shape[1]] = flat
            flat, stride = padded, width * arr.itemsize
        comp = COMPONENT_TYPES[arr.dtype]
        acc = pygltflib.Accessor(bufferView=self.view(flat.tobytes(), target, stride),
                                 componentType=comp, count=len(arr), type=kind,
                                 normalized=normalized)
        if bounds and len(arr):
            values = arr.reshape(len(arr), -1)
            cast = float if comp == _FLOAT else int
            acc.min = [cast(x) for x in values.min(axis=0)]
            acc.max = [cast(x) for x in values.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def add_sparse(self, count: int, indices: np.ndarray, values: np.ndarray, *,
                   bounds: bool = False) -> int:
        """A float32 accessor of ``count`` rows, zero except ``values`` at ``indices``.

        No ``indices`` (an empty array): an accessor without data, all zeros.
        ``values`` has shape ``(n, C)``; ``indices`` (n,) strictly increasing.
        """
        values = np.ascontiguousarray(values, dtype=np.float32)
        # no byteOffset either: it needs a bufferView
        acc = pygltflib.Accessor(componentType=_FLOAT, count=count, byteOffset=None,
                                 type=_KINDS[values.shape[1]])
        if len(indices):
            index_type = np.uint16 if count <= 65535 else np.uint32
            acc.sparse = pygltflib.Sparse(
                count=len(indices),
                indices=pygltflib.AccessorSparseIndices(
                    bufferView=self.view(np.asarray(indices, index_type).tobytes()),
                    componentType=COMPONENT_TYPES[np.dtype(index_type)]),
                values=pygltflib.AccessorSparseValues(bufferView=self.view(values.tobytes())))
        if bounds:
            lo = values.min(axis=0) if len(indices) else np.zeros(values.shape[1])
            hi = values.max(axis=0) if len(indices) else np.zeros(values.shape[1])
            if len(indices) < count:  # the rows not listed are zeros
                lo, hi = np.minimum(lo, 0.0), np.maximum(hi, 0.0)
            acc.min, acc.max = [float(x) for x in lo], [float(x) for x in hi]
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
    save_glb(path, buf, nodes, meshes, extras)


def save_glb(path: str | os.PathLike, buf: _Buffer, nodes: list, meshes: list,
             extras: dict | None = None, animations: list | None = None) -> None:
    """Assemble one scene of ``nodes`` (all roots) with the unlit material; write atomically."""
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
    if animations:
        gltf.animations = animations
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
