"""The ``srf`` asset: the source radiance field of a local light (``field sample --radiance``).

Layout (``docs/formats.md``): the shells of a ``field`` asset -- ``center (3,)``,
``shell_radii (C,)``, ``shell_resolution (C,)``, the same cell-centred (theta,
phi) grid, pole axis ``+z`` and ``phi`` from ``+x`` towards ``+y`` -- with, per
shell ``c``, ``shells/<c>/rcv (R_c, R_c, 3, n*n) u1``: the incoming RGB radiance
from the lamp at each sample, one SH vector per channel, and
``shells/<c>/offset``, ``shells/<c>/step (3, n*n) f4`` (value = ``offset + q *
step``).  Also ``radiance (3,)`` (the emitter's RGB radiance),
``emitter_center (3,)`` and the ``emitter_radius``/``emitter_area`` attributes
(the sphere bounding the emissive faces and their area), and the per-shell
reduction statistics ``reduction_error``/``level_error (C,)`` of eq. (1) on
the RCVs divided by the scale named by the ``error_scale`` attribute.

Version 2 adds the lamp's triangles in its own frame -- ``lamp_vertices (P,
3)``, ``lamp_faces (F, 3)``, ``lamp_emissive (F,)`` -- which the traced shadow
of a field light casts its rays to (the emitter faces, through the fixture).
Version-1 files (no lamp mesh) still read; only the product-space shadow
(``shadows = "shexp"``) can shade them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, register, write_asset
from shtools.data_formats.field import (
    LAYOUT_ATTRS,
    READ_ATTRS,
    check_shells,
    read_shell_asset,
)
from shtools.errors import AssetError

#: Colour channels of an RCV.
CHANNELS = 3


@dataclass
class RadianceField:
    """A source radiance field in memory (quantized, as stored).

    Attributes
    ----------
    center : ndarray, shape (3,)
        Shell centre in the lamp's frame (bounding-sphere centre of the lamp).
    bounding_radius : float
        ``V_r`` of the lamp.
    shell_radii : ndarray, shape (C,)
    resolution : ndarray of int, shape (C,)
    rcv : list of ndarray, each (R_c, R_c, 3*n*n) uint8
        Channel-major: red's ``n*n`` coefficients, then green's, then blue's.
    offset, step : ndarray, shape (C, 3*n*n) float32
    order : int
    radiance : ndarray, shape (3,)
        The emitter's RGB radiance.
    emitter_center : ndarray, shape (3,)
    emitter_radius, emitter_area : float
    reduction_error, level_error : ndarray, shape (C,), optional
    lamp_vertices : ndarray, shape (P, 3), optional
        The lamp's triangles in its own frame (emitter and fixture); None in a
        version-1 file.
    lamp_faces : ndarray of int, shape (F, 3), optional
    lamp_emissive : ndarray of bool, shape (F,), optional
    attrs : dict
    """

    center: np.ndarray
    bounding_radius: float
    shell_radii: np.ndarray
    resolution: np.ndarray
    rcv: list
    offset: np.ndarray
    step: np.ndarray
    order: int
    radiance: np.ndarray
    emitter_center: np.ndarray
    emitter_radius: float
    emitter_area: float
    reduction_error: np.ndarray | None = None
    level_error: np.ndarray | None = None
    lamp_vertices: np.ndarray | None = None
    lamp_faces: np.ndarray | None = None
    lamp_emissive: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)

    #: SH vectors per sample (what :class:`shtools.runtime.FieldTable` lays out)
    channels = CHANNELS
    #: no log space for radiance (lights add, they do not multiply)
    log_ocv = None

    @property
    def ocv(self) -> list:
        """The samples under the name :class:`shtools.runtime.FieldTable` reads."""
        return self.rcv

    @property
    def n_shells(self) -> int:
        return int(self.shell_radii.shape[0])

    def stored_bytes(self) -> int:
        """Bytes of the quantized samples: ``sum_c R_c^2 * 3 * n^2``."""
        return int(sum(int(r) ** 2 for r in self.resolution) * CHANNELS * self.order ** 2)


def _check(f, ctx) -> None:
    path = ctx["path"]
    n2 = int(ctx["attrs"]["sh_order"]) ** 2
    shells = f["shell_radii"].shape
    if shells[0] < 1 or f["shell_resolution"].shape != shells:
        raise AssetError("the radiance field has no shells, or shell_radii and "
                         "shell_resolution disagree; resample it", path)
    res = check_shells(f, path)
    rad = f["radiance"][()]
    if not (np.all(np.isfinite(rad)) and np.all(rad >= 0) and rad.max() > 0):
        raise AssetError("radiance must be finite, >= 0 and not all zero", path)
    for c, r in enumerate(res):
        key = f"shells/{c}/rcv"
        if key not in f:
            raise AssetError(f"missing dataset '{key}'; the file is incomplete, rebuild it", path)
        ds = f[key]
        if ds.shape != (r, r, CHANNELS, n2) or ds.dtype != np.uint8:
            raise AssetError(f"dataset '{key}' has shape {ds.shape} {ds.dtype}, expected "
                             f"({r}, {r}, {CHANNELS}, {n2}) uint8", path)
        for name in ("offset", "step"):
            key = f"shells/{c}/{name}"
            if key not in f or f[key].shape != (CHANNELS, n2):
                raise AssetError(f"dataset '{key}' is missing or not of shape "
                                 f"({CHANNELS}, {n2})", path)
            arr = f[key][()]
            if not np.all(np.isfinite(arr)) or (name == "step" and np.any(arr < 0)):
                raise AssetError(f"dataset '{key}' holds NaN/inf or a negative step", path)
    lamp = [k in f for k in LAMP_DATASETS]
    if any(lamp) and not all(lamp):
        raise AssetError(f"the lamp mesh needs all of {', '.join(LAMP_DATASETS)}; the file "
                         "is incomplete, resample it", path)
    if all(lamp):
        faces = f["lamp_faces"][()]
        n_v = f["lamp_vertices"].shape[0]
        if faces.size and (faces.min() < 0 or faces.max() >= n_v):
            raise AssetError("lamp_faces index outside lamp_vertices; resample the field", path)
        if not f["lamp_emissive"][()].any():
            raise AssetError("lamp_emissive marks no face; resample the field", path)


#: The lamp mesh of a version-2 file (all or none).
LAMP_DATASETS = ("lamp_vertices", "lamp_faces", "lamp_emissive")


SCHEMA = register(
    Schema(
        kind="srf",
        version=2,
        known_versions=(1, 2),
        datasets=(
            DatasetSpec("center", (3,), "f"),
            DatasetSpec("shell_radii", ("C",), "f"),
            DatasetSpec("shell_resolution", ("C",), "iu"),
            DatasetSpec("radiance", (3,), "f"),
            DatasetSpec("emitter_center", (3,), "f"),
            DatasetSpec("reduction_error", ("C",), "f", optional=True),
            DatasetSpec("level_error", ("C",), "f", optional=True),
            DatasetSpec("lamp_vertices", ("P", 3), "f", optional=True),
            DatasetSpec("lamp_faces", ("F", 3), "iu", optional=True),
            DatasetSpec("lamp_emissive", ("F",), "iub", optional=True),
        ),
        required_attrs=("bounding_radius", "emitter_radius", "emitter_area"),
        has_sh=True,
        check=_check,
    )
)


def write_radiance_field(path: str | os.PathLike, fld: RadianceField, *, inputs=None,
                         parameters=None):
    """Write a :class:`RadianceField` as an ``srf`` asset (atomically).

    Returns
    -------
    pathlib.Path
    """
    n2 = fld.order ** 2
    data = {
        "center": np.asarray(fld.center, np.float64),
        "shell_radii": np.asarray(fld.shell_radii, np.float64),
        "shell_resolution": np.asarray(fld.resolution, np.int32),
        "radiance": np.asarray(fld.radiance, np.float64),
        "emitter_center": np.asarray(fld.emitter_center, np.float64),
    }
    if fld.reduction_error is not None:
        data["reduction_error"] = np.asarray(fld.reduction_error, np.float64)
    if fld.level_error is not None:
        data["level_error"] = np.asarray(fld.level_error, np.float64)
    if fld.lamp_vertices is not None:
        data["lamp_vertices"] = np.asarray(fld.lamp_vertices, np.float64)
        data["lamp_faces"] = np.asarray(fld.lamp_faces, np.int32)
        data["lamp_emissive"] = np.asarray(fld.lamp_emissive, np.uint8)
    for c in range(fld.n_shells):
        q = np.asarray(fld.rcv[c], np.uint8)
        data[f"shells/{c}/rcv"] = q.reshape(q.shape[0], q.shape[1], CHANNELS, n2)
        data[f"shells/{c}/offset"] = np.asarray(fld.offset[c], np.float32).reshape(CHANNELS, n2)
        data[f"shells/{c}/step"] = np.asarray(fld.step[c], np.float32).reshape(CHANNELS, n2)
    attrs = {**LAYOUT_ATTRS, **fld.attrs, "bounding_radius": float(fld.bounding_radius),
             "emitter_radius": float(fld.emitter_radius),
             "emitter_area": float(fld.emitter_area),
             "beyond_last_shell": "the last shell's RCV in the point's direction, times "
                                  "(r_last / d)^2",
             "inside_first_shell": "clamped to the first shell",
             "interpolation": "bilinear, theta clamped, phi wrapped; linear across shells"}
    return write_asset(path, "srf", data, attrs=attrs, sh_order=fld.order, inputs=inputs,
                       parameters=parameters, compression="gzip")


def read_radiance_field(path: str | os.PathLike) -> RadianceField:
    """Read and validate an ``srf`` asset.

    Returns
    -------
    RadianceField
    """
    asset, shells, C, stack = read_shell_asset(path, "srf")
    skip = READ_ATTRS | {"emitter_radius", "emitter_area"}
    rcv = []
    for c in range(C):
        q = np.asarray(asset[f"shells/{c}/rcv"])
        rcv.append(q.reshape(q.shape[0], q.shape[1], -1))
    return RadianceField(
        **shells, rcv=rcv, offset=stack("offset"), step=stack("step"),
        order=int(asset.sh_order),
        radiance=np.asarray(asset["radiance"], np.float64),
        emitter_center=np.asarray(asset["emitter_center"], np.float64),
        emitter_radius=float(asset.attrs["emitter_radius"]),
        emitter_area=float(asset.attrs["emitter_area"]),
        reduction_error=asset.data.get("reduction_error"),
        level_error=asset.data.get("level_error"),
        lamp_vertices=asset.data.get("lamp_vertices"),
        lamp_faces=(None if "lamp_faces" not in asset.data
                    else np.asarray(asset["lamp_faces"], np.int64)),
        lamp_emissive=(None if "lamp_emissive" not in asset.data
                       else np.asarray(asset["lamp_emissive"]).astype(bool)),
        attrs={k: v for k, v in asset.attrs.items() if k not in skip},
    )
