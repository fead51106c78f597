"""Export a bake asset to the format its output suffix names.

``.glb`` of a frame range is one animated file (:mod:`shtools.export.animated`);
with ``sequence=True`` (``--sequence``), and always for ``.ply``, a range is
a numbered sequence ``NAME.<frame>.glb`` of single frames (four digits, the
scene frame number) -- see :func:`output_files`.  ``.usda``/``.usdc``/``.usd``
hold every exported frame in one time-sampled stage.  ``.png`` is one frame or a contact sheet,
``.gif`` an animation.  ``.exr`` is a vertex animation texture
(:mod:`shtools.export.vat`).
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from shtools.data_formats.bake import Bake
from shtools.errors import InputError
from shtools.export.objects import mesh_objects
from shtools.export.png import (
    View,
    contact_sheet,
    render_frames,
    save_gif,
    save_png,
)
from shtools.export.quantity import QUANTITIES, check_quantity, display_linear, display_scale

#: Default image sizes (width, height): a single frame, and one tile of a sheet or GIF.
FRAME_SIZE = (800, 600)
TILE_SIZE = (320, 240)
#: Most pixels a contact sheet or GIF may hold over all its frames (768 MiB of RGB
#: images in memory until the file is written).
MAX_SEQUENCE_PIXELS = 2**28

FORMATS = (".ply", ".glb", ".png", ".gif", ".usda", ".usdc", ".usd", ".exr")
#: formats holding every exported frame in one file (default: all the bake's frames)
ANIMATED = (".gif", ".usda", ".usdc", ".usd", ".exr")


def parse_frame_range(bake: Bake, text: str) -> list[int]:
    """``"A:B[:S]"`` (half-open, step S), ``"A:"``, ``":B"`` or ``"A"`` -> asset positions.

    Frame numbers are the scene's; every selected frame must be in the bake.

    Raises
    ------
    InputError
        Malformed, empty, a step < 1, or frames the bake does not hold.
    """
    lo, hi = int(bake.frame_index.min()), int(bake.frame_index.max()) + 1
    parts = text.split(":")
    try:
        if len(parts) == 1:
            start = int(parts[0])
            stop, step = start + 1, 1
        elif len(parts) in (2, 3):
            start = int(parts[0]) if parts[0].strip() else lo
            stop = int(parts[1]) if parts[1].strip() else hi
            step = int(parts[2]) if len(parts) == 3 and parts[2].strip() else 1
        else:
            raise ValueError
    except ValueError:
        raise InputError(f"--frames '{text}' is not A:B[:S], A: or A (frame numbers)",
                         bake.path) from None
    if step < 1:
        raise InputError(f"--frames {text}: the step must be >= 1", bake.path)
    frames = range(start, stop, step)
    if len(frames) == 0:
        raise InputError(f"--frames {text} selects no frame; A:B is half-open like Python",
                         bake.path)
    return [bake.frame_position(f) for f in frames]


def _positions(bake: Bake, suffix: str, frame: int | None, frames_text: str | None):
    if frames_text is not None:
        if frame is not None:
            raise InputError("give --frame or --frames, not both")
        return parse_frame_range(bake, frames_text)
    if frame is not None:
        return [bake.frame_position(frame)]
    return list(range(bake.n_frames)) if suffix in ANIMATED else [0]


def sequence_paths(output: str | os.PathLike, frames: list[int]) -> list[Path]:
    """``out.glb`` and frames ``[0, 2]`` -> ``out.0000.glb``, ``out.0002.glb``.

    One frame keeps ``output`` as given.  The ``NAME.####.ext`` pattern is what
    Houdini, Blender and Nuke read as an image/geometry sequence.
    """
    out = Path(output)
    if len(frames) == 1:
        return [out]
    return [out.with_name(f"{out.stem}.{f:04d}{out.suffix}") for f in frames]


def output_files(bake: Bake, output: str | os.PathLike, *, frame: int | None = None,
                 frames_text: str | None = None, sequence: bool = False,
                 rig: tuple[str, str] | None = None) -> list[Path]:
    """Every file :func:`export_bake` writes for these arguments, in order.

    One file, except a ``.ply`` range and a ``.glb`` range with ``sequence``
    (:func:`sequence_paths`) and a ``.exr`` vertex animation texture with its
    position texture and mesh (:func:`shtools.export.vat.vat_files`).

    Raises
    ------
    InputError
        A bad frame selection (:func:`parse_frame_range`).
    """
    out = Path(output)
    suffix = out.suffix.lower()
    positions = _positions(bake, suffix, frame, frames_text)
    if rig is None and (suffix == ".ply" or (suffix == ".glb" and sequence)):
        return sequence_paths(out, [int(bake.frame_index[t]) for t in positions])
    if suffix == ".exr":
        from shtools.export.vat import vat_files

        return vat_files(out, bake, positions)
    return [out]


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
    quantity: str = "radiance",
    target: str | None = None,
    rig: tuple[str, str] | None = None,
    sequence: bool = False,
    progress=None,
) -> dict:
    """Write ``bake`` to ``output`` (format from the suffix); returns a summary dict.

    Parameters
    ----------
    frame : int, optional
        One scene frame number (default the first baked; every frame for the
        animated formats ``.gif``, USD and ``.exr``).
    frames_text : str, optional
        ``"A:B[:S]"``: a contact sheet (``.png``), the frames of an animated
        format (``.glb`` among them), or a numbered sequence of ``.ply`` files.
    view : View
        Camera, exposure and tone curve.
    quantity : {"radiance", "irradiance", "visibility"}
        What the raw attribute/primvar holds and the display colour shows
        (:mod:`shtools.export.quantity`).
    target : str, optional
        Frame this receiver object with the preview camera (``.png``/``.gif``).
    rig : (object name, glTF path), optional
        ``.glb``: write that skinned object's source glTF with its skin and
        clips and the colours of the frame, or of the range as morph targets
        (:mod:`shtools.export.rig`).
    sequence : bool
        ``.glb`` of a frame range: a numbered sequence of single-frame files
        instead of one animated file.
    progress : callable, optional
        Progress factory (:mod:`shtools.progress`) for frame sequences.
    """
    from shtools.progress import silent

    view = view or View()
    suffix = Path(output).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"unsupported output format '{suffix or '(none)'}'; use one of "
                         f"{', '.join(FORMATS)}", output)
    if quantity not in QUANTITIES:
        raise InputError(f"unknown quantity '{quantity}'; use one of {', '.join(QUANTITIES)}")
    check_quantity(bake, quantity)
    if target is not None and suffix not in (".png", ".gif"):
        raise InputError("--target frames the preview camera; it applies to .png and .gif")
    if sequence and suffix not in (".glb", ".ply"):
        raise InputError("--sequence writes one .glb per frame; it applies to .glb (a .ply "
                         "range is always a sequence)", output)
    positions = _positions(bake, suffix, frame, frames_text)
    frames = [int(bake.frame_index[t]) for t in positions]
    scale = display_scale(bake, positions, quantity, view.exposure, view.auto_exposure)
    summary = {"output": os.fspath(output), "format": suffix[1:], "frames": frames,
               "quantity": quantity}
    if rig is not None:
        if suffix != ".glb" or sequence:
            raise InputError("--rig writes one .glb (of one --frame, or of a --frames range "
                             "with the colours animated)", output)
        from shtools.export.rig import write_rig_glb

        info = write_rig_glb(output, bake, positions, rig[0], rig[1], quantity=quantity,
                             scale=scale, curve=view.curve, progress=progress)
        summary.update(info)
        summary["files"] = [os.fspath(output)]
        colours = (f"colours of frame {frames[0]}" if len(frames) == 1
                   else f"colours of {len(frames)} frames as morph targets (animation 'bake')")
        summary["detail"] = (f"'{rig[0]}' with its skin and {len(info['animations'])} "
                             f"clip(s), {colours}")
    elif suffix == ".glb" and len(positions) > 1 and not sequence:
        from shtools.export.animated import write_animated_glb

        info = write_animated_glb(output, bake, positions, quantity=quantity, scale=scale,
                                  curve=view.curve, progress=progress)
        summary.update(info)
        summary["files"] = [os.fspath(output)]
        summary["detail"] = (f"{len(frames)} frames at {bake.attrs.get('fps', 24.0):g} fps, "
                             f"{len(info['objects'])} object(s), "
                             f"{len(info['colour_animated'])} with animated colours, "
                             f"{len(info['moving'])} moving, {_size(info['bytes'])}")
    elif suffix in (".ply", ".glb"):
        paths = output_files(bake, output, frame=frame, frames_text=frames_text,
                             sequence=sequence)
        steps = positions if len(positions) == 1 else (progress or silent)(
            positions, desc=suffix[1:], unit="frames")
        with contextlib.ExitStack() as stack:  # every file appears only if all were written
            from shtools.data_formats import atomic_path

            for t, path in zip(steps, paths, strict=True):
                tmp = stack.enter_context(atomic_path(path))
                _write_mesh_frame(tmp, suffix, bake, t, quantity, scale, view.curve)
        summary["files"] = [os.fspath(p) for p in paths]
        what = "objects" if len(bake.object_names) > 1 else "object"
        detail = (f"frame {frames[0]}" if len(frames) == 1
                  else f"{len(frames)} files {paths[0].name} .. {paths[-1].name}")
        summary["detail"] = (f"{detail}, {len(bake.object_names)} {what}, "
                             f"{bake.n_vertices} vertices")
    elif suffix in (".usda", ".usdc", ".usd"):
        from shtools.export.usd import write_usd

        info = write_usd(output, bake, positions, quantity=quantity, scale=scale,
                         curve=view.curve, progress=progress)
        summary.update(info)
        summary["detail"] = (f"{len(frames)} frame(s), {len(info['prims'])} prim(s), "
                             f"{len(info['animated'])} with animated points")
    elif suffix == ".exr":
        from shtools.export.vat import write_vat

        info = write_vat(output, bake, positions, quantity=quantity, scale=scale,
                         curve=view.curve, progress=progress)
        summary.update(info)
        summary["detail"] = (f"{len(frames)} frames x {bake.n_vertices} vertices, "
                             f"GLB {info['glb']}")
    elif suffix == ".png" and len(positions) == 1:
        w, h = size or FRAME_SIZE
        (img,) = render_frames(bake, positions, replace(view, width=w, height=h),
                               quantity=quantity, target=target)
        save_png(img, output)
        summary["detail"] = f"frame {frames[0]}, {w}x{h}"
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
        images = render_frames(bake, positions, replace(view, width=w, height=h, supersample=ss),
                               progress=progress, quantity=quantity, target=target)
        if suffix == ".png":
            labels = [f"frame {f}" for f in frames]
            save_png(contact_sheet(images, labels, columns), output)
            summary["detail"] = f"contact sheet of {len(positions)} frames"
        else:
            rate = fps or float(bake.attrs.get("fps", 24.0))
            save_gif(images, output, rate)
            summary["detail"] = f"{len(positions)} frames at {rate:g} fps"
    return summary


def _size(n_bytes: int) -> str:
    return f"{n_bytes / 1e6:.1f} MB" if n_bytes >= 100_000 else f"{n_bytes / 1e3:.0f} kB"


def _write_mesh_frame(path, suffix, bake: Bake, t: int, quantity: str, scale: float,
                      curve: str) -> None:
    """One frame as PLY (sRGB-encoded bytes, all objects in one mesh) or GLB (per object)."""
    if suffix == ".ply":
        from shtools.export.ply import write_ply
        from shtools.export.tonemap import srgb_encode

        colors = srgb_encode(display_linear(bake, t, quantity, scale, curve))
        write_ply(path, np.asarray(bake.frame_vertices(t), dtype=float), bake.faces, colors,
                  np.asarray(bake.frame_normals(t), dtype=float))
    else:
        from shtools.export.gltf import write_glb_objects

        write_glb_objects(path, mesh_objects(bake, t, quantity, scale, curve))
