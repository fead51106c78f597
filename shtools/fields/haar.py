r"""All-frequency occlusion maps in a 2-D Haar basis (Tamura et al. "A" rows; Ng et al. 2004).

Per sample, the binary visibility on the field's own ``M x M`` (theta, phi)
map (:func:`shtools.fields.sampling.direction_map`: cell-centred, theta rows
from the pole axis ``+z``) is transformed with the **nonstandard** 2-D Haar
decomposition (Ng et al.: each level splits every 2 x 2 block into one
scaling and three wavelet coefficients, orthonormal in the pixel inner
product), and only the largest ``keep`` fraction of the coefficients by
magnitude is kept (5 %: 205 of 4096).

Storage (:func:`quantize_sparse`): per sample the kept coefficients' flat
indices (uint16) and their values at 8 bits -- the overall scaling
coefficient on its own linear range per shell (it is the map's mean and
dwarfs the rest), the others on one shared range per shell.

The per-shell reduction is the occlusion field's
(:func:`shtools.fields.reduction.reduce_shell`) with eq. (1) evaluated on the
**reconstructed maps**: :func:`map_l1_error` is the solid-angle weighted mean
absolute difference over the map's cells, and the 2 x 2 averages are
truncated to the kept fraction again before they are compared, as they would
be stored.
"""

from __future__ import annotations

import math

import numpy as np

from shtools.runtime.haar import HaarField, haar2, ihaar2

__all__ = ["haar2", "ihaar2"]  # the transform lives with the runtime lookup


def kept_count(size: int, keep: float) -> int:
    """Coefficients kept per ``size x size`` map: ``round(keep * size**2)``, at least 1."""
    return max(1, round(keep * size * size))


def truncate(coeffs, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` largest coefficients (by magnitude) of each map.

    Parameters
    ----------
    coeffs : array_like, shape (P, N, N)
    count : int

    Returns
    -------
    index : ndarray of uint16, shape (P, count)
        Flat indices, ascending within each map (ties broken by index).
    value : ndarray, shape (P, count)
    """
    c = np.asarray(coeffs, dtype=np.float64).reshape(np.shape(coeffs)[0], -1)
    # a stable order: by magnitude, then by index, so equal magnitudes give fixed bytes
    order = np.lexsort((np.broadcast_to(np.arange(c.shape[1]), c.shape), -np.abs(c)), axis=1)
    idx = np.sort(order[:, :count], axis=1)
    return idx.astype(np.uint16), np.take_along_axis(c, idx, axis=1)


def reconstruct(index, value, size: int) -> np.ndarray:
    """Maps from sparse coefficients, shape ``(P, size, size)``."""
    idx = np.asarray(index, dtype=np.int64)
    full = np.zeros((idx.shape[0], size * size))
    np.put_along_axis(full, idx, np.asarray(value, dtype=np.float64), axis=1)
    return ihaar2(full.reshape(-1, size, size))


def truncated_maps(maps, keep: float) -> np.ndarray:
    """Maps as stored at the kept fraction (transform, truncate, reconstruct), ``(P, N, N)``."""
    m = np.asarray(maps, dtype=np.float64)
    size = m.shape[-1]
    idx, val = truncate(haar2(m), kept_count(size, keep))
    return reconstruct(idx, val, size)


def map_l1_error(a, b, weights) -> np.ndarray:
    """Eq. (1) on maps: ``(1/4 pi) sum_q w_q |a_q - b_q|`` per row, shape ``(P,)``.

    Parameters
    ----------
    a, b : array_like, shape (P, N*N)
    weights : array_like, shape (N*N,)
        Cell solid angles (sum ``4 pi``).
    """
    diff = np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64))
    return diff @ np.asarray(weights, dtype=np.float64) / (4 * math.pi)


def quantize_sparse(value, bits: int = 8) -> dict:
    """8-bit values of one shell's kept coefficients (the DC on its own range).

    Parameters
    ----------
    value : array_like, shape (P, K)
        Kept coefficients per sample; column 0 must be the overall scaling
        coefficient (flat index 0, which :func:`truncate` puts first when kept).

    Returns
    -------
    dict
        ``q (P, K) uint8``, ``offset (2,)``, ``step (2,)`` float32 (DC, others).
    """
    v = np.asarray(value, dtype=np.float64)
    levels = (1 << bits) - 1
    q = np.empty(v.shape, dtype=np.uint8)
    offset, step = np.zeros(2, np.float32), np.zeros(2, np.float32)
    for k, part in enumerate((v[:, :1], v[:, 1:])):
        if part.size == 0:
            continue
        lo, hi = part.min(), part.max()
        st = (hi - lo) / levels
        offset[k], step[k] = lo, st
        safe = st if st > 0 else 1.0
        q[:, slice(0, 1) if k == 0 else slice(1, None)] = np.clip(
            np.rint((part - lo) / safe), 0, levels).astype(np.uint8)
    return {"q": q, "offset": offset, "step": step}


def dequantize_sparse(q, offset, step) -> np.ndarray:
    """Inverse of :func:`quantize_sparse`, shape ``(P, K)`` float32."""
    q = np.asarray(q, dtype=np.float32)
    out = np.empty_like(q)
    out[:, :1] = offset[0] + q[:, :1] * step[0]
    out[:, 1:] = offset[1] + q[:, 1:] * step[1]
    return out


#: Fine samples per chunk of the reduction's interpolation (bounds the (P, 4, N*N) gather).
ERROR_CHUNK = 256


def reduce_haar_shell(maps, threshold: float, weights, keep: float = 0.05,
                      min_resolution: int = 8, *, cumulative: bool = False):
    """Tamura's per-shell reduction with eq. (1) on reconstructed Haar maps.

    Parameters
    ----------
    maps : array_like, shape (R, R, N*N)
        Each sample's stored map (:func:`truncated_maps`), flattened.
    threshold : float
    weights : array_like, shape (N*N,)
        Cell solid angles of the map.
    keep : float
        Kept fraction of the coefficients (the 2 x 2 averages are truncated to
        it again before they are compared).
    min_resolution : int
    cumulative : bool
        Compare every level with the initial samples.

    Returns
    -------
    shtools.fields.reduction.ShellReduction
        ``grid`` holds the kept samples' stored maps, ``(R_c, R_c, N*N)``.
    """
    from shtools.fields.reduction import ShellReduction, box2
    from shtools.runtime.fields import grid_angles, interpolate_grid

    initial = np.asarray(maps, dtype=np.float64)
    R0, Q = initial.shape[0], initial.shape[-1]
    size = math.isqrt(Q)

    def error(coarse, fine):
        R = fine.shape[0]
        theta, phi = grid_angles(R)
        tt, pp = (a.ravel() for a in np.meshgrid(theta, phi, indexing="ij"))
        flat = fine.reshape(R * R, Q)
        worst = 0.0
        for s in range(0, R * R, ERROR_CHUNK):
            up = interpolate_grid(coarse, tt[s:s + ERROR_CHUNK], pp[s:s + ERROR_CHUNK])
            worst = max(worst, float(map_l1_error(up, flat[s:s + ERROR_CHUNK], weights).max()))
        return worst

    current, R, errors = initial, R0, []
    while R > min_resolution and R % 2 == 0:
        new = box2(current)
        new = truncated_maps(new.reshape(-1, size, size), keep).reshape(new.shape)
        err = error(new, initial if cumulative else current)
        errors.append(err)
        if not err < threshold:
            break
        current, R = new, R // 2
    total = error(current, initial) if R < R0 else 0.0
    return ShellReduction(current, R, errors, total)


def build_haar_field(mesh, shells: int = 32, resolution: int = 64, map_size: int = 64,
                     keep: float = 0.05, threshold: float = 0.01, min_resolution: int = 8,
                     *, cumulative: bool = False) -> tuple[HaarField, list]:
    """Sample, reduce and quantize the all-frequency (Haar) shadow field of a mesh.

    Sampling is the occlusion field's (shells around the bounding sphere,
    cone-culled binary visibility over the ``map_size`` map); each sample's map
    is stored at the kept fraction and each shell reduced on reconstructed maps.

    Returns
    -------
    HaarField
    cumulative_error : list of float
        Per shell, eq. (1) of the kept samples against the initial ones.
    """
    from shtools.fields.sampling import (
        bounding_sphere,
        direction_map,
        grid_directions,
        object_visibility,
        shell_radii,
    )
    from shtools.geometry.raycast import RayCaster

    v = np.asarray(mesh.vertices, dtype=np.float64)
    center, vr = bounding_sphere(v)
    caster = RayCaster(v, np.asarray(mesh.faces))
    dirs, weights = direction_map(map_size)
    sample_dirs = grid_directions(resolution).reshape(-1, 3)
    K = kept_count(map_size, keep)
    radii = shell_radii(vr, shells)
    res, cum, index, qs, offs, steps = [], [], [], [], [], []
    for r in radii:
        vis = object_visibility(caster, center, vr, center + r * sample_dirs, dirs)
        maps = np.empty((vis.shape[0], map_size * map_size), dtype=np.float32)
        for s in range(0, vis.shape[0], 512):
            chunk = vis[s:s + 512].reshape(-1, map_size, map_size).astype(np.float64)
            maps[s:s + 512] = truncated_maps(chunk, keep).reshape(chunk.shape[0], -1)
        red = reduce_haar_shell(maps.reshape(resolution, resolution, -1), threshold, weights,
                                keep, min_resolution, cumulative=cumulative)
        Rc = int(red.resolution)
        idx, val = truncate(haar2(red.grid.reshape(-1, map_size, map_size)), K)
        qv = quantize_sparse(val)
        res.append(Rc)
        cum.append(float(red.cumulative_error))
        index.append(idx.reshape(Rc, Rc, K))
        qs.append(qv["q"].reshape(Rc, Rc, K))
        offs.append(qv["offset"])
        steps.append(qv["step"])
    fld = HaarField(center, vr, np.asarray(radii), np.asarray(res, dtype=np.int64), index, qs,
                    np.stack(offs), np.stack(steps), map_size)
    return fld, cum


def haar_shell_sizes(mesh, shells: int = 32, resolution: int = 64, map_size: int = 64,
                     keep: float = 0.05, threshold: float = 0.01, min_resolution: int = 8,
                     *, cumulative: bool = False) -> dict:
    """Per-shell resolutions and bytes of the Haar field of a mesh (:func:`build_haar_field`).

    Returns
    -------
    dict
        ``resolution`` (list of R_c), ``bytes`` (``sum_c R_c^2 K (1 + 2)``),
        ``fixed_bytes`` (every shell at ``resolution``), ``kept`` (K),
        ``cumulative_error`` (per shell).
    """
    fld, cum = build_haar_field(mesh, shells, resolution, map_size, keep, threshold,
                                min_resolution, cumulative=cumulative)
    K = kept_count(map_size, keep)
    return {"resolution": [int(r) for r in fld.resolution], "bytes": fld.stored_bytes(),
            "fixed_bytes": shells * resolution * resolution * K * 3, "kept": K,
            "cumulative_error": cum}
