"""What an export carries per vertex: radiance, irradiance or visibility, before albedo.

Engines and DCCs multiply per-vertex lighting with their own textures, so the
raw exported value never includes the scene's albedo:

* ``radiance`` -- the bake's outgoing radiance of a white Lambertian receiver,
  linear RGB (as stored);
* ``irradiance`` -- ``pi`` x that radiance: the RGB irradiance ``E`` at the
  vertex (a white Lambertian surface reflects ``E / pi``);
* ``visibility`` -- the cosine-weighted unoccluded fraction
  ``(1/pi) * integral V(w) max(n . w, 0) dw`` in [0, 1] (ambient occlusion;
  1 = open sky), from the stored order-n visibility vectors (bake with
  ``--store-visibility``).  It is the exact inner product of the order-n
  visibility with the clamped cosine, whose bands beyond n it cannot see.

The display colour of an export (``COLOR_0``, ``displayColor``, PNG pixels) is
the tone-mapped radiance x albedo for ``radiance`` (what the previews show),
the tone-mapped irradiance for ``irradiance`` and the linear grey visibility
for ``visibility``.
"""

from __future__ import annotations

import math

import numpy as np

from shtools.data_formats.bake import Bake
from shtools.errors import InputError

QUANTITIES = ("radiance", "irradiance", "visibility")


def check_quantity(bake: Bake, quantity: str) -> None:
    """Raise :class:`InputError` when ``bake`` cannot provide ``quantity``."""
    if quantity not in QUANTITIES:
        raise InputError(f"unknown quantity '{quantity}'; use one of {', '.join(QUANTITIES)}")
    if quantity == "visibility" and bake.visibility is None:
        raise InputError("--quantity visibility needs the visibility vectors; rebake with "
                         "'shtools bake --store-visibility'", bake.path)


def channels(quantity: str) -> int:
    """Components per vertex of the raw ``quantity``: 3 (RGB) or 1 (visibility)."""
    return 1 if quantity == "visibility" else 3


def cosine_visibility(visibility: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """``(1/pi) integral V(w) max(n . w, 0) dw`` per vertex.

    Parameters
    ----------
    visibility : ndarray, shape (V, n*n)
        Visibility SH vectors.
    normals : ndarray, shape (V, 3)
        Unit normals.

    Returns
    -------
    ndarray, shape (V,)
    """
    from shtools.sh.zonal import clamped_cosine_zh, zonal_to_sh

    order = math.isqrt(visibility.shape[-1])
    # H = max(n . w, 0) / pi rotated to each normal (eq. 9); <V, H> is the integral
    h = zonal_to_sh(clamped_cosine_zh(order), np.asarray(normals, dtype=np.float64))
    return np.einsum("vk,vk->v", np.asarray(visibility, dtype=np.float64), h)


def raw_values(bake: Bake, t: int, quantity: str) -> np.ndarray:
    """The raw ``quantity`` of asset frame ``t``, before albedo.

    Returns
    -------
    ndarray, shape (V, 3) for radiance/irradiance, (V,) for visibility; float64
    """
    if quantity == "radiance":
        return np.asarray(bake.radiance[t], dtype=np.float64)
    if quantity == "irradiance":
        return math.pi * np.asarray(bake.radiance[t], dtype=np.float64)
    return cosine_visibility(bake.visibility[t], bake.frame_normals(t))


def display_linear(bake: Bake, t: int, quantity: str, scale: float, curve: str) -> np.ndarray:
    """Display colour of frame ``t`` in linear [0, 1] (before sRGB encoding), ``(V, 3)``.

    ``scale`` is the exposure (:func:`display_scale`); ``curve`` a tone curve name.
    """
    from shtools.export.tonemap import CURVES, clip_negative

    if quantity == "visibility":
        grey = np.clip(raw_values(bake, t, quantity), 0.0, 1.0)
        return np.repeat(grey[:, None], 3, axis=1)
    rad = raw_values(bake, t, quantity)
    if quantity == "radiance" and bake.albedo is not None:
        rad = rad * bake.albedo
    return CURVES[curve](clip_negative(rad) * scale)


def display_scale(bake: Bake, positions: list[int], quantity: str, exposure: float = 0.0,
                  auto: bool = True) -> float:
    """Exposure shared by the frames ``positions`` (auto exposure x 2^exposure)."""
    from shtools.export.tonemap import auto_exposure

    scale = 2.0 ** exposure
    if auto and quantity != "visibility":
        rad = np.asarray(bake.radiance[positions], dtype=np.float64)
        if quantity == "irradiance":
            rad = rad * math.pi
        elif bake.albedo is not None:
            rad = rad * bake.albedo[None]
        scale *= auto_exposure(rad)
    return scale
