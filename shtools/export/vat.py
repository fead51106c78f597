"""Vertex animation textures (VAT) for game engines, in the Houdini VAT layout.

``shtools export baked.h5 -o NAME.exr [--frames A:B[:S]] [--quantity Q]`` writes

* ``NAME.exr`` -- float32 RGB, one texel per vertex per frame: the raw
  quantity before albedo (radiance, irradiance, or the visibility repeated in
  R, G, B).  Width ``W = min(V, MAX_WIDTH)``; a frame takes
  ``R = ceil(V / W)`` rows; frame ``k`` of the export occupies rows
  ``k*R .. k*R + R-1`` (top row first);
* ``NAME.pos.exr`` -- only when some vertex moves: float32 RGB world
  positions per vertex per frame, same layout (Houdini's "soft body" position
  texture, absolute rather than offsets so no rest mesh is needed to read it);
* ``NAME.glb`` -- the mesh at the first exported frame, one named node per
  object, with ``TEXCOORD_1`` holding each vertex's texel centre in frame 0:
  ``u = (i mod W + 0.5) / W``, ``v = (i div W + 0.5) / H`` (glTF UVs: origin
  at the image's top-left).  A shader at frame ``k`` samples
  ``(u, v + k * R / H)`` with point filtering.  ``COLOR_0`` is the first
  frame's display colour, so the GLB alone looks right in a viewer.  The
  layout numbers are in the glTF's ``asset.extras.shtools_vat``.

Frames are rows and vertices columns, as in SideFX's Labs VAT ROP; what is not
written is its material/shader and the rotation texture of its rigid mode.
"""

from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path

import numpy as np

from shtools.data_formats import atomic_path
from shtools.data_formats.bake import Bake

#: Widest texture written; common engine limits are 8192 or 16384 texels.
MAX_WIDTH = 8192


def layout(n_vertices: int, n_frames: int) -> dict:
    """Texture layout: ``width``, ``rows_per_frame``, ``height``."""
    width = max(1, min(n_vertices, MAX_WIDTH))
    rows = max(1, math.ceil(n_vertices / width))
    return {"width": width, "rows_per_frame": rows, "height": rows * n_frames}


def texel_uv(n_vertices: int, lay: dict) -> np.ndarray:
    """``TEXCOORD_1`` of every vertex: its texel centre in frame 0, shape (V, 2)."""
    i = np.arange(n_vertices)
    u = (i % lay["width"] + 0.5) / lay["width"]
    v = (i // lay["width"] + 0.5) / lay["height"]
    return np.stack([u, v], axis=1)


def to_texture(per_frame: np.ndarray, lay: dict) -> np.ndarray:
    """(T, V, 3) per-vertex values -> (H, W, 3) float32 image in the VAT layout."""
    T, V, _ = per_frame.shape
    W, R = lay["width"], lay["rows_per_frame"]
    padded = np.zeros((T, R * W, 3), dtype=np.float32)
    padded[:, :V] = per_frame
    return padded.reshape(T * R, W, 3)


def _write_exr(path, image: np.ndarray) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, dtype=np.float32)}) as f:
        f.write(str(path))


def _moving(bake: Bake, positions: list[int]) -> bool:
    return bake.vertices.ndim == 3 and bool(
        np.any(bake.vertices[positions] != bake.vertices[positions[0]]))


def vat_files(path: str | os.PathLike, bake: Bake, positions: list[int]) -> list[Path]:
    """The files :func:`write_vat` writes: ``NAME.exr``, ``NAME.pos.exr`` if some
    vertex moves, ``NAME.glb``."""
    out = Path(path)
    pos = [out.with_name(out.stem + ".pos.exr")] if _moving(bake, positions) else []
    return [out, *pos, out.with_suffix(".glb")]


def write_vat(
    path: str | os.PathLike,
    bake: Bake,
    positions: list[int],
    *,
    quantity: str = "radiance",
    scale: float = 1.0,
    curve: str = "aces",
    progress=None,
) -> dict:
    """Write the VAT files of asset frames ``positions`` (see the module doc), atomically.

    Returns
    -------
    dict
        ``glb``, ``positions_exr`` (or None) and the layout (``width``,
        ``rows_per_frame``, ``height``).
    """
    from shtools.export.gltf import write_glb_objects
    from shtools.export.objects import mesh_objects
    from shtools.export.quantity import raw_values
    from shtools.progress import silent

    out = Path(path)
    V, T = bake.n_vertices, len(positions)
    lay = layout(V, T)
    values = np.empty((T, V, 3), dtype=np.float32)
    moving = _moving(bake, positions)
    points = np.empty((T, V, 3), dtype=np.float32) if moving else None
    with (progress or silent)(total=T, desc="vat", unit="frames") as bar:
        for k, t in enumerate(positions):
            raw = raw_values(bake, t, quantity)
            values[k] = raw if raw.ndim == 2 else raw[:, None]
            if moving:
                points[k] = bake.frame_vertices(t)
            bar.update(1)
    files = vat_files(out, bake, positions)
    glb, pos_path = files[-1], (files[1] if moving else None)
    extras = {"shtools_vat": {
        **lay, "frames": [int(bake.frame_index[t]) for t in positions],
        "fps": float(bake.attrs.get("fps", 24.0)), "quantity": quantity,
        "texture": out.name, "positions": None if pos_path is None else pos_path.name}}
    with contextlib.ExitStack() as stack:  # all files or none
        _write_exr(stack.enter_context(atomic_path(out)), to_texture(values, lay))
        if pos_path is not None:
            _write_exr(stack.enter_context(atomic_path(pos_path)), to_texture(points, lay))
        write_glb_objects(stack.enter_context(atomic_path(glb)),
                          mesh_objects(bake, positions[0], quantity, scale, curve,
                                       uv1=texel_uv(V, lay)), extras=extras)
    return {"glb": os.fspath(glb), "positions_exr": None if pos_path is None else
            os.fspath(pos_path), **lay}
