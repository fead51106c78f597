"""Streaming a bake asset: its per-frame datasets read a slice at a time.

:func:`open_bake` checks a bake as :func:`~shtools.data_formats.bake.read_bake`
does, but leaves the per-frame datasets in the open file, so a reader of every
frame (``shtools relight``) holds a few frames at a time whatever the frame
count; it checks each slice it reads with :func:`check_finite`.
"""

from __future__ import annotations

import contextlib
import os

import h5py
import numpy as np

from shtools.data_formats._base import read_asset
from shtools.data_formats.bake import bake_from_data
from shtools.errors import AssetError

#: The datasets :func:`open_bake` leaves in the file when they hold every frame.
PER_FRAME = ("radiance", "visibility", "vertices", "normals")


@contextlib.contextmanager
def open_bake(path: str | os.PathLike):
    """Open a bake asset to stream its frames: its per-frame datasets stay in the file.

    As :func:`~shtools.data_formats.bake.read_bake`, but ``radiance``,
    ``visibility`` and per-frame ``vertices`` / ``normals`` ``(T, V, k)`` are
    the open file's h5py datasets (read by slicing, while the context is open);
    their shapes are checked here, their values by the reader as it reads them
    (:func:`check_finite`).

    Yields
    ------
    shtools.data_formats.bake.Bake

    Raises
    ------
    AssetError
        As ``read_bake`` (NaN/inf only in the arrays it loads).
    """
    asset = read_asset(path, "bake", lazy=PER_FRAME)
    # no chunk cache: every read is of whole frames (one chunk each), and HDF5's object
    # copy of a dataset with chunks in its cache (relight's output geometry, after the
    # frames were read) took 130 ms instead of 4 on the demo bake
    with h5py.File(path, "r", rdcc_nbytes=0) as f:
        data = dict(asset.data)
        for name in PER_FRAME:
            if name not in f:
                continue
            if f[name].ndim == 3:
                data[name] = f[name]
            else:  # geometry stored once: small, read and checked as read_bake does
                data[name] = check_finite(f[name][()], name, path)
        yield bake_from_data(asset, data, path)


def check_finite(values: np.ndarray, name: str, path) -> np.ndarray:
    """``values`` read from dataset ``name``, refused when they hold NaN or inf.

    Raises
    ------
    AssetError
        As ``read_bake`` words it.
    """
    if not np.all(np.isfinite(values)):
        raise AssetError(f"dataset '{name}' contains NaN or inf; rebuild it", path)
    return values
