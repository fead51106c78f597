"""Error measures used by ``shtools eval``, the tests and the benchmarks."""

from __future__ import annotations

import numpy as np


def relative_rmse(values, reference) -> float:
    """Relative RMSE ``sqrt(sum |x - x_ref|^2 / sum |x_ref|^2)`` over all vertices and channels.

    Parameters
    ----------
    values, reference : array_like, shape (V, ...)
        E.g. per-vertex RGB radiance ``(V, 3)``.

    Returns
    -------
    float
        0 for identical inputs; ``inf`` if the reference is all zero and the
        values are not.
    """
    x = np.asarray(values, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    num = float(np.sum((x - ref) ** 2))
    den = float(np.sum(ref * ref))
    if den == 0.0:
        return 0.0 if num == 0.0 else float("inf")
    return float(np.sqrt(num / den))


def relative_l2_per_vertex(values, reference) -> np.ndarray:
    """Per-row relative L2 error ``|x - x_ref| / |x_ref|``, shape ``(V,)``."""
    x = np.asarray(values, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    num = np.linalg.norm((x - ref).reshape(x.shape[0], -1), axis=1)
    den = np.linalg.norm(ref.reshape(ref.shape[0], -1), axis=1)
    return num / np.maximum(den, 1e-300)
