"""The ``scaling`` asset: round trip, structural validation, ``tables scaling`` CLI."""

from __future__ import annotations

import json
import math
import re

import h5py
import numpy as np
import pytest

from shtools.data_formats.scaling import read_scaling, write_scaling
from shtools.errors import AssetError
from shtools.sh.scaling import build_scaling_table

ORDER = 3
SAMPLES = 9  # few k keep the test fast; the checks do not depend on it


@pytest.fixture(scope="module", params=[("cone", False), ("cone", True), ("midrange", False)])
def built(request):
    function, energy = request.param
    return build_scaling_table(ORDER, function, energy_preserving=energy, samples=SAMPLES,
                               alpha=math.radians(30))


def test_round_trip(tmp_path, built):
    path = tmp_path / "s.h5"
    write_scaling(path, built, parameters={"order": ORDER})
    back = read_scaling(path)
    for key in ("k", "values"):
        np.testing.assert_array_equal(back[key], built[key])
    for key in ("rows", "cols"):
        np.testing.assert_array_equal(back[key], built[key])
    for key in ("function", "energy_preserving", "k_spacing", "interpolation", "out_of_range",
                "quadrature_nodes", "quadrature_error"):
        assert back[key] == built[key]
    assert back["order"] == ORDER
    if built["function"] == "cone":
        assert back["alpha"] == pytest.approx(math.radians(30))
    with h5py.File(path) as f:
        assert f.attrs["format"] == "shtools/scaling"
        assert json.loads(f.attrs["parameters"]) == {"order": ORDER}


def _tamper(path, name, fn):
    with h5py.File(path, "r+") as f:
        data = fn(f[name][()].copy())
        del f[name]
        f.create_dataset(name, data=data)


def _entry(table, l_out, l_in, m):
    rows, cols = table["rows"], table["cols"]
    return int(np.flatnonzero((rows == l_out * l_out + l_out + m)
                              & (cols == l_in * l_in + l_in + m))[0])


@pytest.mark.parametrize(
    ("name", "fn", "message"),
    [
        ("k", lambda k: k[::-1], r"increase"),
        ("values", lambda v: v[:, :-1], r"shape"),
        ("rows", lambda r: r[::-1], r"canonical|m"),
        ("values", lambda v: v * np.nan, r"NaN"),
    ],
)
def test_reader_refuses_broken_layout(tmp_path, built, name, fn, message):
    path = tmp_path / "s.h5"
    write_scaling(path, built)
    _tamper(path, name, fn)
    with pytest.raises(AssetError, match=message):
        read_scaling(path)


def test_reader_checks_the_structural_facts(tmp_path, built):
    path = tmp_path / "s.h5"
    ident = int(np.flatnonzero(np.abs(built["k"] - (1.0 if built["function"] == "cone"
                                                    else 0.0)) < 1e-12)[0])
    other = (ident + 1) % len(built["k"])
    cases = [
        # m = 1 and m = -1 blocks made to differ
        (lambda v: _bump(v, other, _entry(built, 1, 1, 1)), r"m = 1 and m = -1"),
        # M at the identity k no longer I (an off-diagonal m = 0 entry)
        (lambda v: _bump(v, ident, _entry(built, 2, 1, 0)), r"identity"),
    ]
    if built["energy_preserving"]:
        cases.append((lambda v: _bump(v, other, _entry(built, 0, 2, 0)), r"row 0"))
    else:
        cases.append((lambda v: _bump(v, other, _entry(built, 2, 0, 0)), r"column 0"))
    for fn, message in cases:
        write_scaling(path, built)
        _tamper(path, "values", fn)
        with pytest.raises(AssetError, match=message):
            read_scaling(path)


def _bump(values, i, p):
    values[i, p] += 1e-3
    return values


def test_reader_refuses_bad_attributes(tmp_path, built):
    path = tmp_path / "s.h5"
    for key, value, message in [("function", "wedge", "unknown scaling function"),
                                ("interpolation", "cubic", "unknown interpolation"),
                                ("sh_order", ORDER + 1, "n\\(2n\\^2\\+1\\)/3")]:
        write_scaling(path, built)
        with h5py.File(path, "r+") as f:
            f.attrs[key] = value
        with pytest.raises(AssetError, match=message):
            read_scaling(path)


def test_cli_writes_a_checked_asset(run_cli, tmp_path):
    out = tmp_path / "cone.h5"
    code, stdout, err = run_cli("tables", "scaling", "--order", 3, "--function", "cone",
                                "--alpha", 30, "--energy-preserving", "--samples", 12,
                                "--json", "-o", out)
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["entries"] == 19 and summary["quadrature_error"] < 1e-12
    table = read_scaling(out)
    assert table["energy_preserving"] and table["alpha"] == pytest.approx(math.radians(30))
    assert len(table["k"]) == 12
    code, stdout, _ = run_cli("check", out)
    assert code == 0 and "ok" in stdout
    code, stdout, _ = run_cli("info", out)
    assert code == 0 and "values" in stdout and "cone" in stdout
    # diff against an independently built plain table: the mode differs
    plain = tmp_path / "plain.h5"
    assert run_cli("tables", "scaling", "-n", 3, "--function", "cone", "--alpha", 30,
                   "--samples", 12, "-o", plain)[0] == 0
    code, stdout, _ = run_cli("diff", out, plain)
    assert code == 1 and "energy_preserving" in stdout
    assert run_cli("diff", plain, plain)[0] == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--function", "cone", "--k-range", 2, 0.5), "inverted"),
        (("--function", "midrange", "--k-range", 0.9, 0.0), "inverted"),
        (("--function", "cone", "--alpha", 0), r"--alpha.*0<x<90"),
        (("--function", "cone", "--alpha", 90), r"--alpha.*0<x<90"),
        (("--function", "cone", "--k-range", 2, 8), "0 < lo < 1 < hi"),
        (("--function", "midrange", "--k-range", 0, 1.0), "kmax < 1"),
        (("--function", "midrange", "--interpolation", "linear-log-k"), "k > 0"),
    ],
)
def test_cli_bad_inputs_one_line_no_output(run_cli, tmp_path, args, message):
    out = tmp_path / "bad.h5"
    code, _stdout, err = run_cli("tables", "scaling", "--order", 3, *args, "-o", out)
    assert code != 0
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert re.search(message, err), err
    assert "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []
