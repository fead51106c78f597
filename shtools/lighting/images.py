"""Loading high-dynamic-range environment images as linear RGB arrays.

Radiance ``.hdr``/``.pic`` and ``.pfm`` files are read with OpenCV.  OpenEXR
(``.exr``) files are read with the ``OpenEXR`` package (the Academy Software
Foundation's bindings, a dependency): the ``opencv-python-headless`` wheels on
PyPI are built without OpenEXR, so OpenCV cannot read them even with
``OPENCV_IO_ENABLE_OPENEXR`` set.  An EXR must have R, G and B channels (half or
float); other layers and alpha are ignored.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from shtools.errors import InputError

#: File suffixes read as HDR images.
HDR_SUFFIXES = (".hdr", ".pic", ".pfm", ".exr")


#: Largest image accepted, in pixels (16384 x 8192, the largest lat-long probes in
#: use; 1.5 GiB as float32 RGB).  Checked on the header, before decoding.
MAX_PIXELS = 16384 * 8192


def _header_size(path: Path, suffix: str) -> tuple[int, int] | None:
    """(width, height) from a Radiance or PFM header, or None when it cannot be read."""
    import re

    with open(path, "rb") as fh:
        head = fh.read(4096)
    if suffix == ".pfm":
        m = re.match(rb"P[Ff]\s+(\d+)\s+(\d+)\s", head)
    else:  # Radiance: header lines, a blank line, then "-Y H +X W"
        m = re.search(rb"\n\n[-+]Y\s+(\d+)\s+[-+]X\s+(\d+)", head)
        m = m and re.match(rb"(\d+) (\d+)", m.group(2) + b" " + m.group(1))
    return None if m is None else (int(m.group(1)), int(m.group(2)))


def check_image_size(width: int, height: int, path) -> None:
    """Refuse images above :data:`MAX_PIXELS`, with the memory they would take."""
    if width * height > MAX_PIXELS:
        gib = width * height * 3 * 4 / 2**30
        raise InputError(f"the header announces {width}x{height} pixels ({gib:.1f} GiB as "
                         f"float RGB), above the limit of {MAX_PIXELS:,} pixels; downsample "
                         "the map", path)


def _read_opencv(path: Path, suffix: str) -> np.ndarray:
    size = _header_size(path, suffix)
    if size is not None:
        check_image_size(*size, path)
    # OpenCV logs decoder warnings (a truncated file) on stderr; we report our own line
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    import cv2

    try:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    except AttributeError:  # older bindings: the environment variable above
        pass
    img = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
    if img is None:
        raise InputError(f"cannot decode the image as {suffix}; the file is damaged or not "
                         "an HDR image", path)
    if img.ndim != 3 or img.shape[2] != 3 or img.size == 0:
        raise InputError(f"expected an RGB image, got shape {img.shape}", path)
    if img.dtype.kind != "f":
        raise InputError(f"the image holds {img.dtype} integers, not HDR floats; use a "
                         "linear HDR file", path)
    return np.ascontiguousarray(img[..., ::-1], dtype=np.float32)  # OpenCV gives BGR


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    try:
        lo, hi = OpenEXR.File(str(path), header_only=True).header()["dataWindow"]
        size = (int(hi[0]) - int(lo[0]) + 1, int(hi[1]) - int(lo[1]) + 1)
    except Exception:  # the full read below reports what is wrong
        size = None
    if size is not None:
        check_image_size(*size, path)
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: ch.pixels for name, ch in exr.channels().items()}
    except Exception as exc:  # the bindings raise plain RuntimeError/IOError on bad files
        raise InputError(f"cannot decode the image as .exr ({' '.join(str(exc).split())}); "
                         "the file is damaged or not OpenEXR", path) from None
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        names = ", ".join(sorted(channels)) or "none"
        raise InputError(f"the EXR has no {'/'.join(missing)} channel (channels: {names}); "
                         "export the environment as RGB", path)
    rgb = np.stack([np.asarray(channels[c]) for c in "RGB"], axis=-1)
    if rgb.dtype.kind != "f" or rgb.ndim != 3 or rgb.size == 0:
        raise InputError(f"expected float RGB channels, got {rgb.dtype} of shape {rgb.shape}",
                         path)
    return np.ascontiguousarray(rgb, dtype=np.float32)


def load_hdr_image(path: str | os.PathLike) -> np.ndarray:
    """Read an HDR image as linear RGB.

    Parameters
    ----------
    path : path-like
        ``.hdr``/``.pic`` (Radiance RGBE), ``.pfm`` or ``.exr``.

    Returns
    -------
    ndarray, shape (H, W, 3), float32
        Linear RGB, row 0 at the top of the image.

    Raises
    ------
    shtools.errors.InputError
        Missing file, unsupported suffix, unreadable data, NaN/inf or negative
        pixels.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("image not found; check the path", path)
    suffix = path.suffix.lower()
    if suffix not in HDR_SUFFIXES:
        raise InputError(
            f"unsupported image type '{suffix or '(none)'}'; give an HDR environment map "
            f"({', '.join(HDR_SUFFIXES)})",
            path,
        )
    rgb = _read_exr(path) if suffix == ".exr" else _read_opencv(path, suffix)
    bad = ~np.isfinite(rgb)
    if bad.any():
        rows, cols = np.nonzero(bad.any(axis=2))
        raise InputError(
            f"{rows.size} pixels are NaN or inf (first at row {rows[0]}, column {cols[0]}); "
            "fix or clamp the image",
            path,
        )
    negative = rgb < 0
    if negative.any():
        rows, cols = np.nonzero(negative.any(axis=2))
        raise InputError(
            f"{rows.size} pixels are negative (first at row {rows[0]}, column {cols[0]}); "
            "radiance cannot be negative, clamp the image at 0",
            path,
        )
    return rgb
