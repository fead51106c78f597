"""Environment lights to RGB radiance SH: from lat-long HDR images.

:func:`project_environment` is what ``shtools light project`` and scene files
with an image environment call.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.lighting.frames import rotation_about_y
from shtools.lighting.images import load_hdr_image
from shtools.lighting.latlong import project_latlong
from shtools.runtime.settings import WINDOW_CHOICES
from shtools.sh.basis import check_order
from shtools.sh.zonal import apply_window

#: Reflection x -> -x: the same image mirrored left-right.
MIRROR_X = np.diag([-1.0, 1.0, 1.0])


def environment_rotation(rotate_y: float = 0.0, mirror: bool = False) -> np.ndarray:
    """World-space matrix applied to the mapped image: mirror first, then rotate.

    Parameters
    ----------
    rotate_y : float
        Degrees about +y (right-hand rule: +90 takes the image centre from -z to -x).
    mirror : bool
        Mirror the image left-right (x -> -x) first, for maps stored mirrored.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    m = rotation_about_y(rotate_y)
    return m @ MIRROR_X if mirror else m


def check_latlong_shape(shape, path=None) -> None:
    """Refuse images that are not 2:1 lat-long maps, with a one-line reason."""
    height, width = shape[:2]
    if width != 2 * height:
        hint = (" (a square image is probably an angular-map/mirror-ball probe; convert it to "
                "lat-long first)" if width == height else "")
        raise InputError(
            f"image is {width}x{height}; a lat-long (equirectangular) map must be twice as "
            f"wide as high{hint}",
            path,
        )
    if height < 2:
        raise InputError(f"image is {width}x{height}; too small for an environment map", path)


def project_environment(
    path: str | os.PathLike,
    order: int,
    *,
    window: str | None = None,
    window_h: float | None = None,
    rotate_y: float = 0.0,
    exposure: float = 0.0,
    mirror: bool = False,
) -> tuple[np.ndarray, dict]:
    """Project a lat-long HDR environment map to RGB radiance SH (Y-up world).

    Parameters
    ----------
    path : path-like
        ``.hdr``/``.pic``/``.pfm``/``.exr``, lat-long,
        width = 2 x height, row 0 straight up, image centre towards -z (see
        ``docs/conventions.md``).
    order : int
        SH order ``n``.
    window : {"cosine", "hann", "lanczos", "none"}, optional
        Per-band window applied after projection (:func:`shtools.sh.window`).
    window_h : float, optional
        Window width in bands (default: the window's own default).
    rotate_y : float
        Rotate the environment by this many degrees about +y.
    exposure : float
        Exposure in EV: radiance is multiplied by ``2**exposure``.
    mirror : bool
        Mirror the image left-right before rotating.

    Returns
    -------
    coeffs : ndarray, shape (n*n, 3)
        ``int L(s) y_i(s) ds`` for R, G, B with the image piecewise constant
        over pixels (exact per-pixel integrals).
    info : dict
        Image size and the parameters used (recorded in the light asset).
    """
    order = check_order(order)
    if window is not None and window not in WINDOW_CHOICES:
        raise InputError(f"unknown window '{window}'; use one of {', '.join(WINDOW_CHOICES)}")
    if not np.isfinite(exposure) or not np.isfinite(rotate_y):
        raise InputError("exposure and rotation must be finite numbers")
    image = load_hdr_image(path)
    check_latlong_shape(image.shape, path)
    coeffs = project_latlong(image, order, rotation=environment_rotation(rotate_y, mirror))
    coeffs *= 2.0**exposure
    kind = None if window in (None, "none") else window
    if kind is not None:
        coeffs = apply_window(coeffs.T, kind, window_h).T
    info = {
        "mapping": "latlong",
        "width": int(image.shape[1]),
        "height": int(image.shape[0]),
        "window": kind or "none",
        "window_h": window_h,
        "rotate_y_degrees": float(rotate_y),
        "mirror": bool(mirror),
        "exposure_ev": float(exposure),
    }
    return coeffs, info


def project_environment_to_file(image: str | os.PathLike, order: int,
                                output: str | os.PathLike, *, window: str | None = "none",
                                window_h: float | None = None, rotate_y: float = 0.0,
                                exposure: float = 0.0, mirror: bool = False):
    """Project a lat-long HDR image (:func:`project_environment`) and write a ``light`` asset.

    What ``shtools light project`` runs.

    Returns
    -------
    coeffs : ndarray, shape (n*n, 3)
    info : dict
        As from :func:`project_environment`.
    """
    from shtools.data_formats.light import write_light

    coeffs, info = project_environment(image, order, window=window, window_h=window_h,
                                       rotate_y=rotate_y, exposure=exposure, mirror=mirror)
    write_light(output, coeffs, source="image", inputs={"image": image},
                parameters={"order": order, **info})
    return coeffs, info


#: Algorithm version of a cached environment projection (:mod:`shtools.cache`).
ENVIRONMENT_VERSION = 1


def projected_environment(path, order: int, rotate: float, cache=None) -> np.ndarray:
    """An environment image's radiance SH ``(order^2, 3)``, rotated by ``rotate`` radians
    about +y (:func:`project_environment`), read from ``cache`` (a
    :class:`shtools.cache.SetupCache`) when the same image bytes were projected at this
    order before: what a bake's image environment (and its mid-range sphere) uses."""
    def compute():
        coeffs, _ = project_environment(path, order, rotate_y=math.degrees(rotate))
        return {"coeffs": np.asarray(coeffs, dtype=float)}

    if cache is None:
        return compute()["coeffs"]
    parts = {"image": Path(path), "order": int(order), "rotate": float(rotate)}
    return cache.fetch("environment", ENVIRONMENT_VERSION, parts, compute)["coeffs"]
