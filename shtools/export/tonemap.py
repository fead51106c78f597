"""Linear HDR radiance to display colours: exposure, ACES-like tone curve, sRGB encoding."""

from __future__ import annotations

import numpy as np

from shtools.runtime.shading import LUMINANCE, desaturate_negative

#: Auto exposure maps this percentile of the luminance to :data:`AUTO_WHITE`.
AUTO_PERCENTILE = 97.0
#: Pre-curve value the auto-exposed percentile lands on (ACES(0.6) ~= 0.60, sRGB 0.80: bright
#: but below the shoulder, so lit areas keep their gradation).
AUTO_WHITE = 0.6


def auto_exposure(radiance: np.ndarray) -> float:
    """Linear scale that maps the :data:`AUTO_PERCENTILE` luminance to :data:`AUTO_WHITE`.

    Parameters
    ----------
    radiance : ndarray, shape (..., 3)
        Linear RGB; frames of a sequence are pooled so they share one exposure.
    """
    lum = np.asarray(radiance, dtype=float).reshape(-1, 3) @ LUMINANCE
    lum = lum[np.isfinite(lum)]
    ref = float(np.percentile(lum, AUTO_PERCENTILE)) if lum.size else 0.0
    return AUTO_WHITE / ref if ref > 0 else 1.0


def aces(x: np.ndarray) -> np.ndarray:
    """Narkowicz's fit of the ACES filmic curve, clamped to [0, 1]."""
    x = np.maximum(x, 0.0)
    return np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def reinhard(x: np.ndarray) -> np.ndarray:
    """Reinhard's ``x / (1 + x)`` per channel."""
    x = np.maximum(x, 0.0)
    return x / (1.0 + x)


CURVES = {"aces": aces, "reinhard": reinhard, "clamp": lambda x: np.clip(x, 0.0, 1.0)}


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] to sRGB-encoded [0, 1] (IEC 61966-2-1 transfer function)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def clip_negative(radiance: np.ndarray) -> np.ndarray:
    """:func:`shtools.runtime.shading.desaturate_negative` (the bake's de-ringing).

    Kept for bakes made with ``deringing = "none"``: the export removes what is
    left the same way.
    """
    return desaturate_negative(radiance)


def tonemap(radiance: np.ndarray, scale: float, curve: str = "aces") -> np.ndarray:
    """Linear radiance (..., 3) to sRGB-encoded floats in [0, 1], same shape.

    Negative channels (SH ringing) are first removed by :func:`clip_negative`.
    """
    return srgb_encode(CURVES[curve](clip_negative(radiance) * scale))


def to_uint8(colors: np.ndarray) -> np.ndarray:
    """[0, 1] floats to rounded uint8."""
    return np.round(np.clip(colors, 0.0, 1.0) * 255.0).astype(np.uint8)
