"""Vertex-coloured binary glTF (GLB) of one baked frame, with the raw radiance kept.

Attributes of the one mesh primitive:

* ``POSITION``, ``NORMAL`` (float32);
* ``COLOR_0`` (float32 RGB): the tone-mapped colour.  glTF defines vertex colours
  as *linear* and viewers sRGB-encode on output, so ``COLOR_0`` holds the
  tone-mapped value before sRGB encoding; what the viewer shows equals the PLY
  and PNG exports;
* ``_RADIANCE`` (float32 RGB): the baked linear outgoing radiance, untouched
  (application-specific attributes start with ``_`` in glTF 2.0).

The material is unlit (``KHR_materials_unlit``) so viewers do not light the
already-lit colours a second time.
"""

from __future__ import annotations

import os

import numpy as np
import pygltflib

from shtools.data_formats import atomic_path

_FLOAT, _UINT32 = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
UNLIT = "KHR_materials_unlit"


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
    """Write a GLB with vertex colours and a ``_RADIANCE`` attribute, atomically.

    Parameters
    ----------
    vertices, normals : ndarray, shape (V, 3)
    faces : ndarray, shape (F, 3)
    colors_linear : ndarray, shape (V, 3)
        Tone-mapped display colours in [0, 1], linear (not sRGB-encoded).
    radiance : ndarray, shape (V, 3)
        Raw linear radiance.
    """
    arrays = [
        ("POSITION", np.asarray(vertices, np.float32), _ARRAY_BUFFER),
        ("NORMAL", np.asarray(normals, np.float32), _ARRAY_BUFFER),
        ("COLOR_0", np.clip(np.asarray(colors_linear, np.float32), 0, 1), _ARRAY_BUFFER),
        ("_RADIANCE", np.asarray(radiance, np.float32), _ARRAY_BUFFER),
        ("indices", np.asarray(faces, np.uint32).reshape(-1), _ELEMENT_ARRAY_BUFFER),
    ]
    blob = bytearray()
    views, accessors, attributes = [], [], {}
    for k, (key, arr, target) in enumerate(arrays):
        data = np.ascontiguousarray(arr).tobytes()
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data),
                                          target=target))
        blob += data + b"\0" * (-len(data) % 4)  # 4-byte alignment
        if key == "indices":
            acc = pygltflib.Accessor(bufferView=k, componentType=_UINT32, count=arr.size,
                                     type="SCALAR", min=[int(arr.min())] if arr.size else [0],
                                     max=[int(arr.max())] if arr.size else [0])
        else:
            acc = pygltflib.Accessor(bufferView=k, componentType=_FLOAT, count=len(arr),
                                     type="VEC3")
            if key == "POSITION":
                acc.min = arr.min(axis=0).tolist()
                acc.max = arr.max(axis=0).tolist()
            attributes[key] = k
        accessors.append(acc)
    custom = {"_RADIANCE": attributes.pop("_RADIANCE")}
    attrs = pygltflib.Attributes(**attributes)
    for key, value in custom.items():
        setattr(attrs, key, value)
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(generator="shtools export", version="2.0"),
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0])],
        nodes=[pygltflib.Node(mesh=0, name=name)],
        meshes=[pygltflib.Mesh(name=name, primitives=[pygltflib.Primitive(
            attributes=attrs, indices=len(arrays) - 1, material=0)])],
        materials=[pygltflib.Material(
            name="baked_radiance",
            pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=1.0),
            extensions={UNLIT: {}},
        )],
        extensionsUsed=[UNLIT],
        accessors=accessors,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=len(blob))],
    )
    gltf.set_binary_blob(bytes(blob))
    with atomic_path(path) as tmp:
        gltf.save_binary(str(tmp))
