r"""Lat-long (equirectangular) environment maps: directions and exact SH projection.

Mapping (Y-up world, documented in ``docs/conventions.md``): a ``W x H`` image
covers the sphere, row 0 at the top.  Pixel ``(i, j)`` spans polar angles
:math:`\vartheta \in [\pi i/H, \pi (i+1)/H]` measured from **+y (up)** and
azimuths :math:`\varphi \in [2\pi j/W, 2\pi (j+1)/W]`, with direction

.. math:: d(\vartheta, \varphi) = (-\sin\vartheta \sin\varphi,\; \cos\vartheta,\;
          \sin\vartheta \cos\varphi).

So the image centre looks along **-z** (the glTF camera's forward), the left and
right edges along +z (behind), and a quarter image right of centre along **+x**:
standing at the origin facing -z, the image is seen as it is drawn (not mirrored).

Projection treats the image as piecewise constant over pixels and integrates
every basis function over every pixel exactly (to rounding), not at the pixel
centre:

.. math:: f_i = \sum_{\text{pixels } p} L_p \int_p y_i(s)\, ds.

In the image frame, whose polar axis is the image's up, each basis function
separates into :math:`\Lambda_{l|m|}(\vartheta)\,\mathrm{trig}_m(\varphi)`; the
:math:`\varphi` integrals over a column are closed forms and the
:math:`\vartheta` integrals of :math:`\Lambda\sin\vartheta` over a row band use
Gauss–Legendre in :math:`\vartheta` with at least :data:`ROW_GAUSS_POINTS` nodes
(the integrand is a trigonometric polynomial of degree ``l + 1`` on a band of
width ``pi/H``; the node count grows with ``order/H`` so the rule's error stays
below float64 rounding).  For the constant
(DC) term this is the exact pixel solid angle
:math:`(\cos\vartheta_i - \cos\vartheta_{i+1})\,\Delta\varphi`.  The image-frame
coefficients are then carried to the world by :mod:`shtools.lighting.frames`.
"""

from __future__ import annotations

import numpy as np

from shtools.lighting.frames import frame_transform_matrix
from shtools.sh.basis import basis, check_order

#: Minimum Gauss–Legendre nodes per pixel row for the polar integrals; more are used
#: when a row band spans a large part of a period of the highest band (see
#: :func:`_row_gauss_points`).
ROW_GAUSS_POINTS = 8

#: Rows projected per block, to bound memory on large images.
ROW_BLOCK = 256

#: Image frame (polar axis = image up, phi from the image's left edge) -> Y-up world.
#: Image-frame direction (sin t cos p, sin t sin p, cos t) maps to the world
#: direction (-sin t sin p, cos t, sin t cos p).  Its determinant is -1 (the
#: image's azimuth runs clockwise seen from above), which frames.py handles.
IMAGE_TO_WORLD = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def latlong_directions(height: int, width: int) -> np.ndarray:
    """World directions of the pixel centres of a ``width x height`` lat-long map.

    Returns
    -------
    ndarray, shape (H, W, 3)
    """
    theta = np.pi * (np.arange(height) + 0.5) / height
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    return np.stack(
        np.broadcast_arrays(-st * np.sin(phi), ct, st * np.cos(phi)), axis=-1
    )


def pixel_solid_angles(height: int, width: int) -> np.ndarray:
    """Exact solid angle of every pixel of a lat-long map (they sum to ``4*pi``).

    Returns
    -------
    ndarray, shape (H, W)
        ``(cos theta_top - cos theta_bottom) * 2*pi/W``, the same along a row.
    """
    edges = np.cos(np.pi * np.arange(height + 1) / height)
    row = (edges[:-1] - edges[1:]) * (2.0 * np.pi / width)
    return np.repeat(row[:, None], width, axis=1)


def _row_gauss_points(height: int, order: int) -> int:
    """Nodes per row band so that the polar rule's error stays below rounding.

    The integrand has frequencies up to ``order`` in theta; over a band of width
    ``pi/H`` a G-point rule errs like ``(order*pi/(2H))**(2G) / (2G)!``.  Eight
    nodes suffice while ``order*pi/H`` is below ~1 (every probe-sized image);
    coarse images at high orders get proportionally more.
    """
    return ROW_GAUSS_POINTS + int(np.ceil(2.0 * order * np.pi / height))


def _polar_integrals(height: int, order: int) -> np.ndarray:
    """``A[i, l, k] = int_{row i} Lambda_{l k}(t) sin t dt`` for ``k = |m| >= 0``.

    Returns
    -------
    ndarray, shape (H, n*n)
        Indexed by the flat index of ``(l, |m|)``; columns of ``m < 0`` repeat
        those of ``|m|`` so that the array lines up with the flat SH index.
    """
    x, w = np.polynomial.legendre.leggauss(_row_gauss_points(height, order))
    top = np.pi * np.arange(height) / height
    half = 0.5 * np.pi / height
    t = top[:, None] + half * (x + 1.0)  # (H, G) nodes inside each row band
    # At phi = 0 the image-frame basis is Lambda_{l|m|}(t) for m >= 0 (cos(0) = 1).
    dirs = np.stack(np.broadcast_arrays(np.sin(t), 0.0, np.cos(t)), axis=-1)
    lam = basis(dirs, order)  # (H, G, n*n); zero at m < 0 here
    weights = half * w * np.sin(t)  # (H, G)
    integral = np.einsum("hg,hgi->hi", weights, lam)
    l = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    m = np.concatenate([np.arange(-k, k + 1) for k in range(order)])
    return integral[:, l * l + l + np.abs(m)]


def _azimuth_integrals(width: int, order: int) -> np.ndarray:
    """``B[j, i] = int_{column j} trig_m(p) dp`` for the ``m`` of each flat index.

    ``trig_m`` is ``cos(m p)`` for ``m >= 0`` and ``sin(|m| p)`` for ``m < 0``.

    Returns
    -------
    ndarray, shape (W, n*n)
    """
    edges = 2.0 * np.pi * np.arange(width + 1) / width
    m = np.concatenate([np.arange(-k, k + 1) for k in range(order)])
    k = np.abs(m).astype(np.float64)
    p0, p1 = edges[:-1, None], edges[1:, None]
    safe_k = np.where(k == 0, 1.0, k)
    cos_part = np.where(k == 0, p1 - p0, (np.sin(k * p1) - np.sin(k * p0)) / safe_k)
    sin_part = (np.cos(k * p0) - np.cos(k * p1)) / safe_k
    return np.where(m < 0, sin_part, cos_part)


def project_latlong(image, order: int, rotation=None) -> np.ndarray:
    """Project a lat-long environment map to SH, integrating over pixels exactly.

    Parameters
    ----------
    image : array_like, shape (H, W, C)
        Radiance per pixel (e.g. linear RGB, ``C = 3``), row 0 at the top.
        Any ``H`` and ``W`` work; lat-long maps have ``W = 2H``.
    order : int
        SH order ``n``.
    rotation : array_like, shape (3, 3), optional
        Orthogonal matrix applied to the environment after the standard mapping
        (a direction ``d`` of the image ends up at ``rotation @ d``).

    Returns
    -------
    ndarray, shape (n*n, C)
        Coefficients ``int L(s) y_i(s) ds`` of the piecewise-constant image in
        the Y-up world.
    """
    order = check_order(order)
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[..., None]
    height, width, channels = img.shape
    polar = _polar_integrals(height, order)  # (H, n*n)
    azimuth = np.ascontiguousarray(_azimuth_integrals(width, order))  # (W, n*n)
    coeffs = np.zeros((order * order, channels))
    for start in range(0, height, ROW_BLOCK):
        # (rows, C, W) @ (W, n*n): sum_j L[i, j, c] B[j, k] as one BLAS matmul per block,
        # then weight by the row integrals and sum over rows.
        block = np.ascontiguousarray(img[start : start + ROW_BLOCK].transpose(0, 2, 1),
                                     dtype=np.float64)
        rows = block.shape[0]
        # one 2-D GEMM (a stacked matmul can miss BLAS and be orders of magnitude slower)
        per_row = (block.reshape(rows * channels, width) @ azimuth).reshape(
            rows, channels, -1)  # (rows, C, n*n)
        coeffs += np.einsum("hk,hck->kc", polar[start : start + ROW_BLOCK], per_row)
    to_world = IMAGE_TO_WORLD
    if rotation is not None:
        to_world = np.asarray(rotation, dtype=np.float64) @ to_world
    return frame_transform_matrix(to_world, order) @ coeffs
