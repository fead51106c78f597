"""Linear quantization per shell and coefficient (Tamura et al. Sec. 5.1).

``value = offset + q * step`` with ``offset = min``, ``step = (max - min) /
(2**bits - 1)`` over the shell's samples of one coefficient (``step = 0`` for a
constant coefficient), ``q = rint((value - offset) / step)``; the error of a
stored value is at most ``step / 2``.
"""

from __future__ import annotations

import numpy as np


def quantize(grid, bits: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quantize one shell.

    Parameters
    ----------
    grid : array_like, shape (R, R, K)
    bits : int
        1..8 (stored as uint8).

    Returns
    -------
    q : ndarray of uint8, shape (R, R, K)
    offset : ndarray of float32, shape (K,)
    step : ndarray of float32, shape (K,)
    """
    if not 1 <= int(bits) <= 8:
        raise ValueError(f"bits must be 1..8, got {bits!r}")
    g = np.asarray(grid, dtype=np.float64)
    K = g.shape[-1]
    flat = g.reshape(-1, K)
    lo = flat.min(axis=0)
    levels = (1 << int(bits)) - 1
    step = (flat.max(axis=0) - lo) / levels
    safe = np.where(step > 0, step, 1.0)
    q = np.clip(np.rint((g - lo) / safe), 0, levels).astype(np.uint8)
    return q, lo.astype(np.float32), step.astype(np.float32)


def dequantize(q, offset, step) -> np.ndarray:
    """``offset + q * step``, float32, the shape of ``q``."""
    return np.asarray(offset, np.float32) + np.asarray(q, np.float32) * np.asarray(step, np.float32)
