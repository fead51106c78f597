"""The ``tables`` asset: round trip, validation, and the ``tables log`` command."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from shtools.data_formats.tables import TABLE_KEYS, read_tables, write_tables
from shtools.errors import AssetError
from shtools.sh.tables import build_log_tables

ORDER = 3
SAMPLES = 24  # few cap radii keep the test fast; the layout does not depend on it


@pytest.fixture(scope="module")
def built():
    return build_log_tables(ORDER, samples=SAMPLES)


def test_round_trip_keeps_every_array_bit_for_bit(tmp_path, built):
    path = tmp_path / "tables.h5"
    write_tables(path, built, ORDER, parameters={"samples": SAMPLES})
    back = read_tables(path)
    assert back["order"] == ORDER
    for key in TABLE_KEYS:
        assert back[key].dtype == np.float64
        np.testing.assert_array_equal(back[key], np.asarray(built[key], dtype=np.float64))
    with h5py.File(path) as f:
        assert f.attrs["format"] == "shtools/tables"
        assert json.loads(f.attrs["parameters"]) == {"order": ORDER, "samples": SAMPLES}


def test_write_refuses_tables_of_another_order(tmp_path, built):
    with pytest.raises(ValueError, match=r"shape \(T, 4\)"):
        write_tables(tmp_path / "t.h5", built, ORDER + 1)
    assert not (tmp_path / "t.h5").exists()


def _tamper(path, name, data):
    with h5py.File(path, "r+") as f:
        del f[name]
        f.create_dataset(name, data=data)


@pytest.mark.parametrize(
    ("name", "make", "message"),
    [
        ("vis_zh", lambda t: np.zeros((len(t["theta"]), ORDER + 1)), r"shape|bands"),
        ("log_zh", lambda t: np.zeros((len(t["theta"]) + 1, ORDER)), r"shape"),
        ("theta", lambda t: t["theta"][::-1].copy(), r"'theta' must increase"),
        ("theta", lambda t: t["theta"] * 3.0, r"within \(0, pi/2\]"),
        ("ol_norm", lambda t: -t["ol_norm"], r"'ol_norm' must increase"),
        ("ol_a", lambda t: np.full(len(t["ol_norm"]), np.nan), r"NaN"),
    ],
)
def test_read_refuses_inconsistent_tables(tmp_path, built, name, make, message):
    path = tmp_path / "tables.h5"
    write_tables(path, built, ORDER)
    _tamper(path, name, make(built))
    with pytest.raises(AssetError, match=message) as info:
        read_tables(path)
    assert str(path) in str(info.value)


def test_read_tables_refuses_a_light_asset(tmp_path):
    from shtools.data_formats.light import write_light

    path = tmp_path / "light.h5"
    write_light(path, np.ones((4, 3)))
    with pytest.raises(AssetError, match="is a 'light' asset, expected a 'tables' asset"):
        read_tables(path)


def test_cli_tables_log_writes_a_valid_asset_and_json(run_cli, tmp_path):
    out = tmp_path / "t.h5"
    code, stdout, stderr = run_cli("tables", "log", "--order", ORDER, "--samples", SAMPLES,
                                   "-o", out, "--json")
    assert code == 0, stderr
    summary = json.loads(stdout)
    assert summary["order"] == ORDER and summary["theta_count"] == SAMPLES
    tab = read_tables(out)
    assert tab["vis_zh"].shape == (SAMPLES, ORDER)


def test_ol_tables_agree_with_eq24_on_single_caps(tmp_path, run_cli):
    """The plotted cap points (eq. 24 recomputed from vis_zh/log_zh) lie on ol_a/ol_b.

    Independent of how the tables were built: eq. 24 is re-derived here from the
    zonal coefficients alone.  Compared where the paper says OL tables are
    single-valued (||f_hat|| < 4.8); tolerance 1e-6 covers linear interpolation
    between the table's own samples (which are denser than the caps used here).
    """
    from shtools.cli.tables import OL_ACCURATE_NORM, cap_ol_points

    out = tmp_path / "t4.h5"
    assert run_cli("tables", "log", "--order", 4, "--samples", 64, "-o", out)[0] == 0
    tab = read_tables(out)
    norm, a, b = cap_ol_points(tab)
    keep = norm < OL_ACCURATE_NORM
    assert keep.sum() > 20
    # linear interpolation of a smooth curve between 64 samples: error ~h^2 ~ 1e-6
    np.testing.assert_allclose(np.interp(norm[keep], tab["ol_norm"], tab["ol_a"]), a[keep],
                               atol=1e-6)
    np.testing.assert_allclose(np.interp(norm[keep], tab["ol_norm"], tab["ol_b"]), b[keep],
                               atol=1e-6)


def test_cli_plot_writes_a_png(run_cli, tmp_path):
    out, png = tmp_path / "t.h5", tmp_path / "curves.png"
    code, stdout, stderr = run_cli("tables", "log", "--order", 4, "--samples", 48, "-o", out,
                                   "--plot", png)
    assert code == 0, stderr
    from PIL import Image

    with Image.open(png) as im:
        assert im.format == "PNG" and im.width > 600 and im.height > 500
        # not blank: the curves put many distinct colours on the canvas
        assert len(im.convert("RGB").getcolors(maxcolors=1 << 20)) > 50
    assert "plot" in stdout


def test_cli_plot_refuses_order_one(run_cli, tmp_path):
    code, _, stderr = run_cli("tables", "log", "--order", 1, "-o", tmp_path / "t.h5",
                              "--plot", tmp_path / "p.png")
    # options that do not go together: a usage error (exit 2, as click's own), naming the
    # options, not a file
    assert code == 2 and "no OL curves" in stderr and "t.h5" not in stderr
    assert list(tmp_path.iterdir()) == []
