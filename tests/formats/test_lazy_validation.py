"""read_asset(load=False) (what info, check and diff open assets with) validates float
datasets block by block: memory stays bounded however large the asset, and a NaN
anywhere is still found."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from shtools.data_formats import _base
from shtools.data_formats._base import DatasetSpec, Schema, read_asset, row_blocks, write_asset
from shtools.errors import AssetError


@pytest.fixture
def big_kind(monkeypatch):
    """A kind of one float dataset ``values (N, 3)``, registered for this test only."""
    schema = Schema(kind="lazytest", version=1, datasets=(DatasetSpec("values", ("N", 3)),))
    monkeypatch.setitem(_base.SCHEMAS, "lazytest", schema)
    return schema


def test_row_blocks_cover_every_row_once():
    for shape, elements in (((10, 3), 7), ((10, 3), 1), ((10, 3), 1000), ((0, 3), 5),
                            ((5,), 2)):
        rows = np.concatenate([np.arange(shape[0])[b] for b in row_blocks(shape, elements)])
        np.testing.assert_array_equal(rows, np.arange(shape[0]))
    assert row_blocks((), 5) == [()]


def test_unloaded_validation_reads_in_bounded_memory(big_kind, tmp_path):
    path = tmp_path / "big.h5"
    n = 4 * _base.BLOCK_ELEMENTS // 3  # rows of 4 blocks' worth of elements
    write_asset(path, "lazytest", {"values": np.ones((n, 3), dtype=np.float32)})
    size = n * 3 * 4  # bytes of the dataset
    tracemalloc.start()
    try:
        asset = read_asset(path, load=False)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert asset.data == {} and asset.dims == {"N": n}
    # one float32 block (16 MB) and its isfinite mask (4 MB) at a time; the whole
    # dataset is 64 MB, which a reader that loads it exceeds
    assert peak < size / 2, (peak, size)


@pytest.mark.parametrize("row", [0, 6, 9])
def test_a_nan_in_any_block_is_found_without_loading(big_kind, tmp_path, monkeypatch, row):
    monkeypatch.setattr(_base, "BLOCK_ELEMENTS", 7)  # 10 rows of 3 -> 2 rows a block
    values = np.ones((10, 3))
    values[row, 1] = np.nan
    path = tmp_path / "nan.h5"
    write_asset(path, "lazytest", {"values": values})
    for load in (False, True):
        with pytest.raises(AssetError, match="dataset 'values' contains NaN or inf"):
            read_asset(path, load=load)
