"""The asset comparison engine as a library (shtools.data_formats.compare), no CLI involved."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.data_formats._base import write_asset
from shtools.data_formats.compare import compare_assets, summarize_asset


@pytest.fixture
def pair(tmp_path):
    rng = np.random.default_rng(4)
    ref = rng.uniform(1.0, 2.0, size=(5, 4))
    new = ref.copy()
    new[3, 1] *= 1.0 + 1e-3  # one element 1e-3 off, relative
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_asset(a, "light", {"coeffs": np.ones((1, 3)), "extra": new}, sh_order=1)
    write_asset(b, "light", {"coeffs": np.ones((1, 3)), "extra": ref}, sh_order=1)
    return a, b, new, ref


def test_compare_reports_the_worst_element_with_numpy_figures(pair):
    a, b, new, ref = pair
    r = compare_assets(a, b, rtol=1e-4, atol=0.0, worst=1)
    assert not r["equal"]
    (w,) = r["worst"]
    assert (w["dataset"], list(w["index"])) == ("extra", [3, 1])
    assert w["abs"] == pytest.approx(abs(new[3, 1] - ref[3, 1]), rel=1e-12)
    extra = next(d for d in r["datasets"] if d["name"] == "extra")
    # relative RMSE computed independently
    assert extra["rel_rmse"] == pytest.approx(np.linalg.norm(new - ref) / np.linalg.norm(ref),
                                              rel=1e-9)
    assert extra["outside"] == 1


def test_compare_within_tolerance_and_ignore(pair):
    a, b, _, _ = pair
    assert compare_assets(a, b, rtol=2e-3, atol=0.0)["equal"]
    assert compare_assets(a, b, rtol=0.0, atol=0.0, ignore={"extra"})["equal"]


def test_summary_ranges_match_numpy(pair):
    a, _, new, _ = pair
    s = summarize_asset(a)
    assert s["kind"] == "light"
    extra = next(d for d in s["datasets"] if d["name"] == "extra")
    assert (extra["min"], extra["max"]) == (new.min(), new.max())
    assert extra["shape"] in ([5, 4], (5, 4))
