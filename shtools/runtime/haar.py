r"""All-frequency (Haar) shadow fields at run time: lookup, products, shading (NumPy only).

A :class:`HaarField` holds, per shell, the kept Haar coefficients of every
sample's occlusion map (flat indices and 8-bit values,
:mod:`shtools.fields.haar`).  At a receiver point its visibility map is the
**bilinear blend of the sparse coefficient vectors** of the four nearest
samples on each of the two nearest shells (the same weights as the SH
field's lookup, :func:`shtools.runtime.fields.shell_bilinear`), summed into
one dense coefficient vector and transformed back with :func:`ihaar2`: the
blend of the reconstructed maps, since the transform is linear.  Inside the
first shell the first shell is used; beyond the last, the map fades to
unoccluded over one shell spacing, as for SH fields.

Shading (:func:`haar_radiance`): the integral of lighting, visibility and
the cosine transfer over the map's cells in the object's frame,
``(1/pi) sum_q w_q L_q V_q max(0, N . s_q)``.  Posed objects (world-frame
maps, rotation, several occluders, SH blockers mixed in) and Ng et al.'s
wavelet triple product are in :mod:`shtools.runtime.haar_shading` and
:mod:`shtools.runtime.haar_triple`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shtools.runtime.fields import shell_bilinear


def haar2(maps) -> np.ndarray:
    """Nonstandard 2-D Haar transform of square maps, shape ``(..., N, N)`` (N a power of 2).

    Layout: level by level in place (Mallat order): ``[0, 0]`` is the overall
    scaling coefficient; at size ``n`` the quadrants ``[:h, h:n]``, ``[h:n, :h]``,
    ``[h:n, h:n]`` (``h = n/2``) hold the horizontal, vertical and diagonal
    wavelets of the ``n x n`` level.  Orthonormal in the pixel inner product.
    """
    out = np.array(maps, dtype=np.float64)
    n = out.shape[-1]
    while n > 1:
        a = out[..., :n, :n]
        tl, tr = a[..., 0::2, 0::2], a[..., 0::2, 1::2]
        bl, br = a[..., 1::2, 0::2], a[..., 1::2, 1::2]
        h = n // 2
        parts = ((tl + tr + bl + br) / 2, (tl - tr + bl - br) / 2,
                 (tl + tr - bl - br) / 2, (tl - tr - bl + br) / 2)
        out[..., :h, :h], out[..., :h, h:n], out[..., h:n, :h], out[..., h:n, h:n] = parts
        n = h
    return out


def ihaar2(coeffs) -> np.ndarray:
    """Inverse of :func:`haar2`, shape ``(..., N, N)``."""
    out = np.array(coeffs, dtype=np.float64)
    N = out.shape[-1]
    n = 1
    while n < N:
        s, hz = out[..., :n, :n].copy(), out[..., :n, n:2 * n].copy()
        vt, dg = out[..., n:2 * n, :n].copy(), out[..., n:2 * n, n:2 * n].copy()
        blk = out[..., :2 * n, :2 * n]
        blk[..., 0::2, 0::2] = (s + hz + vt + dg) / 2
        blk[..., 0::2, 1::2] = (s - hz + vt - dg) / 2
        blk[..., 1::2, 0::2] = (s + hz - vt - dg) / 2
        blk[..., 1::2, 1::2] = (s - hz - vt + dg) / 2
        n *= 2
    return out


@dataclass
class HaarField:
    """An all-frequency shadow field (quantized, as stored).

    Attributes
    ----------
    center : ndarray, shape (3,)
    bounding_radius : float
    shell_radii : ndarray, shape (C,)
    resolution : ndarray of int, shape (C,)
    index : list of ndarray, each (R_c, R_c, K) uint16
        Flat indices of the kept coefficients of each sample's map.
    q : list of ndarray, each (R_c, R_c, K) uint8
    offset, step : ndarray, shape (C, 2) float32
        Dequantization of column 0 (the overall scaling coefficient when kept)
        and of the other columns.
    map_size : int
    """

    center: np.ndarray
    bounding_radius: float
    shell_radii: np.ndarray
    resolution: np.ndarray
    index: list
    q: list
    offset: np.ndarray
    step: np.ndarray
    map_size: int

    def stored_bytes(self) -> int:
        """``sum_c R_c^2 K (1 + 2)``: an 8-bit value and a uint16 index per kept coefficient."""
        K = int(self.index[0].shape[-1])
        return int(sum(int(r) ** 2 for r in self.resolution) * K * 3)

    def values(self, c: int) -> np.ndarray:
        """Dequantized kept coefficients of shell ``c``, shape ``(R_c*R_c, K)`` float32."""
        q = np.asarray(self.q[c], np.float32).reshape(-1, self.q[c].shape[-1])
        out = self.offset[c, 1] + q * self.step[c, 1]
        out[:, 0] = self.offset[c, 0] + q[:, 0] * self.step[c, 0]
        return out

    @classmethod
    def from_asset(cls, path) -> HaarField:
        """Read a ``haar`` asset (:mod:`shtools.data_formats.haar`)."""
        from shtools.data_formats.haar import read_haar_asset

        d = read_haar_asset(path)
        return cls(d["center"], d["bounding_radius"], d["shell_radii"], d["resolution"],
                   d["index"], d["q"], d["offset"], d["step"], d["map_size"])

    @property
    def fade_end(self) -> float:
        """Distance from the centre beyond which the field is exactly unoccluded."""
        r = np.asarray(self.shell_radii, dtype=np.float64)
        return float(r[-1] + (r[1] - r[0] if len(r) > 1 else r[0]))

    def visibility_maps(self, points) -> np.ndarray:
        """Visibility maps at object-frame points, shape ``(P, N*N)`` float64, in [0, 1].

        Cell ``(s, t)`` of a map is the direction ``theta_s = (s + 1/2) pi / N``
        from ``+z``, ``phi_t = (t + 1/2) 2 pi / N`` (the field's direction map).
        """
        N = self.map_size
        maps = ihaar2(self.coefficients(points).reshape(-1, N, N)).reshape(-1, N * N)
        # truncation rings slightly outside [0, 1], which a visibility cannot be (and
        # products must not amplify)
        return np.clip(maps, 0.0, 1.0)

    def coefficients(self, points) -> np.ndarray:
        """Haar coefficients of the visibility maps at object-frame points, ``(P, N*N)``.

        The bilinear blend of the kept coefficients of the nearest samples on the two
        nearest shells (:meth:`sparse_terms`), faded to the unoccluded map (scaling
        coefficient ``N``) beyond the last shell; not clipped (the stored function).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        N = self.map_size
        terms, fade = self.sparse_terms(p)
        coeff = np.zeros((p.shape[0], N * N))
        for rows, w, kidx, vals in terms:
            # one sample's kept indices are distinct: no repeated (row, index) pair within
            # one term, so a buffered += is exact
            coeff[rows[:, None], kidx] += vals * w[:, None]
        coeff[:, 0] += fade * N
        return coeff

    def sparse_terms(self, points) -> tuple[list, np.ndarray]:
        """The weighted sparse samples whose sum is each point's map, and the fade.

        Parameters
        ----------
        points : array_like, shape (P, 3)
            Object frame.

        Returns
        -------
        terms : list of (rows (n,), weight (n,), index (n, K), value (n, K))
            Per shell and bilinear corner: the receiver rows, their weights and the
            kept coefficients (flat positions, dequantized values) of the sample used.
        fade : ndarray, shape (P,)
            Weight of the unoccluded map (beyond the last shell), the terms' weights
            already scaled by ``1 - fade``.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        radii = np.asarray(self.shell_radii, dtype=np.float64)
        C = radii.shape[0]
        rel = p - self.center
        d = np.linalg.norm(rel, axis=1)
        safe = np.where(d > 0, d, 1.0)
        theta = np.arccos(np.clip(rel[:, 2] / safe, -1, 1))
        phi = np.arctan2(rel[:, 1], rel[:, 0])
        spacing = float(radii[1] - radii[0]) if C > 1 else float(radii[0])
        x = np.clip((d - radii[0]) / spacing, 0, C - 1) if C > 1 else np.zeros_like(d)
        c1 = np.minimum(np.floor(x).astype(np.int64), max(C - 2, 0))
        w2 = x - c1 if C > 1 else np.zeros_like(d)
        fade = np.clip((d - radii[-1]) / spacing, 0, 1)
        terms = []
        for off, wshell in ((0, 1 - w2), (1, w2)):
            c = np.minimum(c1 + off, C - 1)
            for shell in np.unique(c):
                sel = np.flatnonzero((c == shell) & (wshell > 0))
                if sel.size == 0:
                    continue
                idx, wb = shell_bilinear(theta[sel], phi[sel], int(self.resolution[shell]))
                vals = self.values(int(shell))
                kidx = np.asarray(self.index[shell], np.int64).reshape(vals.shape)
                for k in range(4):
                    w = wb[:, k] * wshell[sel] * (1 - fade[sel])
                    terms.append((sel, w, kidx[idx[:, k]], vals[idx[:, k]]))
        return terms, fade


def haar_radiance(visibility_maps, env_map, normals, dirs, weights) -> np.ndarray:
    """White-Lambertian radiance from per-receiver visibility maps, shape ``(V, 3)``.

    Parameters
    ----------
    visibility_maps : array_like, shape (V, Q)
        Product of every occluder's map (cell-wise), in the map's directions.
    env_map : array_like, shape (Q, 3)
        Environment radiance averaged over each cell.
    normals : array_like, shape (V, 3)
    dirs, weights : array_like, shape (Q, 3), (Q,)
        Cell directions and solid angles.
    """
    cos = np.maximum(np.asarray(normals, dtype=np.float64) @ np.asarray(dirs).T, 0.0)
    return (np.asarray(visibility_maps) * cos * np.asarray(weights)) @ np.asarray(env_map) \
        / math.pi
