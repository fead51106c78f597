"""The ``scaling`` asset: SH scaling matrices M(k) sampled in k (Wang et al. 2005).

Datasets (``docs/formats.md``):

======= ======= ===== ==========================================================
name    shape   dtype meaning
======= ======= ===== ==========================================================
k       (K,)    f8    sampled scale parameters, strictly increasing
rows    (P,)    i4    flat SH index (``l*l+l+m``) of each stored entry's row
cols    (P,)    i4    flat SH index of its column (same ``m`` as the row)
values  (K, P)  f8    ``M(k[i])[rows[p], cols[p]]``
======= ======= ===== ==========================================================

Root attributes: ``function`` (``"cone"``/``"midrange"``), ``alpha`` (cone,
radians), ``energy_preserving``, ``k_spacing``, ``interpolation`` (the rule a
reader must use between samples), ``out_of_range`` (``"clamp"``/``"error"``),
``quadrature_nodes`` and ``quadrature_error`` (max entry change against twice
the nodes).  ``P = n(2n²+1)/3`` in the canonical order of
:func:`shtools.sh.scaling.scaling_pattern`.

The reader validates the structural facts of SH scaling matrices
(:mod:`shtools.sh.scaling`):
pattern = canonical pattern of ``sh_order``, ``m`` and ``-m`` values equal,
column 0 (plain) or row 0 (energy-preserving) equal to ``e0``, ``M = I`` at the
identity ``k`` (cone 1, mid-range 0) within :data:`IDENTITY_TOL`, and ``k``
monotone inside the map's domain.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

KIND = "scaling"
VERSION = 1

#: ``M(identity k)`` must equal I within this (400-node quadrature gives ~3e-14).
IDENTITY_TOL = 1e-9
#: e0 rows/columns and m/-m equality hold to rounding of the quadrature sums.
STRUCTURE_TOL = 1e-9

#: Root attributes every scaling asset has (beyond the provenance set).
ATTRS = ("function", "energy_preserving", "k_spacing", "interpolation", "out_of_range",
         "quadrature_nodes", "quadrature_error")
FUNCTIONS = ("cone", "midrange")
INTERPOLATIONS = ("linear", "linear-log-k")
OUT_OF_RANGE = ("clamp", "error")


def canonical_pattern(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows and cols of the order-``n`` scaling pattern (m ascending, l_out, l_in).

    Kept here (and not imported from :mod:`shtools.sh.scaling`) so the reader
    checks files against the format's definition, not the writer's code.
    """
    rows, cols = [], []
    for m in range(-(order - 1), order):
        for lo in range(abs(m), order):
            for li in range(abs(m), order):
                rows.append(lo * lo + lo + m)
                cols.append(li * li + li + m)
    return np.array(rows, dtype=np.int64), np.array(cols, dtype=np.int64)


def _m_of(flat: np.ndarray) -> np.ndarray:
    l = np.floor(np.sqrt(flat)).astype(np.int64)
    return flat - (l * l + l)


def _check(f, ctx: dict) -> None:
    path, attrs = ctx["path"], ctx["attrs"]
    n = int(attrs["sh_order"])
    if n < 1:
        raise AssetError(f"sh_order must be >= 1, got {n}", path)
    function = attrs["function"]
    if function not in FUNCTIONS:
        raise AssetError(f"unknown scaling function '{function}' (knows cone, midrange)", path)
    if attrs["interpolation"] not in INTERPOLATIONS:
        raise AssetError(f"unknown interpolation '{attrs['interpolation']}' (knows "
                         f"{', '.join(INTERPOLATIONS)}); upgrade shtools", path)
    if attrs["out_of_range"] not in OUT_OF_RANGE:
        raise AssetError(f"unknown out_of_range policy '{attrs['out_of_range']}'", path)
    rows, cols = f["rows"][()].astype(np.int64), f["cols"][()].astype(np.int64)
    want_r, want_c = canonical_pattern(n)
    if rows.shape != want_r.shape:
        raise AssetError(f"has {rows.size} pattern entries but order {n} has "
                         f"n(2n^2+1)/3 = {want_r.size}; rebuild it", path)
    if np.any(_m_of(rows) != _m_of(cols)):
        raise AssetError("pattern couples different m (scaling keeps m); rebuild it", path)
    if not (np.array_equal(rows, want_r) and np.array_equal(cols, want_c)):
        raise AssetError("pattern is not the canonical order (m, l_out, l_in); rebuild it", path)
    k = f["k"][()]
    if k.size < 2 or np.any(np.diff(k) <= 0):
        raise AssetError("'k' must increase strictly (at least 2 samples); rebuild it", path)
    if function == "cone":
        if "alpha" not in attrs:
            raise AssetError("missing root attribute 'alpha' (cone half-angle)", path)
        alpha = float(attrs["alpha"])
        if not 0 < alpha < math.pi / 2:
            raise AssetError(f"cone alpha {alpha} rad is outside (0, pi/2)", path)
        if k[0] <= 0:
            raise AssetError("cone 'k' must be > 0", path)
        identity = 1.0
    else:
        if k[0] < 0 or k[-1] >= 1:
            raise AssetError("mid-range 'k' must lie in [0, 1) (inside the sphere)", path)
        identity = 0.0
    if attrs["interpolation"] == "linear-log-k" and k[0] <= 0:
        raise AssetError("linear-log-k interpolation needs k > 0", path)
    hit = np.flatnonzero(np.abs(k - identity) <= 1e-12)
    if hit.size != 1:
        raise AssetError(f"'k' must contain the identity k = {identity:g} exactly once", path)
    values = f["values"][()]
    m = _m_of(rows)
    # rows/cols of the canonical order: the m block and the -m block are laid out alike
    for mm in range(1, n):
        if not np.allclose(values[:, m == mm], values[:, m == -mm], rtol=0, atol=STRUCTURE_TOL):
            raise AssetError(f"m = {mm} and m = -{mm} blocks differ (they must be equal)", path)
    if bool(attrs["energy_preserving"]):  # integral of F kept: row 0 is e0
        line, name, other = values[:, rows == 0], "row 0", cols[rows == 0]
        mode = "energy-preserving"
    else:  # a constant warps to itself: column 0 is e0
        line, name, other = values[:, cols == 0], "column 0", rows[cols == 0]
        mode = "plain"
    e0 = (other == 0).astype(np.float64)
    if not np.allclose(line, e0, rtol=0, atol=STRUCTURE_TOL):
        raise AssetError(f"{name} is not e0 as {mode} scaling requires; rebuild it", path)
    eye = (rows == cols).astype(np.float64)
    if not np.allclose(values[hit[0]], eye, rtol=0, atol=IDENTITY_TOL):
        raise AssetError(f"M({identity:g}) is not the identity; rebuild it", path)


SCHEMA = register(
    Schema(
        kind=KIND,
        version=VERSION,
        has_sh=True,
        required_attrs=ATTRS,
        datasets=(
            DatasetSpec("k", ("K",)),
            DatasetSpec("rows", ("P",), dtype_kind="iu"),
            DatasetSpec("cols", ("P",), dtype_kind="iu"),
            DatasetSpec("values", ("K", "P")),
        ),
        check=_check,
    )
)


def write_scaling(path: str | os.PathLike, table: Mapping[str, Any],
                  parameters: Mapping[str, Any] | None = None) -> os.PathLike:
    """Write a ``scaling`` asset atomically.

    Parameters
    ----------
    path : path-like
    table : mapping
        As :func:`shtools.sh.scaling.build_scaling_table` returns.
    parameters : mapping, optional
        The stage's parameters, recorded as JSON.
    """
    attrs = {key: table[key] for key in ATTRS}
    attrs["energy_preserving"] = np.bool_(attrs["energy_preserving"])
    if table["function"] == "cone":
        attrs["alpha"] = float(table["alpha"])
    datasets = {
        "k": np.asarray(table["k"], dtype=np.float64),
        "rows": np.asarray(table["rows"], dtype=np.int32),
        "cols": np.asarray(table["cols"], dtype=np.int32),
        "values": np.asarray(table["values"], dtype=np.float64),
    }
    return write_asset(path, KIND, datasets, attrs=attrs, sh_order=int(table["order"]),
                       parameters=dict(parameters or {}))


def read_scaling(path: str | os.PathLike) -> dict:
    """Read and validate a ``scaling`` asset.

    Returns
    -------
    dict
        ``k (K,)``, ``rows (P,)``, ``cols (P,)``, ``values (K, P)``, ``order``
        and the root attributes of :data:`ATTRS` (plus ``alpha`` for a cone) —
        what :class:`shtools.runtime.scaling.ScalingTable` takes.
    """
    asset = read_asset(path, KIND)
    out = {name: asset.data[name] for name in ("k", "rows", "cols", "values")}
    out["order"] = asset.sh_order
    for key in ATTRS + (("alpha",) if asset.attrs["function"] == "cone" else ()):
        out[key] = asset.attrs[key]
    out["energy_preserving"] = bool(out["energy_preserving"])
    return out
