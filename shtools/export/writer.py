"""Export a bake asset to the format its output suffix names (.ply, .glb, .png, .gif)."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from shtools.data_formats.bake import Bake
from shtools.errors import InputError
from shtools.export.png import (
    View,
    contact_sheet,
    exposure_scale,
    render_frames,
    save_gif,
    save_png,
    vertex_colors,
)
from shtools.export.tonemap import CURVES

#: Default image sizes (width, height): a single frame, and one tile of a sheet or GIF.
FRAME_SIZE = (800, 600)
TILE_SIZE = (320, 240)
#: Most pixels a contact sheet or GIF may hold over all its frames (768 MiB of RGB
#: images in memory until the file is written).
MAX_SEQUENCE_PIXELS = 2**28


def _positions(bake: Bake, frame: int | None, frames_text: str | None) -> list[int]:
    if frames_text is not None:
        if frame is not None:
            raise InputError("give --frame or --frames, not both")
        from shtools.data_formats.bake import parse_frames

        lo = int(bake.frame_index.min())
        hi = int(bake.frame_index.max()) + 1
        text = frames_text
        rng = parse_frames(text, hi, bake.path)
        if rng.start < lo:
            raise InputError(f"--frames {text} starts before the bake's first frame {lo}",
                             bake.path)
        return [bake.frame_position(f) for f in rng]
    if frame is None:
        return [0]
    return [bake.frame_position(frame)]


def export_bake(
    bake: Bake,
    output: str | os.PathLike,
    *,
    frame: int | None = None,
    frames_text: str | None = None,
    view: View | None = None,
    size: tuple[int, int] | None = None,
    columns: int | None = None,
    fps: float | None = None,
) -> dict:
    """Write ``bake`` to ``output`` (format from the suffix); returns a summary dict.

    ``.ply``/``.glb`` take one frame (``frame``, a scene frame number; default
    the first baked).  ``.png`` renders one frame, or a contact sheet when
    ``frames_text`` (``"A:B"``) is given; ``.gif`` animates ``frames_text``
    (default every baked frame).
    """
    view = view or View()
    suffix = Path(output).suffix.lower()
    if suffix == ".gif" and frames_text is None and frame is None:
        positions = list(range(bake.n_frames))
    else:
        positions = _positions(bake, frame, frames_text)
    if suffix in (".ply", ".glb"):
        if len(positions) != 1:
            raise InputError(f"{suffix} holds one frame; use --frame F (or export a .png "
                             "sheet / .gif for a range)", output)
        t = positions[0]
        scale = exposure_scale(bake, [t], view)
        verts = np.asarray(bake.frame_vertices(t), dtype=float)
        normals = np.asarray(bake.frame_normals(t), dtype=float)
        if suffix == ".ply":
            from shtools.export.ply import write_ply

            write_ply(output, verts, bake.faces, vertex_colors(bake, t, scale, view.curve),
                      normals)
        else:
            from shtools.export.gltf import write_glb

            rad = bake.radiance[t].astype(float)
            shaded = rad * bake.albedo if bake.albedo is not None else rad
            linear = CURVES[view.curve](shaded * scale)
            write_glb(output, verts, bake.faces, linear, normals, bake.radiance[t])
        detail = f"frame {int(bake.frame_index[t])}, {bake.n_vertices} vertices"
    elif suffix == ".png" and len(positions) == 1:
        w, h = size or FRAME_SIZE
        (img,) = render_frames(bake, positions, replace(view, width=w, height=h))
        save_png(img, output)
        detail = f"frame {int(bake.frame_index[positions[0]])}, {w}x{h}"
    else:
        w, h = size or TILE_SIZE
        total = len(positions) * w * h
        if total > MAX_SEQUENCE_PIXELS:  # every frame's image is kept until the file is written
            raise InputError(
                f"{len(positions)} frames of {w}x{h} are {total:,} pixels "
                f"({3 * total / 2**30:.1f} GiB of images), above the limit of "
                f"{MAX_SEQUENCE_PIXELS:,}; export fewer frames (--frames A:B) or a smaller "
                "--size", output)
        # GIF frames are palette-quantised anyway: skip the supersampling (4x faster)
        ss = 1 if suffix == ".gif" else view.supersample
        images = render_frames(bake, positions, replace(view, width=w, height=h, supersample=ss))
        if suffix == ".png":
            labels = [f"frame {int(bake.frame_index[t])}" for t in positions]
            save_png(contact_sheet(images, labels, columns), output)
            detail = f"contact sheet of {len(positions)} frames"
        else:
            rate = fps or float(bake.attrs.get("fps", 24.0))
            save_gif(images, output, rate)
            detail = f"{len(positions)} frames at {rate:g} fps"
    return {
        "output": os.fspath(output),
        "format": suffix[1:],
        "frames": [int(bake.frame_index[t]) for t in positions],
        "detail": detail,
    }
