"""Summaries and comparisons of assets (the engine of ``shtools info`` / ``check`` / ``diff``).

:func:`compare_assets` is the CI regression check: every dataset of two assets of
the same kind is compared with ``|a - b| <= atol + rtol * |b|`` (``b`` is the
reference, e.g. the golden file), in blocks of :data:`BLOCK_ELEMENTS` so
memory stays bounded; provenance that legitimately differs between builds
(``generator``; ``inputs`` and input file names in ``parameters`` unless
asked) is ignored; ``frames`` restricts two bakes to shared scene frames; shape, dtype, kind and
parameter mismatches are reported with the worst differences.
:func:`summarize_asset` validates an asset and gives ranges per dataset.
"""

from __future__ import annotations

import json

import h5py
import numpy as np

from shtools.data_formats._base import read_asset, row_blocks
from shtools.errors import AssetError, InputError


def short(v, limit: int = 60) -> str:
    """``str(v)`` cut to ``limit`` characters (with an ellipsis)."""
    text = str(v)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _datasets(path) -> dict[str, tuple]:
    """Every dataset path of an (already validated) asset -> (shape, dtype), sorted."""
    out = {}

    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.shape, obj.dtype)

        f.visititems(visit)
    return dict(sorted(out.items()))


def summarize_asset(path) -> dict:
    """Validate ``path`` and summarise it.

    Returns
    -------
    dict
        ``path``, ``kind``, ``version``, ``attributes`` (decoded root attributes)
        and ``datasets``: a list of ``{name, shape, dtype, min, max, nonfinite}``
        (``min``/``max`` over finite values of numeric datasets, else ``None``).
    """
    asset = read_asset(path, load=False)
    datasets = []
    with h5py.File(path, "r") as f:
        for name in _datasets(path):
            datasets.append(_dataset_summary(name, f[name]))
    attrs = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in asset.attrs.items()}
    return {"path": str(path), "kind": asset.kind, "version": asset.version,
            "attributes": attrs, "datasets": datasets}


def _blocks(shape):
    """Slices along the first axis of about BLOCK_ELEMENTS elements each."""
    return row_blocks(shape, BLOCK_ELEMENTS)


def _dataset_summary(name, ds) -> dict:
    """Shape, dtype, finite min/max and non-finite count, streamed block by block."""
    entry = {"name": name, "shape": list(ds.shape), "dtype": str(ds.dtype),
             "min": None, "max": None, "nonfinite": 0}
    if ds.dtype.kind not in "fiub" or ds.size == 0:
        return entry
    lo, hi = np.inf, -np.inf
    for block in _blocks(ds.shape):
        values = np.asarray(ds[block])
        if values.dtype.kind == "b":
            values = values.astype(np.int8)
        if values.dtype.kind == "f":
            finite = np.isfinite(values)
            entry["nonfinite"] += int(values.size - np.count_nonzero(finite))
            values = values[finite]
        if values.size:
            lo, hi = min(lo, float(values.min())), max(hi, float(values.max()))
    if lo <= hi:
        entry["min"], entry["max"] = lo, hi
    return entry


#: Root attributes that differ between equivalent builds and are never compared.
IGNORED_ATTRS = ("generator",)
#: Parameters that name input files: provenance like ``inputs``, compared only with them.
PROVENANCE_PARAMETERS = ("parameters.scene",)
#: Datasets of a bake asset indexed by frame along their first axis (vertices and
#: normals only when they have a frame axis).
BAKE_FRAME_DATASETS = ("radiance", "visibility", "times", "frame_index", "vertices", "normals")


def frame_numbers(text: str) -> range:
    """``A:B[:S]`` or ``A`` -> scene frame numbers (a one-line error otherwise)."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            return range(int(parts[0]), int(parts[0]) + 1)
        if len(parts) in (2, 3) and parts[0].strip() and parts[1].strip():
            step = int(parts[2]) if len(parts) == 3 and parts[2].strip() else 1
            if step >= 1 and int(parts[1]) > int(parts[0]):
                return range(int(parts[0]), int(parts[1]), step)
    except ValueError:
        pass
    raise InputError(f"--frames '{text}' is not A:B[:S] (half-open, A < B, S >= 1) or A")


def _frame_positions(f: h5py.File, frames: range, path) -> np.ndarray:
    """Positions along the frame axis of scene frames ``frames`` in an open bake asset."""
    index = f["frame_index"][()] if "frame_index" in f else np.arange(f["radiance"].shape[0])
    where = {int(k): i for i, k in enumerate(index)}
    missing = [k for k in frames if k not in where]
    if missing:
        raise AssetError(f"does not hold frame {missing[0]} (it holds {int(index.min())}.."
                         f"{int(index.max())}); pick frames both bakes hold", path)
    return np.array([where[k] for k in frames])


def _flatten_parameters(params, prefix="parameters."):
    if isinstance(params, dict):
        out = {}
        for k, v in params.items():
            out.update(_flatten_parameters(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: params}


def _comparable_attrs(attrs: dict, compare_inputs: bool) -> dict:
    out = {}
    for k, v in attrs.items():
        if k in IGNORED_ATTRS or (k == "inputs" and not compare_inputs):
            continue
        if k == "parameters":
            out.update({name: value for name, value in _flatten_parameters(v).items()
                        if compare_inputs or name not in PROVENANCE_PARAMETERS})
        elif k == "inputs":
            out.update({f"inputs.{name}": digest for name, digest in (v or {}).items()})
        else:
            out[k] = v.tolist() if isinstance(v, np.ndarray) else v
    return out


def _is_ignored(name: str, ignore: set[str]) -> bool:
    # "parameters.window" is ignored by "window" or by the full dotted name.
    return name in ignore or name.split(".", 1)[-1] in ignore


def compare_assets(path_a, path_b, *, rtol=1e-5, atol=1e-8, compare_inputs=False,
                   ignore=frozenset(), worst=10, rel_rmse=None, frames=None) -> dict:
    """Compare two assets; B is the reference.

    Parameters
    ----------
    path_a, path_b : path-like
        Assets to compare (both validated first).
    rtol, atol : float
        An element passes when ``|a - b| <= atol + rtol * |b|``; NaN equals NaN.
    compare_inputs : bool
        Also compare the recorded input hashes (ignored by default: the same
        result can come from inputs at different paths or re-saved files).
    ignore : set of str
        Dataset names, root attribute names or parameter keys to skip.
    worst : int
        How many of the most out-of-tolerance elements to return.
    rel_rmse : float, optional
        Also fail a numeric dataset whose relative RMSE ``||a - b|| / ||b||``
        (over finite elements) exceeds this.
    frames : range, optional
        Bake assets: compare only these scene frame numbers (both must hold
        them); the baked frame range parameter is then not compared.

    Returns
    -------
    dict
        ``equal`` (bool), ``problems`` (list of str: kind/version/attribute/shape
        mismatches, missing datasets), ``datasets`` (per dataset: name, shape,
        max_abs, max_rel, rel_rmse, outside, status) and ``worst`` (list of ``{dataset,
        index, a, b, abs, rel}``), plus the inputs of the comparison.
    """
    a, b = read_asset(path_a, load=False), read_asset(path_b, load=False)
    result = {"a": str(path_a), "b": str(path_b), "rtol": rtol, "atol": atol,
              "rel_rmse_limit": rel_rmse, "equal": True, "problems": [], "datasets": [],
              "worst": []}
    problems = result["problems"]
    if a.kind != b.kind:
        problems.append(f"kind differs: A is '{a.kind}', B is '{b.kind}'")
        result["equal"] = False
        return result
    if frames is not None and a.kind != "bake":
        raise AssetError(f"--frames applies to bake assets; this is a '{a.kind}' asset", path_a)
    attrs_a = _comparable_attrs(a.attrs, compare_inputs)
    attrs_b = _comparable_attrs(b.attrs, compare_inputs)
    for key in sorted(set(attrs_a) | set(attrs_b)):
        if _is_ignored(key, ignore) or (frames is not None and key == "parameters.frames"):
            continue
        va, vb = attrs_a.get(key, "<absent>"), attrs_b.get(key, "<absent>")
        if va != vb:
            problems.append(f"attribute {key} differs: A={short(json.dumps(va, default=str))} "
                            f"B={short(json.dumps(vb, default=str))}")
    sets_a, sets_b = _datasets(path_a), _datasets(path_b)
    candidates = []
    with h5py.File(path_a, "r") as fa, h5py.File(path_b, "r") as fb:
        pos_a = pos_b = None
        if frames is not None:
            pos_a = _frame_positions(fa, frames, path_a)
            pos_b = _frame_positions(fb, frames, path_b)
        for name in sorted(set(sets_a) | set(sets_b)):
            if _is_ignored(name, ignore):
                continue
            if name not in sets_b or name not in sets_a:
                where = "B" if name not in sets_b else "A"
                problems.append(f"dataset {name} is missing in {where}")
                result["datasets"].append({"name": name, "status": f"missing in {where}"})
                continue
            da, db = fa[name], fb[name]
            if pos_a is not None and name in BAKE_FRAME_DATASETS and da.ndim == db.ndim and (
                    name not in ("vertices", "normals") or da.ndim == 3):
                da, db = da[pos_a], db[pos_b]  # the selected frames only
            entry, worst_here = _compare_dataset(name, da, db, rtol, atol, worst)
            if (rel_rmse is not None and entry.get("rel_rmse") is not None
                    and entry["rel_rmse"] > rel_rmse):
                entry["status"] = f"relative RMSE {entry['rel_rmse']:.3g} > {rel_rmse:g}"
            result["datasets"].append(entry)
            if entry["status"].startswith("shape"):
                problems.append(f"dataset {name}: {entry['status']}")
            candidates.extend(worst_here)
    candidates.sort(key=lambda w: -w["excess"])
    for w in candidates[:worst]:
        del w["excess"]
        result["worst"].append(w)
    result["equal"] = not problems and all(
        d["status"] in ("identical", "within tolerance") for d in result["datasets"])
    return result


#: Elements compared per block, so huge bake assets compare in bounded memory.
BLOCK_ELEMENTS = 1 << 20


def _compare_dataset(name, da, db, rtol, atol, worst):
    """Compare two h5py datasets (or arrays) block by block along the first axis."""
    entry = {"name": name, "shape": list(db.shape)}
    if da.shape != db.shape:
        entry["status"] = f"shape differs: A {tuple(da.shape)} vs B {tuple(db.shape)}"
        return entry, []
    if da.dtype != db.dtype:
        entry["dtype"] = f"A {da.dtype} vs B {db.dtype}"
    numeric = da.dtype.kind in "fiub" and db.dtype.kind in "fiub"
    if not numeric:
        same = np.array_equal(da[()], db[()])
        entry.update(outside=0 if same else int(np.prod(da.shape)),
                     status="identical" if same else "values differ (non-numeric)")
        return entry, []
    shape = da.shape
    size = int(np.prod(shape))
    max_abs = max_rel = 0.0
    n_out = 0
    sum_d2 = sum_b2 = 0.0  # for the relative RMSE over finite elements
    picks = []
    offset = 0  # flat index of the block's first element
    for block in _blocks(shape):
        fa = np.asarray(da[block], dtype=np.float64)
        fb = np.asarray(db[block], dtype=np.float64)
        diff, rel, excess = _elementwise(fa, fb, rtol, atol)
        if diff.size:
            max_abs = max(max_abs, float(diff.max()))
            finite = np.isfinite(diff) & np.isfinite(fb)
            sum_d2 += float(np.sum(diff[finite] ** 2))
            sum_b2 += float(np.sum(fb[finite] ** 2))
            max_rel = max(max_rel, float(rel.max()))
        n_out += int(np.count_nonzero(excess > 1.0))
        if worst and diff.size and np.any(diff):
            flat = excess.ravel()
            k = min(worst, flat.size)
            for i in np.argpartition(-flat, k - 1)[:k]:
                if flat[i] == 0:
                    continue
                idx = np.unravel_index(offset + int(i), shape)
                local = np.unravel_index(int(i), fa.shape)
                picks.append({"dataset": name, "index": [int(j) for j in idx],
                              "a": float(fa[local]), "b": float(fb[local]),
                              "abs": float(diff[local]), "rel": float(rel[local]),
                              "excess": float(flat[i])})
            picks = sorted(picks, key=lambda w: -w["excess"])[:worst]
        offset += fa.size
    entry.update(
        max_abs=max_abs,
        max_rel=max_rel,
        rel_rmse=(0.0 if sum_d2 == 0 else float(np.sqrt(sum_d2 / sum_b2)) if sum_b2 > 0
                  else float("inf")),
        outside=n_out,
        status=("identical" if max_abs == 0 else
                "within tolerance" if n_out == 0 else f"{n_out} of {size} outside"),
    )
    return entry, picks


def _elementwise(fa, fb, rtol, atol):
    """|a-b| (inf where exactly one is NaN), |a-b|/|b|, and |a-b| / (atol + rtol|b|)."""
    both_nan = np.isnan(fa) & np.isnan(fb)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        diff = np.where(both_nan | (fa == fb), 0.0, np.abs(fa - fb))
        diff = np.where(np.isnan(diff), np.inf, diff)  # NaN against a number, or inf - inf
        allowed = atol + rtol * np.abs(fb)
        rel = np.where(diff == 0, 0.0, diff / np.abs(fb))
        excess = np.where(diff == 0, 0.0,
                          np.divide(diff, allowed, out=np.full_like(diff, np.inf),
                                    where=allowed > 0))
    return diff, rel, excess
