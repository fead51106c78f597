"""The ``tables`` asset: circle (cap) log tables and the OL exponential tables.

Datasets (``docs/formats.md``):

========== ========= ====== ===============================================
name       shape     dtype  meaning
========== ========= ====== ===============================================
theta      (T,)      f8     cap angular radii, increasing, in (0, pi/2]
vis_zh     (T, n)    f8     scaled zonal coefficients g*_l of the cap visibility
log_zh     (T, n)    f8     scaled zonal coefficients f*_l of its log (eigen)
ol_norm    (K,)      f8     ||f_hat|| samples of the OL tables, increasing, >= 0
ol_a       (K,)      f8     OL coefficient a(||f_hat||)
ol_b       (K,)      f8     OL coefficient b(||f_hat||)
========== ========= ====== ===============================================

``n`` equals the root attribute ``sh_order``.  "Scaled" means
``g*_l = g_l * sqrt(4*pi/(2l+1))`` so that a cap about axis ``s`` has the SH
vector ``vis_zh[t, band_of(n)] * basis(s, n)``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

KIND = "tables"
VERSION = 1

#: The table arrays, in the order build_log_tables returns them.
TABLE_KEYS = ("theta", "vis_zh", "log_zh", "ol_norm", "ol_a", "ol_b")


def _check(f, ctx: dict) -> None:
    path = ctx["path"]
    order = int(ctx["attrs"]["sh_order"])
    if ctx["dims"].get("n") != order:
        raise AssetError(
            f"tables have {ctx['dims'].get('n')} bands but sh_order is {order}; rebuild them",
            path,
        )
    theta = f["theta"][()]
    if theta.size and not (
        np.all(np.diff(theta) > 0) and theta[0] > 0 and theta[-1] <= math.pi / 2 + 1e-12
    ):
        raise AssetError(
            "'theta' must increase strictly within (0, pi/2]; rebuild the tables", path
        )
    ol_norm = f["ol_norm"][()]
    if ol_norm.size and not (np.all(np.diff(ol_norm) > 0) and ol_norm[0] >= 0):
        raise AssetError("'ol_norm' must increase strictly from >= 0; rebuild the tables", path)


SCHEMA = register(
    Schema(
        kind=KIND,
        version=VERSION,
        has_sh=True,
        datasets=(
            DatasetSpec("theta", ("T",)),
            DatasetSpec("vis_zh", ("T", "n")),
            DatasetSpec("log_zh", ("T", "n")),
            DatasetSpec("ol_norm", ("K",)),
            DatasetSpec("ol_a", ("K",)),
            DatasetSpec("ol_b", ("K",)),
        ),
        check=_check,
    )
)


def write_tables(
    path: str | os.PathLike,
    tables_dict: Mapping[str, Any],
    order: int,
    parameters: Mapping[str, Any] | None = None,
) -> os.PathLike:
    """Write a ``tables`` asset atomically.

    Parameters
    ----------
    path : path-like
        Output file.
    tables_dict : mapping
        As returned by :func:`shtools.sh.tables.build_log_tables`: ``theta (T,)``,
        ``vis_zh (T, n)``, ``log_zh (T, n)``, ``ol_norm (K,)``, ``ol_a (K,)``,
        ``ol_b (K,)``.  Other keys are ignored.
    order : int
        SH order ``n``; recorded as ``sh_order``.
    parameters : mapping, optional
        The stage's parameters (e.g. ``{"samples": 256}``), recorded as JSON.

    Returns
    -------
    pathlib.Path
    """
    missing = [k for k in TABLE_KEYS if k not in tables_dict]
    if missing:
        raise ValueError(f"tables_dict lacks {', '.join(missing)}")
    datasets = {k: np.asarray(tables_dict[k], dtype=np.float64) for k in TABLE_KEYS}
    for k in ("vis_zh", "log_zh"):
        if datasets[k].ndim != 2 or datasets[k].shape[1] != order:
            raise ValueError(f"{k} must have shape (T, {order}), got {datasets[k].shape}")
    params = {"order": int(order), **dict(parameters or {})}
    return write_asset(path, KIND, datasets, sh_order=int(order), parameters=params)


def read_tables(path: str | os.PathLike) -> dict:
    """Read and validate a ``tables`` asset.

    Returns
    -------
    dict
        The keys of :func:`shtools.sh.tables.build_log_tables` (``theta (T,)``,
        ``vis_zh (T, n)``, ``log_zh (T, n)``, ``ol_norm (K,)``, ``ol_a (K,)``,
        ``ol_b (K,)``) plus ``"order"`` (int).

    Raises
    ------
    shtools.errors.AssetError
        Not a tables asset, unknown version, wrong shapes, NaN, or tables that
        disagree with ``sh_order``.
    """
    asset = read_asset(path, KIND)
    out = {k: asset.data[k] for k in TABLE_KEYS}
    out["order"] = asset.sh_order
    return out


def write_log_tables(path: str | os.PathLike, order: int, samples: int = 256) -> dict:
    """Build the cap log and OL tables of ``order`` and write them (``shtools tables log``).

    Returns
    -------
    dict
        The tables, as from :func:`shtools.sh.tables.build_log_tables`.
    """
    from shtools.sh.tables import build_log_tables

    built = build_log_tables(order, samples=samples)
    write_tables(path, built, order, parameters={"samples": samples})
    return built
