"""The ``spheres`` asset: a sphere set bounding a blocker (``shtools spheres fit``).

Datasets: ``centers (N, 3) f8``, ``radii (N,) f8`` (all > 0).  Root attributes:
``outside_volume_ratio`` (E = sum_i V(S_i - T) / V(T)), ``coverage`` (fraction of
surface samples inside some sphere) and ``method``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

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
    asset = read_asset(path, "spheres")
    return SphereSet(
        centers=asset["centers"],
        radii=asset["radii"],
        outside_volume_ratio=float(asset.attrs.get("outside_volume_ratio", float("nan"))),
        coverage=float(asset.attrs.get("coverage", float("nan"))),
        method=str(asset.attrs.get("method", "")),
        info={"parameters": asset.parameters},
    )


@dataclass
class SphereSet:
    """A set of spheres bounding a solid.

    Attributes
    ----------
    centers : ndarray, shape (N, 3), float64
    radii : ndarray, shape (N,), float64
    outside_volume_ratio : float
        E = sum_i V(S_i - T) / V(T): the volume the spheres add outside the
        solid T, summed over spheres, relative to T's volume (NaN if unknown,
        e.g. after importing a ``.sph`` file without its mesh).
    coverage : float
        Fraction of surface samples inside at least one sphere (1.0 for a
        bounding set; NaN if unknown).
    method : str
        How the set was made (``"variational"``, ``"octree"``, ``"kmeans"``,
        ``"import"``).
    info : dict
        Extra diagnostics (iterations, timings, solid volume, ...).
    """

    centers: np.ndarray
    radii: np.ndarray
    outside_volume_ratio: float = float("nan")
    coverage: float = float("nan")
    method: str = ""
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.centers = np.ascontiguousarray(self.centers, dtype=np.float64).reshape(-1, 3)
        self.radii = np.ascontiguousarray(self.radii, dtype=np.float64).reshape(-1)
        if len(self.centers) != len(self.radii):
            raise ValueError(
                f"centers {self.centers.shape} and radii {self.radii.shape} disagree"
            )

    def __len__(self) -> int:
        return len(self.radii)

    def contains(self, points: np.ndarray, *, tolerance: float = 0.0) -> np.ndarray:
        """Which points lie inside at least one sphere.

        Parameters
        ----------
        points : ndarray, shape (P, 3)
        tolerance : float
            Added to every radius.

        Returns
        -------
        ndarray, shape (P,), bool
        """
        from scipy.spatial import cKDTree

        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        inside = np.zeros(len(points), dtype=bool)
        if len(self) == 0 or len(points) == 0:
            return inside
        tree = cKDTree(points)
        for c, r in zip(self.centers, self.radii + tolerance, strict=True):
            inside[tree.query_ball_point(c, r)] = True
        return inside
