"""A bake's receiver objects of one frame as glTF mesh objects (vertices, faces, colours).

The one conversion both the single-frame ``.glb`` writer (:mod:`shtools.export.writer`)
and the vertex animation texture's base mesh (:mod:`shtools.export.vat`) use.
"""

from __future__ import annotations

import numpy as np

from shtools.data_formats.bake import Bake
from shtools.export.quantity import display_linear


def mesh_objects(bake: Bake, t: int, quantity: str, scale: float, curve: str, uv1=None):
    """The bake's receiver objects at asset frame ``t`` as :class:`GlbObject` s."""
    from shtools.export.gltf import GlbObject  # on use: a PNG or PLY export need not load pygltflib
    from shtools.export.quantity import raw_values

    verts = np.asarray(bake.frame_vertices(t), dtype=np.float64)
    normals = np.asarray(bake.frame_normals(t), dtype=np.float64)
    display = display_linear(bake, t, quantity, scale, curve)
    raw = raw_values(bake, t, quantity)
    out = []
    for o, name in enumerate(bake.object_names):
        lo, hi = int(bake.object_offsets[o]), int(bake.object_offsets[o + 1])
        out.append(GlbObject(name, verts[lo:hi], bake.object_faces(o), display[lo:hi],
                             normals[lo:hi], raw[lo:hi], f"_{quantity.upper()}",
                             None if uv1 is None else uv1[lo:hi]))
    return out
