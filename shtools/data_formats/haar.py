"""The ``haar`` asset: an all-frequency shadow field (``field sample --basis haar``).

Layout (``docs/formats.md``): the shells of a ``field`` asset -- ``center (3,)``,
``shell_radii (C,)``, ``shell_resolution (C,)``, the same cell-centred (theta,
phi) sample grid, pole axis ``+z``, ``phi`` from ``+x`` towards ``+y`` -- with,
per shell ``c``, the kept coefficients of every sample's ``M x M`` occlusion
map in the nonstandard 2-D Haar basis: ``shells/<c>/index (R_c, R_c, K) u2``
(flat positions in the ``M x M`` coefficient layout, ascending) and
``shells/<c>/value (R_c, R_c, K) u1``, dequantized as ``offset[0] + q * step[0]``
for column 0 (the overall scaling coefficient, kept first) and ``offset[1] +
q * step[1]`` for the others (``shells/<c>/offset``, ``shells/<c>/step (2,) f4``).
Per-shell reduction statistics ``reduction_error (C,)`` (eq. 1 of the stored
float maps against the initial ones).  Root attributes: ``bounding_radius``,
``map_size`` (M), ``kept`` (K) and the layout facts of ``field`` assets.
"""

from __future__ import annotations

import os

import h5py
import numpy as np

from shtools.data_formats._base import (
    FORMAT_PREFIX,
    DatasetSpec,
    Schema,
    register,
    write_asset,
)
from shtools.data_formats.field import LAYOUT_ATTRS, check_shells, read_shell_asset
from shtools.errors import AssetError

#: Largest map side: the kept coefficients' indices into the M x M map are uint16.
MAX_MAP_SIZE = 256
#: How a Haar map is parameterised and coded (recorded on every asset).
HAAR_ATTRS = {
    **LAYOUT_ATTRS,
    "basis": "nonstandard 2-D Haar, orthonormal in the map's pixel inner product",
    "map_layout": "M x M cells: theta rows (s + 1/2) pi / M from +z, phi columns "
                  "(t + 1/2) 2 pi / M from +x towards +y; coefficients in Mallat order",
    "quantization": "value = offset[0] + q * step[0] (column 0), offset[1] + q * step[1] "
                    "(other columns), per shell",
}


def _check(f, ctx) -> None:
    path = ctx["path"]
    M = int(f.attrs["map_size"])
    K = int(f.attrs["kept"])
    if M < 2 or M & (M - 1) or M > MAX_MAP_SIZE:
        raise AssetError(f"map_size {M} is not a power of two in 2..{MAX_MAP_SIZE}; resample "
                         "the field", path)
    if not 1 <= K <= M * M:
        raise AssetError(f"kept {K} is outside 1..{M * M}; resample the field", path)
    res = check_shells(f, path)
    for c, r in enumerate(res):
        for name, dtype in (("index", np.uint16), ("value", np.uint8)):
            key = f"shells/{c}/{name}"
            if key not in f:
                raise AssetError(f"missing dataset '{key}'; the file is incomplete, rebuild it",
                                 path)
            ds = f[key]
            if ds.shape != (r, r, K) or ds.dtype != dtype:
                raise AssetError(f"dataset '{key}' has shape {ds.shape} {ds.dtype}, expected "
                                 f"({r}, {r}, {K}) {np.dtype(dtype).name}", path)
        idx = f[f"shells/{c}/index"][()]
        if idx.size and int(idx.max()) >= M * M:
            raise AssetError(f"dataset 'shells/{c}/index' points past the {M}x{M} map", path)
        for name in ("offset", "step"):
            key = f"shells/{c}/{name}"
            if key not in f or f[key].shape != (2,):
                raise AssetError(f"dataset '{key}' is missing or not of shape (2,)", path)
            arr = f[key][()]
            if not np.all(np.isfinite(arr)) or (name == "step" and np.any(arr < 0)):
                raise AssetError(f"dataset '{key}' holds NaN/inf or a negative step", path)


SCHEMA = register(
    Schema(
        kind="haar",
        version=1,
        datasets=(
            DatasetSpec("center", (3,), "f"),
            DatasetSpec("shell_radii", ("C",), "f"),
            DatasetSpec("shell_resolution", ("C",), "iu"),
            DatasetSpec("reduction_error", ("C",), "f", optional=True),
        ),
        required_attrs=("bounding_radius", "map_size", "kept"),
        check=_check,
    )
)


def asset_kind(path: str | os.PathLike) -> str | None:
    """The kind an HDF5 asset says it is (its ``format`` attribute), or None when unreadable."""
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
    except OSError:
        return None
    if isinstance(fmt, bytes):
        fmt = fmt.decode()
    if isinstance(fmt, str) and fmt.startswith(FORMAT_PREFIX):
        return fmt[len(FORMAT_PREFIX):]
    return None


def write_haar_field(path: str | os.PathLike, fld, *, reduction_error=None, inputs=None,
                     parameters=None, attrs=None):
    """Write an all-frequency field as a ``haar`` asset (atomically, deterministic bytes).

    Parameters
    ----------
    fld : shtools.runtime.haar.HaarField
        Anything with its attributes (``center``, ``bounding_radius``,
        ``shell_radii``, ``resolution``, ``index``, ``q``, ``offset``, ``step``,
        ``map_size``).
    reduction_error : array_like, shape (C,), optional

    Returns
    -------
    pathlib.Path
    """
    C = len(fld.resolution)
    data = {
        "center": np.asarray(fld.center, np.float64),
        "shell_radii": np.asarray(fld.shell_radii, np.float64),
        "shell_resolution": np.asarray(fld.resolution, np.int32),
    }
    if reduction_error is not None:
        data["reduction_error"] = np.asarray(reduction_error, np.float64)
    for c in range(C):
        data[f"shells/{c}/index"] = np.asarray(fld.index[c], np.uint16)
        data[f"shells/{c}/value"] = np.asarray(fld.q[c], np.uint8)
        data[f"shells/{c}/offset"] = np.asarray(fld.offset[c], np.float32)
        data[f"shells/{c}/step"] = np.asarray(fld.step[c], np.float32)
    root = {**HAAR_ATTRS, **(attrs or {}), "bounding_radius": float(fld.bounding_radius),
            "map_size": np.int64(fld.map_size), "kept": np.int64(np.shape(fld.index[0])[-1])}
    return write_asset(path, "haar", data, attrs=root, inputs=inputs, parameters=parameters,
                       compression="gzip")


def read_haar_asset(path: str | os.PathLike) -> dict:
    """Read and validate a ``haar`` asset.

    Returns
    -------
    dict
        The :class:`shtools.runtime.haar.HaarField` fields (``center``,
        ``bounding_radius``, ``shell_radii``, ``resolution``, ``index``, ``q``,
        ``offset (C, 2)``, ``step (C, 2)``, ``map_size``) and ``reduction_error``
        (or None), ``attrs``.
    """
    asset, shells, C, stack = read_shell_asset(path, "haar")
    return {
        **shells,
        "index": [np.asarray(asset[f"shells/{c}/index"]) for c in range(C)],
        "q": [np.asarray(asset[f"shells/{c}/value"]) for c in range(C)],
        "offset": stack("offset"),
        "step": stack("step"),
        "map_size": int(asset.attrs["map_size"]),
        "reduction_error": asset.data.get("reduction_error"),
        "attrs": dict(asset.attrs),
    }
