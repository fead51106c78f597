"""The ``field`` asset: an adaptive shadow field of a rigid object (``shtools field sample``).

Layout (``docs/formats.md``): ``center (3,)``, ``shell_radii (C,)``,
``shell_resolution (C,)``; per shell ``c``: ``shells/<c>/ocv (R_c, R_c, n*n) u1``
with ``shells/<c>/offset`` and ``shells/<c>/step (n*n,) f4`` (value =
``offset + q * step``), and the same for the SH log of the visibility
(``shells/<c>/log``, ``log_offset``, ``log_step``).  Optional
``self_visibility (V, m*m) f4`` (per-vertex self-visibility O_v of the object
on its own mesh vertices, object frame, at an order ``m >= n``: by default ``n``,
by the estimator named in ``parameters.self_estimator``).  Per-shell reduction statistics:
``reduction_error (C,)`` (cumulative L1 error of the stored float field
against the full-resolution one, eq. 1), ``level_error (C,)`` (largest error of
the last accepted halving).

Sample ``(s, t)`` of a shell of resolution ``R`` is the object-frame direction
``theta_s = (s + 1/2) pi / R`` from the pole axis ``+z``, ``phi_t = (t + 1/2)
2 pi / R`` from ``+x`` towards ``+y`` (cell-centred), at radius
``shell_radii[c]`` from ``center``.  These facts are root attributes too
(``pole_axis``, ``phi_origin``, ``cell_centred``, ``phi_wrap``).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

#: Layout facts recorded on every field asset (the runtime relies on them).
LAYOUT_ATTRS = {
    "pole_axis": "+z",
    "phi_origin": "+x towards +y",
    "cell_centred": True,
    "phi_wrap": True,
    "quantization": "linear per shell and coefficient: value = offset + q * step",
}


@dataclass
class ShadowField:
    """A shadow field in memory (quantized, as stored).

    Attributes
    ----------
    center : ndarray, shape (3,)
        Shell centre in the object's frame (bounding-sphere centre).
    bounding_radius : float
        Radius ``V_r`` of the object's bounding sphere.
    shell_radii : ndarray, shape (C,)
        Increasing shell radii.
    resolution : ndarray of int, shape (C,)
        ``R_c`` per shell (samples ``R_c x R_c``).
    ocv : list of ndarray, each (R_c, R_c, n*n) uint8
    offset, step : ndarray, shape (C, n*n) float32
        Dequantization ``offset + q * step`` of ``ocv``.
    log_ocv : list of ndarray, each (R_c, R_c, n*n) uint8
        Quantized SH log of each sample's visibility.
    log_offset, log_step : ndarray, shape (C, n*n) float32
    order : int
    self_visibility : ndarray, shape (V, m*m) or None
        O_v on the object's own mesh vertices (object frame), at SH order ``m >= n``
        (:attr:`self_order`).
    reduction_error, level_error : ndarray, shape (C,)
    attrs : dict
        Everything else recorded (quadrature, thresholds, leak information ...).
    """

    center: np.ndarray
    bounding_radius: float
    shell_radii: np.ndarray
    resolution: np.ndarray
    ocv: list
    offset: np.ndarray
    step: np.ndarray
    log_ocv: list
    log_offset: np.ndarray
    log_step: np.ndarray
    order: int
    self_visibility: np.ndarray | None = None
    reduction_error: np.ndarray | None = None
    level_error: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)

    @property
    def n_shells(self) -> int:
        return int(self.shell_radii.shape[0])

    @property
    def self_order(self) -> int | None:
        """SH order of the stored O_v (None without one)."""
        if self.self_visibility is None:
            return None
        return math.isqrt(np.shape(self.self_visibility)[-1])

    def stored_bytes(self) -> int:
        """Bytes of the quantized OCV samples (Table 2's measure): ``sum_c R_c^2 n^2``."""
        return int(sum(int(r) ** 2 for r in self.resolution) * self.order ** 2)


def check_shells(f, path) -> np.ndarray:
    """The ``shell_resolution`` of an open shell-field file (``field``, ``srf``,
    ``haar``), after checking that ``shell_radii`` is non-empty, positive and
    increasing and that every resolution is a power of two.

    Raises
    ------
    AssetError
        When either is not.
    """
    radii = f["shell_radii"][()]
    res = f["shell_resolution"][()]
    if radii.shape[0] < 1 or np.any(radii <= 0) or np.any(np.diff(radii) <= 0):
        raise AssetError("shell_radii must be positive and increasing; resample the field", path)
    if np.any(res < 1) or np.any(res & (res - 1)):
        raise AssetError("shell_resolution must be powers of two; resample the field", path)
    return res


def _check(f, ctx) -> None:
    path = ctx["path"]
    n = int(ctx["attrs"]["sh_order"])
    n2 = n * n
    if f["shell_radii"].shape[0] < 1:
        raise AssetError("the field has no shells; resample it", path)
    res = check_shells(f, path)
    for c, r in enumerate(res):
        for name in ("ocv", "log"):
            key = f"shells/{c}/{name}"
            if key not in f:
                raise AssetError(f"missing dataset '{key}'; the file is incomplete, rebuild it",
                                 path)
            ds = f[key]
            if ds.shape != (r, r, n2) or ds.dtype != np.uint8:
                raise AssetError(f"dataset '{key}' has shape {ds.shape} {ds.dtype}, expected "
                                 f"({r}, {r}, {n2}) uint8", path)
        for name in ("offset", "step", "log_offset", "log_step"):
            key = f"shells/{c}/{name}"
            if key not in f or f[key].shape != (n2,):
                raise AssetError(f"dataset '{key}' is missing or not of shape ({n2},)", path)
            arr = f[key][()]
            if not np.all(np.isfinite(arr)) or (name.endswith("step") and np.any(arr < 0)):
                raise AssetError(f"dataset '{key}' holds NaN/inf or a negative step", path)
    if "self_visibility" in f:
        cols = f["self_visibility"].shape[-1]
        m = math.isqrt(cols)
        if m * m != cols or m < n:
            raise AssetError(f"self_visibility must have m*m columns with m >= the field's "
                             f"order {n} (got {cols}); resample the field", path)


SCHEMA = register(
    Schema(
        kind="field",
        # 2: self_visibility may have more columns than the field's order (an O_v of
        # --self-order above it); version-1 files (O_v at the field's order) still read.
        version=2,
        known_versions=(1, 2),
        datasets=(
            DatasetSpec("center", (3,), "f"),
            DatasetSpec("shell_radii", ("C",), "f"),
            DatasetSpec("shell_resolution", ("C",), "iu"),
            DatasetSpec("reduction_error", ("C",), "f", optional=True),
            DatasetSpec("level_error", ("C",), "f", optional=True),
            DatasetSpec("self_visibility", (None, None), "f", optional=True),
        ),
        required_attrs=("bounding_radius",),
        has_sh=True,
        check=_check,
    )
)


def write_field(path: str | os.PathLike, fld: ShadowField, *, inputs=None, parameters=None):
    """Write a :class:`ShadowField` as a ``field`` asset (atomically).

    Returns
    -------
    pathlib.Path
    """
    data = {
        "center": np.asarray(fld.center, np.float64),
        "shell_radii": np.asarray(fld.shell_radii, np.float64),
        "shell_resolution": np.asarray(fld.resolution, np.int32),
    }
    if fld.reduction_error is not None:
        data["reduction_error"] = np.asarray(fld.reduction_error, np.float64)
    if fld.level_error is not None:
        data["level_error"] = np.asarray(fld.level_error, np.float64)
    if fld.self_visibility is not None:
        data["self_visibility"] = np.asarray(fld.self_visibility, np.float32)
    for c in range(fld.n_shells):
        data[f"shells/{c}/ocv"] = np.asarray(fld.ocv[c], np.uint8)
        data[f"shells/{c}/offset"] = np.asarray(fld.offset[c], np.float32)
        data[f"shells/{c}/step"] = np.asarray(fld.step[c], np.float32)
        data[f"shells/{c}/log"] = np.asarray(fld.log_ocv[c], np.uint8)
        data[f"shells/{c}/log_offset"] = np.asarray(fld.log_offset[c], np.float32)
        data[f"shells/{c}/log_step"] = np.asarray(fld.log_step[c], np.float32)
    attrs = {**LAYOUT_ATTRS, **fld.attrs, "bounding_radius": float(fld.bounding_radius)}
    return write_asset(path, "field", data, attrs=attrs, sh_order=fld.order, inputs=inputs,
                       parameters=parameters, compression="gzip")


def shell_resolution(asset, path: str | os.PathLike) -> np.ndarray:
    """The ``(C, 2)`` int64 shell resolutions of a read shell-field asset (``field`` or
    ``srf``), after checking it samples its shells in this package's layout.

    Raises
    ------
    AssetError
        When the asset's ``pole_axis`` or ``phi_origin`` differs from :data:`LAYOUT_ATTRS`.
    """
    layout = {k: asset.attrs.get(k) for k in ("pole_axis", "phi_origin")}
    if layout != {k: LAYOUT_ATTRS[k] for k in layout}:
        raise AssetError(f"unsupported field layout {layout}; resample it with this shtools", path)
    return np.asarray(asset["shell_resolution"], dtype=np.int64)



#: Root attributes a shell-field reader does not hand on in ``attrs``: the asset's
#: identity and the ``bounding_radius`` it reads into a field of its own.
READ_ATTRS = frozenset({"format", "format_version", "sh_order", "sh_convention",
                        "bounding_radius"})


def shell_geometry(asset, path: str | os.PathLike) -> dict:
    """What every shell-field asset (``field``, ``srf``, ``haar``) stores of its shells:
    ``center (3,)``, ``bounding_radius``, ``shell_radii (C,)`` float64 and
    ``resolution (C,)`` int64 (checked by :func:`shell_resolution`)."""
    return {"center": np.asarray(asset["center"], np.float64),
            "bounding_radius": float(asset.attrs["bounding_radius"]),
            "shell_radii": np.asarray(asset["shell_radii"], np.float64),
            "resolution": shell_resolution(asset, path)}

def stack_shells(asset, n_shells: int, name: str) -> np.ndarray:
    """The per-shell datasets ``shells/<c>/<name>`` of a read asset, each flattened and
    stacked: shape ``(n_shells, k)`` float32."""
    return np.stack([np.asarray(asset[f"shells/{c}/{name}"]).reshape(-1)
                     for c in range(n_shells)]).astype(np.float32)


def read_shell_asset(path: str | os.PathLike, kind: str):
    """Read and validate a shell-field asset of ``kind`` (``field``, ``srf``, ``haar``).

    Returns
    -------
    asset
        The read asset (:func:`shtools.data_formats._base.read_asset`).
    shells : dict
        Its :func:`shell_geometry`.
    n_shells : int
        C, the number of shells.
    stack : callable
        ``stack(name) -> (C, k) float32``, :func:`stack_shells` of this asset.
    """
    asset = read_asset(path, kind)
    shells = shell_geometry(asset, path)
    n_shells = shells["resolution"].shape[0]
    return asset, shells, n_shells, functools.partial(stack_shells, asset, n_shells)


def read_field(path: str | os.PathLike) -> ShadowField:
    """Read and validate a ``field`` asset.

    Returns
    -------
    ShadowField
    """
    asset, shells, C, stack = read_shell_asset(path, "field")
    return ShadowField(
        **shells,
        ocv=[asset[f"shells/{c}/ocv"] for c in range(C)],
        offset=stack("offset"),
        step=stack("step"),
        log_ocv=[asset[f"shells/{c}/log"] for c in range(C)],
        log_offset=stack("log_offset"),
        log_step=stack("log_step"),
        order=int(asset.sh_order),
        self_visibility=asset.data.get("self_visibility"),
        reduction_error=asset.data.get("reduction_error"),
        level_error=asset.data.get("level_error"),
        attrs={k: v for k, v in asset.attrs.items() if k not in READ_ATTRS},
    )
