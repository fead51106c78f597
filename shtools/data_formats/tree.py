"""The ``tree`` asset: a bounding-sphere hierarchy over a sphere set.

Datasets (M nodes, N leaves):

- ``centers (M, 3) f8``, ``radii (M,) f8``: every node's sphere.
- ``parent (M,) i4``: parent node index, ``-1`` at the root.
- ``leaf (M,) i4``: index into the sphere set for leaves, ``-1`` for inner nodes.
- ``level (M,) i4``: height above the leaves (0 for leaves, the root is highest).
- ``child_offsets (M+1,) i4``, ``child_index (M-1,) i4``: children of node ``m``
  are ``child_index[child_offsets[m]:child_offsets[m+1]]`` (CSR form of ``parent``).

Node order written by :func:`shtools.geometry.sphere_tree.build_tree`: the
leaves first (node ``i`` is sphere ``i``), then each level bottom-up, the root
last, so ``parent[m] > m`` and a single forward pass visits children before
parents.  Readers must not rely on that order for trees from other tools; the
``parent`` array is the definition.  Root attributes: ``branching`` (the target)
and ``average_branching`` (the achieved mean number of children per inner node).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

KIND = "tree"
VERSION = 1


@dataclass
class SphereTree:
    """A sphere hierarchy.

    Attributes
    ----------
    centers : ndarray, shape (M, 3)
    radii : ndarray, shape (M,)
    parent : ndarray of int32, shape (M,)
        Parent node, ``-1`` at the root.
    leaf : ndarray of int32, shape (M,)
        Index into the sphere set for leaf nodes, ``-1`` for inner nodes.
    """

    centers: np.ndarray
    radii: np.ndarray
    parent: np.ndarray
    leaf: np.ndarray

    def __len__(self) -> int:
        return int(self.parent.shape[0])

    @property
    def root(self) -> int:
        """Index of the root node."""
        return int(np.flatnonzero(self.parent < 0)[0])

    def children(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR children lists: ``(child_offsets (M+1,), child_index (M-1,))``."""
        return children_csr(self.parent)

    def level(self) -> np.ndarray:
        """Height of every node above the leaves, shape ``(M,)`` (leaves 0)."""
        return node_heights(self.parent)


def children_csr(parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Children of every node from a parent array.

    Parameters
    ----------
    parent : ndarray of int, shape (M,)

    Returns
    -------
    offsets : ndarray of int32, shape (M+1,)
    index : ndarray of int32, shape (number of non-root nodes,)
        Children of node ``m`` are ``index[offsets[m]:offsets[m+1]]``, ascending.
    """
    parent = np.asarray(parent, dtype=np.int64)
    m = parent.shape[0]
    nonroot = np.flatnonzero(parent >= 0)
    order = nonroot[np.argsort(parent[nonroot], kind="stable")]
    counts = np.bincount(parent[nonroot], minlength=m)
    offsets = np.zeros(m + 1, dtype=np.int32)
    np.cumsum(counts, out=offsets[1:])
    return offsets, order.astype(np.int32)


def node_heights(parent: np.ndarray) -> np.ndarray:
    """Height of every node (0 for nodes without children), shape ``(M,)``.

    Raises
    ------
    ValueError
        If following parents from the leaves does not end at a root (a cycle).
    """
    parent = np.asarray(parent, dtype=np.int64)
    m = parent.shape[0]
    height = np.zeros(m, dtype=np.int64)
    has_children = np.zeros(m, dtype=bool)
    has_children[parent[parent >= 0]] = True
    frontier = np.flatnonzero(~has_children)
    for _ in range(m + 1):
        up = parent[frontier]
        keep = up >= 0
        frontier, up = frontier[keep], up[keep]
        if frontier.size == 0:
            break
        np.maximum.at(height, up, height[frontier] + 1)
        frontier = np.unique(up)
    else:
        raise ValueError("the parent array has a cycle")
    return height.astype(np.int32)


def validate_tree_arrays(parent, leaf, n_leaves: int | None = None, path=None) -> None:
    """Check that ``parent``/``leaf`` describe one rooted tree whose leaves are a sphere set.

    Raises
    ------
    AssetError
        One root, parents in range, no cycles, inner nodes have children,
        leaves are exactly ``0..N-1`` once each.
    """
    parent = np.asarray(parent, dtype=np.int64)
    leaf = np.asarray(leaf, dtype=np.int64)
    m = parent.shape[0]
    if m == 0:
        raise AssetError("the tree is empty; rebuild it with 'shtools spheres tree'", path)
    if np.count_nonzero(parent < 0) != 1:
        raise AssetError("the tree must have exactly one root (parent -1)", path)
    if np.any(parent >= m) or np.any(parent == np.arange(m)):
        raise AssetError("a parent index is out of range or a node is its own parent", path)
    # walking up from every node must reach the root within M steps (no cycles)
    node = np.arange(m)
    for _ in range(m):
        node = np.where(node >= 0, parent[np.maximum(node, 0)], -1)
        if np.all(node < 0):
            break
    else:
        raise AssetError("the parent array has a cycle; rebuild the tree", path)
    has_children = np.zeros(m, dtype=bool)
    has_children[parent[parent >= 0]] = True
    if np.any(has_children & (leaf >= 0)) or np.any(~has_children & (leaf < 0)):
        raise AssetError("leaf nodes must have no children and inner nodes must have some",
                         path)
    leaves = np.sort(leaf[leaf >= 0])
    expected = leaves.size if n_leaves is None else n_leaves
    if leaves.size != expected or not np.array_equal(leaves, np.arange(expected)):
        raise AssetError("the leaves must index every sphere of the set exactly once", path)


def _check(f, ctx: dict) -> None:
    validate_tree_arrays(f["parent"][()], f["leaf"][()], path=ctx["path"])


SCHEMA = register(
    Schema(
        kind=KIND,
        version=VERSION,
        datasets=(
            DatasetSpec("centers", ("M", 3)),
            DatasetSpec("radii", ("M",)),
            DatasetSpec("parent", ("M",), dtype_kind="i"),
            DatasetSpec("leaf", ("M",), dtype_kind="i"),
            DatasetSpec("level", ("M",), dtype_kind="i", optional=True),
            DatasetSpec("child_offsets", (None,), dtype_kind="i", optional=True),
            DatasetSpec("child_index", (None,), dtype_kind="i", optional=True),
        ),
        check=_check,
    )
)


def write_tree(
    path: str | os.PathLike,
    tree: SphereTree,
    *,
    inputs: Mapping[str, str | os.PathLike] | None = None,
    parameters: Mapping[str, Any] | None = None,
) -> os.PathLike:
    """Write a ``tree`` asset atomically.

    Parameters
    ----------
    path : path-like
    tree : SphereTree
    inputs, parameters : mapping, optional
        Provenance (input files are hashed).

    Returns
    -------
    pathlib.Path
    """
    parent = np.asarray(tree.parent, dtype=np.int32)
    leaf = np.asarray(tree.leaf, dtype=np.int32)
    validate_tree_arrays(parent, leaf, path=path)
    offsets, index = children_csr(parent)
    inner = int(np.count_nonzero(leaf < 0))
    attrs = {
        "average_branching": float((parent.size - 1) / inner) if inner else 0.0,
        "branching": int((parameters or {}).get("branching", 0)),
    }
    return write_asset(
        path,
        KIND,
        {
            "centers": np.asarray(tree.centers, dtype=np.float64),
            "radii": np.asarray(tree.radii, dtype=np.float64),
            "parent": parent,
            "leaf": leaf,
            "level": node_heights(parent),
            "child_offsets": offsets,
            "child_index": index,
        },
        attrs=attrs,
        inputs=inputs,
        parameters=parameters,
    )


def read_tree(path: str | os.PathLike) -> SphereTree:
    """Read and validate a ``tree`` asset.

    Returns
    -------
    SphereTree
    """
    asset = read_asset(path, KIND)
    return SphereTree(
        centers=np.asarray(asset["centers"], dtype=np.float64),
        radii=np.asarray(asset["radii"], dtype=np.float64),
        parent=np.asarray(asset["parent"], dtype=np.int32),
        leaf=np.asarray(asset["leaf"], dtype=np.int32),
    )
