"""The ``spheres`` asset: a sphere set bounding a blocker (``shtools spheres fit``).

Datasets: ``centers (N, 3) f8``, ``radii (N,) f8`` (all > 0).  Root attributes:
``outside_volume_ratio`` (E = sum_i V(S_i - T) / V(T)), ``coverage`` (fraction of
surface samples inside some sphere) and ``method``.
"""

from __future__ import annotations

import os

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError


def _check(f, ctx) -> None:
    radii = f["radii"][()]
    if len(radii) == 0:
        raise AssetError("the sphere set is empty; refit it", ctx["path"])
    if np.any(radii <= 0):
        raise AssetError("some sphere radii are not positive; refit the spheres", ctx["path"])


SCHEMA = register(
    Schema(
        kind="spheres",
        version=1,
        datasets=(
            DatasetSpec("centers", ("N", 3), "f"),
            DatasetSpec("radii", ("N",), "f"),
        ),
        required_attrs=("outside_volume_ratio",),
        check=_check,
    )
)


def write_spheres(
    path: str | os.PathLike,
    spheres,
    *,
    inputs=None,
    parameters=None,
):
    """Write a :class:`~shtools.geometry.sphere_set.SphereSet` as a ``spheres`` asset.

    Parameters
    ----------
    path : path-like
    spheres : SphereSet
        ``centers (N, 3)``, ``radii (N,)``, ``outside_volume_ratio``, ``coverage``.
    inputs : mapping, optional
        Input files (name -> path) recorded with their sha256.
    parameters : mapping, optional
        Stage parameters recorded as JSON.

    Returns
    -------
    pathlib.Path
    """
    return write_asset(
        path,
        "spheres",
        {
            "centers": np.asarray(spheres.centers, dtype=np.float64),
            "radii": np.asarray(spheres.radii, dtype=np.float64),
        },
        attrs={
            "outside_volume_ratio": float(spheres.outside_volume_ratio),
            "coverage": float(spheres.coverage),
            "method": str(spheres.method or ""),
        },
        inputs=inputs,
        parameters=parameters,
    )


def read_spheres(path: str | os.PathLike):
    """Read and validate a ``spheres`` asset.

    Returns
    -------
    SphereSet
    """
    from shtools.geometry.sphere_set import SphereSet

    asset = read_asset(path, "spheres")
    return SphereSet(
        centers=asset["centers"],
        radii=asset["radii"],
        outside_volume_ratio=float(asset.attrs.get("outside_volume_ratio", float("nan"))),
        coverage=float(asset.attrs.get("coverage", float("nan"))),
        method=str(asset.attrs.get("method", "")),
        info={"parameters": asset.parameters},
    )
