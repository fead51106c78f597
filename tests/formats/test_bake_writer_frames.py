"""BakeWriter.write_frames: a block of frames in one write is the same file as frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.data_formats.bake import BakeWriter, read_bake
from shtools.errors import AssetError

T, V, K = 5, 7, 4


def _arrays(seed=0):
    rng = np.random.default_rng(seed)
    return {name: rng.normal(size=(T, V, k)).astype(np.float32)
            for name, k in (("radiance", 3), ("vertices", 3), ("normals", 3),
                            ("visibility", K))}


def _writer(path):
    return BakeWriter(path, n_frames=T, faces=[[0, 1, 2]], sh_order=2, n_vertices=V,
                      visibility_size=K, compression=None)


def test_write_frames_gives_the_bytes_of_write_frame(tmp_path):
    a = _arrays()
    with _writer(tmp_path / "one.h5") as w:
        for t in range(T):
            w.write_frame(t, a["radiance"][t], vertices=a["vertices"][t],
                          normals=a["normals"][t], visibility=a["visibility"][t])
    with _writer(tmp_path / "blocks.h5") as w:
        for start, stop in ((0, 2), (2, 5)):  # blocks of unequal length
            w.write_frames(start, a["radiance"][start:stop],
                           vertices=a["vertices"][start:stop],
                           normals=a["normals"][start:stop],
                           visibility=a["visibility"][start:stop])
    assert (tmp_path / "one.h5").read_bytes() == (tmp_path / "blocks.h5").read_bytes()
    back = read_bake(tmp_path / "blocks.h5")
    for name, values in a.items():
        np.testing.assert_array_equal(getattr(back, name), values)


def test_write_frames_refuses_nan_and_leaves_no_file(tmp_path):
    a = _arrays()
    a["radiance"][3, 2, 1] = np.nan
    with pytest.raises(AssetError, match="frame 3 produced NaN"), _writer(tmp_path / "x.h5") as w:
        w.write_frames(0, a["radiance"], vertices=a["vertices"], normals=a["normals"],
                       visibility=a["visibility"])
    assert list(tmp_path.iterdir()) == []
