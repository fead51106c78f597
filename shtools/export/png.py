"""Preview images of a bake: one frame as PNG, a contact sheet, an animated GIF.

Rendered on the CPU with :mod:`shtools.export.raster` from a camera fitted to
the receivers' bounding box over all exported frames (so the view does not jump
between frames), looking down at 30 degrees.  Vertex colours are the baked
radiance times the albedo, exposed (auto by default, shared across frames),
tone-mapped and sRGB-encoded, then Gouraud-interpolated.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from shtools.data_formats import atomic_path
from shtools.data_formats.bake import Bake
from shtools.errors import InputError
from shtools.export.raster import fit_camera, rasterize
from shtools.export.tonemap import srgb_encode, to_uint8

#: Background gradient, sRGB-encoded (top, bottom): a neutral studio grey.
BACKGROUND_TOP = np.array([0.72, 0.75, 0.80])
BACKGROUND_BOTTOM = np.array([0.42, 0.43, 0.46])


@dataclass
class View:
    """How to look at a bake: image size, camera angles (degrees), zoom, exposure.

    ``exposure`` is in stops on top of the automatic exposure (or of 1.0 when
    ``auto_exposure`` is off); ``curve`` is ``"aces"``, ``"reinhard"`` or ``"clamp"``;
    ``distance`` (scene units) fixes the camera's distance from the framed centre.
    """

    width: int = 800
    height: int = 600
    elevation: float = 30.0
    azimuth: float = 35.0
    zoom: float = 1.0
    exposure: float = 0.0
    auto_exposure: bool = True
    curve: str = "aces"
    supersample: int = 2
    distance: float | None = None


def exposure_scale(bake: Bake, positions: list[int], view: View,
                   quantity: str = "radiance") -> float:
    """Linear exposure shared by the frames at ``positions``."""
    from shtools.export.quantity import display_scale

    return display_scale(bake, positions, quantity, view.exposure, view.auto_exposure)


def vertex_colors(bake: Bake, t: int, scale: float, curve: str = "aces",
                  quantity: str = "radiance") -> np.ndarray:
    """Display colours (V, 3) in [0, 1], sRGB-encoded, of asset frame ``t``.

    For radiance: albedo x radiance, exposed and tone-mapped
    (:func:`shtools.export.quantity.display_linear`).
    """
    from shtools.export.quantity import display_linear

    return srgb_encode(display_linear(bake, t, quantity, scale, curve))


def _background(width: int, height: int) -> np.ndarray:
    u = np.linspace(0.0, 1.0, height)[:, None, None]
    row = (1 - u) * BACKGROUND_TOP + u * BACKGROUND_BOTTOM
    return np.broadcast_to(row, (height, width, 3))


def target_range(bake: Bake, target: str | None) -> tuple[int, int]:
    """Vertex range ``(lo, hi)`` of receiver object ``target`` (None: every vertex).

    Raises :class:`InputError` naming the bake's objects when there is no such object.
    """
    if target is None:
        return 0, bake.n_vertices
    if target not in bake.object_names:
        raise InputError(f"no receiver object '{target}' in this bake; it has "
                         f"{', '.join(bake.object_names)}", bake.path)
    o = bake.object_names.index(target)
    return int(bake.object_offsets[o]), int(bake.object_offsets[o + 1])


def _camera(bake: Bake, positions: list[int], view: View, target: str | None = None):
    lo, hi = target_range(bake, target)
    if bake.vertices.ndim == 3:
        pts = bake.vertices[positions, lo:hi].reshape(-1, 3)
    else:
        pts = bake.vertices[lo:hi]
    return fit_camera(
        np.asarray(pts, dtype=float),
        elevation=np.radians(view.elevation),
        azimuth=np.radians(view.azimuth),
        aspect=view.width / view.height,
        zoom=view.zoom,
        fixed_distance=view.distance,
    )


def render_frames(bake: Bake, positions: list[int], view: View, progress=None,
                  quantity: str = "radiance", target: str | None = None) -> list[np.ndarray]:
    """Render asset frames ``positions`` with one camera and exposure; uint8 (H, W, 3) each.

    ``progress``: a progress factory (:mod:`shtools.progress`), one step per frame;
    ``quantity``: what the colours show (:mod:`shtools.export.quantity`);
    ``target``: frame this receiver object (every object stays visible).
    """
    from shtools.progress import silent

    scale = exposure_scale(bake, positions, view, quantity)
    camera = _camera(bake, positions, view, target)
    bg = _background(view.width, view.height)
    images = []
    steps = positions if len(positions) == 1 else (progress or silent)(
        positions, desc="render", unit="frames")
    for t in steps:
        colors = vertex_colors(bake, t, scale, view.curve, quantity)
        img, _ = rasterize(
            np.asarray(bake.frame_vertices(t), dtype=float), bake.faces, colors, camera,
            view.width, view.height, background=bg, supersample=view.supersample,
        )
        images.append(to_uint8(img))
    return images


def contact_sheet(images: list[np.ndarray], labels: list[str], columns: int | None = None):
    """Tile images (H, W, 3) into a grid with a label in each tile's corner; uint8."""
    from PIL import Image, ImageDraw

    n = len(images)
    columns = columns or int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / columns))
    h, w = images[0].shape[:2]
    gap = 4
    sheet = Image.new("RGB", (columns * w + (columns + 1) * gap, rows * h + (rows + 1) * gap),
                      (32, 32, 36))
    draw = ImageDraw.Draw(sheet)
    for k, (img, label) in enumerate(zip(images, labels, strict=True)):
        r, c = divmod(k, columns)
        x, y = gap + c * (w + gap), gap + r * (h + gap)
        sheet.paste(Image.fromarray(img), (x, y))
        draw.rectangle((x, y, x + 8 + 7 * len(label), y + 16), fill=(0, 0, 0))
        draw.text((x + 4, y + 3), label, fill=(255, 255, 255))
    return np.asarray(sheet)


def save_png(image: np.ndarray, path: str | os.PathLike) -> None:
    """Write a uint8 (H, W, 3) image atomically as PNG."""
    from PIL import Image

    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG", optimize=False)


def save_gif(images: list[np.ndarray], path: str | os.PathLike, fps: float) -> None:
    """Write frames as a looping animated GIF, atomically."""
    from PIL import Image

    if not images:
        raise InputError("no frames to write", path)
    # Floyd–Steinberg dithering hides the banding of smooth shading in a 255-colour palette
    frames = [Image.fromarray(img).quantize(colors=255, method=Image.Quantize.MEDIANCUT,
                                            dither=Image.Dither.FLOYDSTEINBERG)
              for img in images]
    with atomic_path(path) as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:],
                       duration=max(round(1000 / fps), 20), loop=0, disposal=1)
