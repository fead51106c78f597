"""Skies for tests, projected to SH by quadrature (not by the code under test)."""

from __future__ import annotations

import math

import numpy as np


def sun_sky(sun, order: int, floor: float = 0.2) -> np.ndarray:
    """Luminance in SH ``(n*n,)`` of a uniform ``floor`` plus a sun lobe
    ``exp(8 (s.sun - 1))`` about the unit direction ``sun``, projected by quadrature
    over 20,000 equal-area directions (``world_directions``)."""
    from shtools.scene.traced_shadows import world_directions
    from shtools.sh import basis

    d = world_directions(20000)
    radiance = floor + np.exp(8.0 * (d @ np.asarray(sun, dtype=float) - 1.0))
    return (4.0 * math.pi / len(d)) * basis(d, order).T @ radiance
