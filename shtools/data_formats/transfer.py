"""The ``transfer`` asset: an object's precomputed self-visibility on its own vertices.

Written by ``shtools transfer MESH -o x.transfer.h5``
(:func:`shtools.geometry.visibility.self_visibility`), read by the baker to
shadow a rigid object by its real mesh instead of its own spheres.

Datasets (V vertices, SH order n):

- ``vertices (V, 3) f8``, ``normals (V, 3) f8``: the receiver points and unit
  normals it was computed for, in the mesh's own frame (the baker checks them
  against the scene's mesh);
- ``visibility (V, n*n) f4``: ray-traced binary visibility projected to SH
  (directions below the tangent plane count as visible);
- ``log_visibility (V, n*n) f4``: its SH log by eigen-inversion of
  ``floor + (1 - floor) visibility`` (what the runtime adds in log space).

Root attributes: the provenance set with ``sh_order = n``; ``parameters``
records ``order``, ``n_dirs`` (quadrature nodes used), ``floor``, ``offset``
and ``max_distance`` (None: unbounded rays).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

KIND = "transfer"
VERSION = 1


@dataclass
class Transfer:
    """A ``transfer`` asset in memory.

    Attributes
    ----------
    vertices, normals : ndarray, shape (V, 3)
    visibility : ndarray, shape (V, n*n) float32
    log_visibility : ndarray, shape (V, n*n) float32
    order : int
    parameters : dict
    """

    vertices: np.ndarray
    normals: np.ndarray
    visibility: np.ndarray
    log_visibility: np.ndarray
    order: int
    parameters: dict


def _check(f, ctx: dict) -> None:
    n = int(ctx["attrs"]["sh_order"])
    size = f["visibility"].shape[1]
    if size != n * n:
        raise AssetError(f"visibility has {size} coefficients but sh_order is {n} "
                         f"({n * n} expected); rebuild it with 'shtools transfer'", ctx["path"])


SCHEMA = register(
    Schema(
        kind=KIND,
        version=VERSION,
        has_sh=True,
        datasets=(
            DatasetSpec("vertices", ("V", 3)),
            DatasetSpec("normals", ("V", 3)),
            DatasetSpec("visibility", ("V", "S")),
            DatasetSpec("log_visibility", ("V", "S")),
        ),
        check=_check,
    )
)


def write_transfer(path: str | os.PathLike, vertices, normals, visibility, log_visibility, *,
                   inputs: Mapping[str, str | os.PathLike] | None = None,
                   parameters: Mapping[str, Any] | None = None) -> os.PathLike:
    """Write a ``transfer`` asset atomically.

    Parameters
    ----------
    path : path-like
    vertices, normals : array_like, shape (V, 3)
    visibility, log_visibility : array_like, shape (V, n*n)
    inputs : mapping, optional
        Input files (e.g. ``{"mesh": path}``), recorded with their sha256.
    parameters : mapping, optional

    Returns
    -------
    pathlib.Path
    """
    vis = np.asarray(visibility, dtype=np.float32)
    order = math.isqrt(vis.shape[1])
    return write_asset(
        path, KIND,
        {"vertices": np.asarray(vertices, dtype=np.float64),
         "normals": np.asarray(normals, dtype=np.float64),
         "visibility": vis,
         "log_visibility": np.asarray(log_visibility, dtype=np.float32)},
        sh_order=order, inputs=inputs, parameters=parameters, compression="gzip")


def read_transfer(path: str | os.PathLike) -> Transfer:
    """Read and validate a ``transfer`` asset."""
    asset = read_asset(path, KIND)
    return Transfer(np.asarray(asset["vertices"], np.float64),
                    np.asarray(asset["normals"], np.float64),
                    np.asarray(asset["visibility"], np.float32),
                    np.asarray(asset["log_visibility"], np.float32),
                    int(asset.sh_order), dict(asset.parameters))
