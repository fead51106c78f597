"""The ``light`` asset: round trip and validation."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from shtools.data_formats.light import read_light, write_light
from shtools.errors import AssetError


def test_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    coeffs = rng.normal(size=(16, 3))
    path = tmp_path / "light.h5"
    write_light(path, coeffs, source="inline", parameters={"note": "x"})
    back, attrs = read_light(path)
    np.testing.assert_array_equal(back, coeffs)
    assert attrs["sh_order"] == 4 and attrs["source"] == "inline"
    assert attrs["parameters"] == {"note": "x"}
    assert attrs["sh_convention"] == "real-orthonormal-xyz"


@pytest.mark.parametrize("shape", [(15, 3), (16, 4), (16,)])
def test_write_refuses_bad_shapes(tmp_path, shape):
    with pytest.raises(ValueError):
        write_light(tmp_path / "l.h5", np.ones(shape))
    assert not (tmp_path / "l.h5").exists()


def test_read_refuses_order_mismatch(tmp_path):
    path = tmp_path / "light.h5"
    write_light(path, np.ones((9, 3)))
    with h5py.File(path, "r+") as f:
        f.attrs["sh_order"] = np.int64(4)
    with pytest.raises(AssetError, match="sh_order 4 needs 16"):
        read_light(path)
