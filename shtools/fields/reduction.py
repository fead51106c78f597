r"""Adaptive per-shell reduction (Tamura et al. Sec. 4) and the error of eq. (1).

One shell's OCVs ``O (R, R, n*n)`` on the cell-centred (theta, phi) grid:

1. ``Õ = box2x2(O)`` -- the new ``R/2 x R/2`` samples; on a cell-centred grid
   the bilinear interpolation of the four nearest samples at a new cell centre
   *is* the 2 x 2 average (step 4);
2. ``Ô`` = ``Õ`` interpolated back at every current sample position with the
   **runtime's own lookup** (:func:`shtools.runtime.fields.interpolate_grid`:
   theta clamps, phi wraps), so the threshold holds for what the runtime
   reconstructs (step 5; Tamura et al. clamp phi as well -- our lookup wraps);
3. ``e = (1/4 pi) int |Ô . y - O . y|`` per sample (eq. 1) on a fixed
   quadrature (:data:`ERROR_QUAD_DEGREE`);
4. if every ``e < threshold`` the new samples replace the current ones and R
   halves; otherwise R stays (step 7).  ``R`` never goes below
   ``min_resolution`` (Table 1 never goes below 8; the paper does not state it).

Tamura et al. compare each level with the previous one, so errors can add up; the
cumulative error against the full-resolution samples is reported per shell,
and ``cumulative=True`` (beyond the paper) compares every level against them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shtools.runtime.fields import grid_angles, interpolate_grid
from shtools.sh import basis, sphere_quadrature

#: Degree of the quadrature of eq. (1) (``sphere_quadrature(32)``: 561 points).
#: |.| is not polynomial; against degree 64 it changes the error by < 2 % of its
#: value (checked in the tests), far below the threshold's resolution.
ERROR_QUAD_DEGREE = 32


@dataclass
class ShellReduction:
    """Result of :func:`reduce_shell`.

    Attributes
    ----------
    grid : ndarray, shape (R_c, R_c, n*n)
        The kept samples (unquantized).
    resolution : int
    level_errors : list of float
        Largest eq. (1) error of each tested halving (the last one failed
        unless R reached the floor).
    cumulative_error : float
        Largest eq. (1) error of the kept samples, interpolated, against the
        initial samples.
    """

    grid: np.ndarray
    resolution: int
    level_errors: list = field(default_factory=list)
    cumulative_error: float = 0.0


def l1_error(a, b, degree: int = ERROR_QUAD_DEGREE, channels: int = 1) -> np.ndarray:
    """Eq. (1): ``(1/4 pi) int |(a - b) . y(s)| ds`` per row, shape ``(...)``.

    Parameters
    ----------
    a, b : array_like, shape (..., channels*n*n)
        ``channels`` SH vectors per row, channel-major (an RGB radiance vector
        is its red, green and blue coefficients in turn).
    degree : int
        Quadrature degree.
    channels : int
        With several channels the error of a row is the largest of theirs.
    """
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    n = math.isqrt(diff.shape[-1] // channels)
    dirs, w = sphere_quadrature(degree)
    y = basis(dirs, n)
    if channels == 1:
        return np.abs(diff @ y.T) @ w / (4 * math.pi)
    diff = diff.reshape((*diff.shape[:-1], channels, n * n))
    return (np.abs(diff @ y.T) @ w / (4 * math.pi)).max(axis=-1)


def box2(grid) -> np.ndarray:
    """2 x 2 block average, ``(R, R, K) -> (R/2, R/2, K)``."""
    g = np.asarray(grid, dtype=np.float64)
    R = g.shape[0]
    return g.reshape(R // 2, 2, R // 2, 2, -1).mean(axis=(1, 3))


def upsample(coarse, res: int) -> np.ndarray:
    """The runtime's interpolation of a coarse grid at a finer grid's samples, ``(res, res, K)``."""
    theta, phi = grid_angles(res)
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    return interpolate_grid(coarse, tt.ravel(), pp.ravel()).reshape(res, res, -1)


def reduce_shell(grid, threshold: float, min_resolution: int = 8, *,
                 cumulative: bool = False, degree: int = ERROR_QUAD_DEGREE,
                 channels: int = 1) -> ShellReduction:
    """Halve one shell's resolution while eq. (1) stays below ``threshold`` everywhere.

    Parameters
    ----------
    grid : array_like, shape (R, R, channels*n*n)
        Initial OCVs (or RCVs, one SH vector per colour channel), R a power of two.
    threshold : float
        > 0 (Tamura et al. use 0.01).
    min_resolution : int
        Floor of R (a power of two).
    cumulative : bool
        Compare every level with the initial samples instead of the previous level.
    degree : int
        Quadrature degree of eq. (1).
    channels : int
        SH vectors per sample (3 for an RGB radiance field; the error is the
        largest channel's).

    Returns
    -------
    ShellReduction
    """
    initial = np.asarray(grid, dtype=np.float64)
    R0 = initial.shape[0]
    current, R = initial, R0
    errors = []
    while R > min_resolution and R % 2 == 0:
        new = box2(current)
        ref, res = (initial, R0) if cumulative else (current, R)
        err = float(l1_error(upsample(new, res), ref, degree, channels).max())
        errors.append(err)
        if not err < threshold:
            break
        current, R = new, R // 2
    total = 0.0
    if R < R0:
        total = float(l1_error(upsample(current, R0), initial, degree, channels).max())
    return ShellReduction(current, R, errors, total)
