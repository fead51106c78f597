"""The ``bound`` asset: a sphere set bound to a glTF skin.

Datasets (N spheres, K bones per sphere):

- ``centers (N, 3) f8``, ``radii (N,) f8``: the spheres at rest (bind space of
  the rig, i.e. the space of its ``POSITION`` data).
- ``bone_index (N, K) i4``: joint indices (into the glTF skin's ``joints``).
- ``bone_vectors (N, K, 4) f8``: per-bone homogeneous vectors ``q``; the posed
  centre is ``sum_k M[bone_index[:, k]] @ bone_vectors[:, k]`` (first three
  rows) for skinning matrices ``M (J, 4, 4)``; the fourth components sum to 1.
- ``dropped_weight (N,) f8``: share of the bone weight (sum of ``|beta|`` over
  dropped bones / over all bones) folded into the kept bones.
- ``fallback (N,) u1``: 1 where mean value coordinates were unusable and the
  centre was bound by inverse-distance weights of the nearest vertices.
- ``fit_radii (N,) f8`` (optional): the sphere set's radii when ``radii`` were
  grown to cover the rig's animations (``shtools spheres bind --cover-animations``);
  ``radii`` are always the ones to use.

Root attributes: ``joint_count``, ``mesh_closed`` (the rest mesh was a closed
surface, so MVC were linearly precise), ``max_rest_residual``.  The glTF's
sha256 is in ``inputs`` (key ``rig``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

KIND = "bound"
VERSION = 1


@dataclass
class BoundSpheres:
    """Spheres plus their skin binding, as stored.

    Attributes
    ----------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    bone_index : ndarray of int32, shape (N, K)
    bone_vectors : ndarray, shape (N, K, 4)
    dropped_weight : ndarray, shape (N,)
    joint_count : int
    attrs : dict
        Root attributes (provenance included).
    fit_radii : ndarray, shape (N,), or None
        The sphere set's radii when ``radii`` were grown to cover animations.
    """

    centers: np.ndarray
    radii: np.ndarray
    bone_index: np.ndarray
    bone_vectors: np.ndarray
    dropped_weight: np.ndarray
    joint_count: int
    attrs: dict
    fit_radii: np.ndarray | None = None


def _check(f, ctx: dict) -> None:
    joints = int(ctx["attrs"].get("joint_count", 0))
    index = f["bone_index"][()]
    if index.size and (index.min() < 0 or index.max() >= joints):
        raise AssetError(f"bone_index out of range for {joints} joints; rebind", ctx["path"])


SCHEMA = register(
    Schema(
        kind=KIND,
        version=VERSION,
        required_attrs=("joint_count",),
        datasets=(
            DatasetSpec("centers", ("N", 3)),
            DatasetSpec("radii", ("N",)),
            DatasetSpec("bone_index", ("N", "K"), dtype_kind="i"),
            DatasetSpec("bone_vectors", ("N", "K", 4)),
            DatasetSpec("dropped_weight", ("N",), optional=True),
            DatasetSpec("fallback", ("N",), dtype_kind="iu", optional=True),
            DatasetSpec("fit_radii", ("N",), optional=True),
        ),
        check=_check,
    )
)


def write_bound(
    path: str | os.PathLike,
    centers,
    radii,
    binding,
    *,
    fit_radii=None,
    inputs: Mapping[str, str | os.PathLike] | None = None,
    parameters: Mapping[str, Any] | None = None,
) -> os.PathLike:
    """Write a ``bound`` asset atomically.

    Parameters
    ----------
    path : path-like
    centers : array_like, shape (N, 3)
    radii : array_like, shape (N,)
    binding : SphereBinding
        From :func:`shtools.geometry.binding.bind_spheres` (any object with
        ``bone_index``, ``bone_vectors``, ``dropped_weight``, ``fallback``,
        ``joint_count``, ``mesh_closed``, ``rest_residual``).
    fit_radii : array_like, shape (N,), optional
        Original radii when ``radii`` were grown to cover animations.
    inputs : mapping, optional
        Input files, e.g. ``{"spheres": ..., "rig": ...}`` (sha256 recorded).
    parameters : mapping, optional

    Returns
    -------
    pathlib.Path
    """
    centers = np.asarray(centers, dtype=np.float64)
    n = centers.shape[0]
    bone_index = np.asarray(binding.bone_index, dtype=np.int32)
    bone_vectors = np.asarray(binding.bone_vectors, dtype=np.float64)
    if bone_index.shape[0] != n or bone_vectors.shape[:2] != bone_index.shape:
        raise ValueError("binding does not match the sphere set")
    datasets = {
        "centers": centers,
        "radii": np.asarray(radii, dtype=np.float64),
        "bone_index": bone_index,
        "bone_vectors": bone_vectors,
        "dropped_weight": np.asarray(binding.dropped_weight, dtype=np.float64),
        "fallback": np.asarray(binding.fallback, dtype=np.uint8),
    }
    if fit_radii is not None:
        datasets["fit_radii"] = np.asarray(fit_radii, dtype=np.float64)
    return write_asset(
        path,
        KIND,
        datasets,
        attrs={
            "joint_count": np.int64(binding.joint_count),
            "mesh_closed": bool(binding.mesh_closed),
            "max_rest_residual": float(np.max(binding.rest_residual, initial=0.0)),
        },
        inputs=inputs,
        parameters=parameters,
    )


def read_bound(path: str | os.PathLike) -> BoundSpheres:
    """Read and validate a ``bound`` asset.

    Returns
    -------
    BoundSpheres
    """
    asset = read_asset(path, KIND)
    n = asset["centers"].shape[0]
    return BoundSpheres(
        centers=np.asarray(asset["centers"], dtype=np.float64),
        radii=np.asarray(asset["radii"], dtype=np.float64),
        bone_index=np.asarray(asset["bone_index"], dtype=np.int32),
        bone_vectors=np.asarray(asset["bone_vectors"], dtype=np.float64),
        dropped_weight=np.asarray(asset.data.get("dropped_weight", np.zeros(n)),
                                  dtype=np.float64),
        joint_count=int(asset.attrs["joint_count"]),
        attrs=asset.attrs,
        fit_radii=asset.data.get("fit_radii"),
    )
