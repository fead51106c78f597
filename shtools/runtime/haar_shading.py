r"""All-frequency shadow fields posed in a scene: world-frame maps, products, shading (NumPy only).

The shading frame is the world, parameterised like a field's own map
(``M x M`` cells, theta from world ``+z``, phi from ``+x`` towards ``+y``;
:func:`map_directions`), so an unrotated object's maps are used as stored.
A rotated object's map is resampled cell by cell (each world cell takes the
object-frame cell its direction falls in: nearest-cell resampling, exact for
rotations about ``z`` by whole cells).

Several occluders multiply, as the stored functions (not clipped, so that
every scheme below computes the same number): :func:`combined_maps` in the
pixel domain, :func:`combined_coefficients` in the Haar basis with Ng et
al.'s double product (:func:`shtools.runtime.haar_triple.haar_product`).
Both equal the product of reconstructed maps (the tests).  SH visibility of
the scene's other blockers (sphere sets, SH fields, self-visibility) is
evaluated on the map's cells (clipped to [0, 1]: SH ringing) and multiplied
in the same way: the SH factor stays low-frequency, the Haar factor
all-frequency.

Shading with an environment given per cell (``(Q, 3)`` mean radiance):

* ``"cells"`` (:func:`shade_cells`): ``(1/pi) sum_q w_q L_q V_q max(0, N.s_q)``;
* ``"triple"`` (:class:`TripleShader`): Ng et al.'s wavelet triple product
  of lighting, visibility and cosine transfer, computed as the dot product of
  the visibility's Haar coefficients with the Haar coefficients of
  lighting x transfer (:func:`~shtools.runtime.haar_triple.haar_product`),
  which depend only on the receiver normal and are kept while the normals do
  not change (static receivers); for one unrotated field straight from its
  kept coefficients (:meth:`TripleShader.radiance_sparse`), ``O(K)`` per
  sample blended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from shtools.runtime.haar import HaarField, haar2, ihaar2
from shtools.runtime.haar_triple import haar_product

#: Largest cache of lighting x transfer coefficients a TripleShader keeps, bytes.
TRIPLE_CACHE_BYTES = 256 << 20


def map_directions(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell-centre directions ``(M*M, 3)`` and exact cell solid angles ``(M*M,)`` of a map."""
    theta = (np.arange(size) + 0.5) * math.pi / size
    phi = (np.arange(size) + 0.5) * 2 * math.pi / size
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    edges = np.cos(np.arange(size + 1) * math.pi / size)
    band = (edges[:-1] - edges[1:]) * (2 * math.pi / size)
    return dirs.reshape(-1, 3), np.repeat(band, size)


def cell_of(dirs, size: int) -> np.ndarray:
    """Flat map cell of each unit direction, shape ``(D,)`` int64."""
    d = np.asarray(dirs, dtype=np.float64)
    row = np.minimum((np.arccos(np.clip(d[:, 2], -1, 1)) / math.pi * size).astype(np.int64),
                     size - 1)
    col = np.minimum(((np.arctan2(d[:, 1], d[:, 0]) % (2 * math.pi)) / (2 * math.pi)
                      * size).astype(np.int64), size - 1)
    return row * size + col


@dataclass
class HaarBlocker:
    """A rigid object with an all-frequency (Haar) shadow field, posed for one frame.

    It is neutral in SH accumulation (:meth:`log_visibility` is zero): the
    environment is shaded through :func:`combined_maps` instead.

    Parameters
    ----------
    table : HaarField
    rotation : array_like, shape (3, 3)
    translation : array_like, shape (3,)
    scale : float
    skip_rows : array_like of int, optional
        Receiver rows of the object itself (inside the innermost shells: never looked up).
    """

    table: HaarField
    rotation: Any
    translation: Any
    scale: float = 1.0
    skip_rows: Any = None
    #: marks a blocker shaded in the map basis (the baker's test)
    all_frequency: ClassVar[bool] = True

    @classmethod
    def from_matrix(cls, table: HaarField, matrix, skip_rows=None) -> HaarBlocker:
        """Pose from a 4x4 object-to-world matrix (rigid + uniform scale, as SH fields)."""
        from shtools.errors import InputError
        from shtools.runtime.fields import SCALE_TOL

        m = np.asarray(matrix, dtype=np.float64)
        scales = np.linalg.norm(m[:3, :3], axis=0)
        s = float(scales.mean())
        if not s > 0 or np.ptp(scales) > SCALE_TOL * s:
            raise InputError("shadow fields need a rigid pose with a uniform scale; got scales "
                             f"{np.round(scales, 6).tolist()} (use a sphere-set blocker for a "
                             "stretched object)")
        R = m[:3, :3] / s
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise InputError("shadow fields need a rigid pose (rotation, uniform scale, "
                             "translation); this transform shears or mirrors")
        return cls(table, R, m[:3, 3].copy(), s, skip_rows)

    @property
    def map_size(self) -> int:
        return int(self.table.map_size)

    def log_visibility(self, points, normals, order: int) -> np.ndarray:
        """Zero ``(P, order^2)``: the field does not enter the SH visibility."""
        return np.zeros((len(points), order * order), dtype=np.float32)

    def _rows(self, points):
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        rows = np.ones(len(p), dtype=bool)
        if self.skip_rows is not None:
            rows[np.asarray(self.skip_rows, dtype=np.int64)] = False
        center = self.rotation @ self.table.center * self.scale + self.translation
        rows &= np.linalg.norm(p - center, axis=1) < self.table.fade_end * self.scale
        return p, np.flatnonzero(rows)

    @property
    def unrotated(self) -> bool:
        """The object's frame is the world's up to translation and scale (maps used as stored)."""
        return bool(np.allclose(self.rotation, np.eye(3), atol=1e-9))

    def _resample(self) -> np.ndarray | None:
        """World cell -> object cell index ``(Q,)``, or None when the object is unrotated."""
        if self.unrotated:
            return None
        dirs, _ = map_directions(self.map_size)
        return cell_of(dirs @ self.rotation, self.map_size)  # R^T d per row

    def maps(self, points) -> np.ndarray:
        """World-frame visibility maps at world points, shape ``(P, M*M)``, not clipped."""
        p, rows = self._rows(points)
        M = self.map_size
        out = np.ones((len(p), M * M))
        if rows.size:
            local = (p[rows] - self.translation) @ self.rotation / self.scale
            m = ihaar2(self.table.coefficients(local).reshape(-1, M, M)).reshape(-1, M * M)
            index = self._resample()
            out[rows] = m if index is None else m[:, index]
        return out

    def sparse_terms(self, points) -> tuple[list, np.ndarray]:
        """:meth:`HaarField.sparse_terms` at world points (rows skipped or out of reach:
        fade 1, unoccluded); an unrotated object only (its maps are the world's)."""
        if not self.unrotated:
            raise ValueError("sparse terms are in the object's frame; resample a rotated "
                             "object's maps (coefficients) instead")
        p, rows = self._rows(points)
        fade = np.ones(len(p))
        if not rows.size:
            return [], fade
        local = (p[rows] - self.translation) @ self.rotation / self.scale
        terms, f = self.table.sparse_terms(local)
        fade[rows] = f
        return [(rows[r], w, k, v) for r, w, k, v in terms], fade

    def coefficients(self, points) -> np.ndarray:
        """World-frame Haar coefficients at world points, shape ``(P, M, M)``."""
        p, rows = self._rows(points)
        M = self.map_size
        out = np.zeros((len(p), M, M))
        out[:, 0, 0] = M  # unoccluded
        if rows.size:
            local = (p[rows] - self.translation) @ self.rotation / self.scale
            c = self.table.coefficients(local).reshape(-1, M, M)
            index = self._resample()
            if index is not None:
                c = haar2(ihaar2(c).reshape(-1, M * M)[:, index].reshape(-1, M, M))
            out[rows] = c
        return out


def sh_on_cells(visibility, size: int) -> np.ndarray:
    """SH visibility ``(P, n*n)`` evaluated on the map's cells, clipped to [0, 1]: ``(P, M*M)``."""
    from shtools.sh import basis

    g = np.asarray(visibility, dtype=np.float64)
    n = math.isqrt(g.shape[1])
    return np.clip(g @ basis(map_directions(size)[0], n).T, 0.0, 1.0)


def combined_maps(blockers, points, sh_visibility=None) -> np.ndarray:
    """Pixel-domain product of every blocker's map, ``(P, M*M)``.

    Parameters
    ----------
    blockers : list of HaarBlocker
        The same ``map_size``.
    points : array_like, shape (P, 3)
    sh_visibility : array_like, shape (P, n*n), optional
        The other blockers' SH visibility, multiplied in on the cells.
    """
    M = blockers[0].map_size
    out = np.ones((len(points), M * M))
    for b in blockers:
        out *= b.maps(points)
    if sh_visibility is not None:
        out *= sh_on_cells(sh_visibility, M)
    return out


def combined_coefficients(blockers, points, sh_visibility=None) -> np.ndarray:
    """Haar-domain product (Ng's double product) of every blocker's function, ``(P, M, M)``."""
    M = blockers[0].map_size
    out = None
    for b in blockers:
        c = b.coefficients(points)
        out = c if out is None else haar_product(out, c)
    if sh_visibility is not None:
        out = haar_product(out, haar2(sh_on_cells(sh_visibility, M).reshape(-1, M, M)))
    return out


def cosine_transfer(normals, size: int) -> np.ndarray:
    """``w_q max(0, N . s_q) / pi`` per receiver and cell, shape ``(P, M*M)``."""
    dirs, w = map_directions(size)
    return np.maximum(np.asarray(normals, dtype=np.float64) @ dirs.T, 0.0) * w / math.pi


def shade_cells(maps, env_cells, normals) -> np.ndarray:
    """White-Lambertian radiance ``(P, 3)`` from world-frame visibility maps ``(P, M*M)``
    and the environment's mean radiance per cell ``(M*M, 3)``."""
    m = np.asarray(maps, dtype=np.float64)
    M = math.isqrt(m.shape[1])
    return (m * cosine_transfer(normals, M)) @ np.asarray(env_cells, dtype=np.float64)


class TripleShader:
    """Ng et al.'s triple product of lighting, visibility and transfer in the Haar basis.

    ``radiance = sum_k V_k W_k`` with ``W = haar_product(L, T)``: the Haar
    coefficients of lighting x cosine transfer (solid angles folded into ``T``),
    one per distinct receiver normal, kept while the normals and the lighting stay
    the same (up to :data:`TRIPLE_CACHE_BYTES`).

    Parameters
    ----------
    env_cells : array_like, shape (M*M, 3)
        Mean radiance per cell of the world-frame map.
    """

    def __init__(self, env_cells):
        e = np.asarray(env_cells, dtype=np.float64)
        self.size = math.isqrt(e.shape[0])
        M = self.size
        self.light = haar2(e.T.reshape(3, M, M))  # (3, M, M)
        self._normals = None
        self._w = None
        self._inverse = None

    def lit_transfer(self, normals) -> tuple[np.ndarray, np.ndarray]:
        """``W (U, 3, M*M)`` float32 per distinct normal and the row -> normal index ``(P,)``."""
        nrm = np.asarray(normals, dtype=np.float64)
        if self._normals is not None and np.array_equal(nrm, self._normals):
            return self._w, self._inverse
        M = self.size
        uniq, inverse = np.unique(nrm, axis=0, return_inverse=True)
        w = np.empty((len(uniq), 3, M * M), dtype=np.float32)
        for s in range(0, len(uniq), 128):
            t = haar2(cosine_transfer(uniq[s:s + 128], M).reshape(-1, 1, M, M))
            w[s:s + 128] = haar_product(self.light[None], t).reshape(-1, 3, M * M)
        if w.nbytes <= TRIPLE_CACHE_BYTES:
            self._normals, self._w, self._inverse = nrm.copy(), w, inverse.ravel()
        return w, inverse.ravel()

    def radiance_sparse(self, terms, fade, normals) -> np.ndarray:
        """Radiance ``(P, 3)`` straight from kept coefficients (:meth:`HaarBlocker.sparse_terms`).

        ``sum_terms weight sum_k value_k W[index_k]`` plus ``fade N W[0]``: ``O(K)``
        per sample blended instead of ``O(M^2)``.
        """
        w, inverse = self.lit_transfer(normals)
        out = np.asarray(fade, dtype=np.float64)[:, None] * self.size * w[inverse, :, 0]
        for rows, weight, index, value in terms:
            lit = w[inverse[rows][:, None], :, index]  # (n, K, 3)
            out[rows] += np.einsum("nkc,nk->nc", lit, value * weight[:, None])
        return out

    def radiance(self, coefficients, normals) -> np.ndarray:
        """White-Lambertian radiance ``(P, 3)`` from world-frame Haar visibility ``(P, M, M)``."""
        c = np.asarray(coefficients, dtype=np.float64).reshape(len(normals), -1)
        w, inverse = self.lit_transfer(normals)
        out = np.empty((len(c), 3))
        for s in range(0, len(c), 512):
            out[s:s + 512] = np.einsum("pk,pck->pc", c[s:s + 512], w[inverse[s:s + 512]])
        return out
