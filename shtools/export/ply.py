"""Vertex-coloured PLY of one baked frame (binary, trimesh's writer).

PLY has no colour-space convention; viewers (MeshLab, Blender's importer) show
the bytes as display colours, so the colours are tone-mapped and sRGB-encoded.
"""

from __future__ import annotations

import os

import numpy as np
import trimesh

from shtools.data_formats import atomic_path
from shtools.export.tonemap import to_uint8


def write_ply(
    path: str | os.PathLike,
    vertices: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray,
    normals: np.ndarray | None = None,
) -> None:
    """Write a binary PLY with per-vertex RGBA colours, atomically.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
    faces : ndarray, shape (F, 3)
    colors : ndarray, shape (V, 3)
        sRGB-encoded display colours in [0, 1].
    normals : ndarray, shape (V, 3), optional
    """
    rgba = np.concatenate([to_uint8(colors), np.full((len(colors), 1), 255, np.uint8)], axis=1)
    mesh = trimesh.Trimesh(
        vertices=np.asarray(vertices, dtype=np.float64),
        faces=np.asarray(faces, dtype=np.int64),
        vertex_normals=None if normals is None else np.asarray(normals, dtype=np.float64),
        vertex_colors=rgba,
        process=False,
    )
    data = mesh.export(file_type="ply", encoding="binary", include_attributes=False)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
