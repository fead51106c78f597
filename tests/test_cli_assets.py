"""``shtools info/check/diff`` and the asset layer's guarantees, through the real CLI.

Bad files of every kind must give ONE line ``error: <file>: ...`` on stderr, a
non-zero exit, nothing on stdout and no traceback; writes are atomic and
deterministic.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from shtools.data_formats import write_asset
from shtools.data_formats.light import write_light
from shtools.data_formats.tables import write_tables
from shtools.sh.tables import build_log_tables

ORDER = 3


@pytest.fixture(scope="module")
def tables_dict():
    return build_log_tables(ORDER, samples=16)


@pytest.fixture
def good(tmp_path, tables_dict):
    path = tmp_path / "good.h5"
    write_tables(path, tables_dict, ORDER, parameters={"samples": 16})
    return path


def _copy(src, dst):
    shutil.copyfile(src, dst)
    return dst


def _truncated(good, path):
    data = good.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _not_hdf5(good, path):
    path.write_text("ply\nformat ascii 1.0\n")


def _set_attr(name, value):
    def make(good, path):
        _copy(good, path)
        with h5py.File(path, "r+") as f:
            f.attrs[name] = value
    return make


def _del_attr(name):
    def make(good, path):
        _copy(good, path)
        with h5py.File(path, "r+") as f:
            del f.attrs[name]
    return make


def _replace(name, data_of):
    def make(good, path):
        _copy(good, path)
        with h5py.File(path, "r+") as f:
            data = data_of(f[name][()])
            del f[name]
            if data is not None:
                f.create_dataset(name, data=data)
    return make


BAD_FILES = {
    "truncated": (_truncated, "not a readable HDF5 file"),
    "not-hdf5": (_not_hdf5, "not a readable HDF5 file"),
    "plain-hdf5": (_del_attr("format"), "not an shtools asset"),
    "unknown-kind": (_set_attr("format", "shtools/teapots"), "unknown asset kind 'teapots'"),
    "unknown-version": (_set_attr("format_version", np.int64(99)), "format version 99"),
    "missing-dataset": (_replace("ol_a", lambda a: None), "missing dataset 'ol_a'"),
    "wrong-shape": (_replace("vis_zh", lambda a: a[:, :2]), "has shape (16, 3), expected"),
    "wrong-rank": (_replace("theta", lambda a: a[:, None]), "dataset 'theta' has shape"),
    "nan": (_replace("log_zh", lambda a: np.where(a == a.max(), np.nan, a)), "NaN"),
    "bad-json": (_set_attr("parameters", "{oops"), "not valid JSON"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
@pytest.mark.parametrize("command", ["check", "info", "diff"])
def test_bad_file_gives_one_line_error(run_cli, tmp_path, good, case, command):
    make, message = BAD_FILES[case]
    bad = tmp_path / f"{case}.h5"
    make(good, bad)
    args = [command, bad] + ([good] if command == "diff" else [])
    code, stdout, stderr = run_cli(*args)
    assert code == 1
    assert stdout == ""
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"error: {bad}: ")
    assert message in lines[0]


def test_missing_file(run_cli, tmp_path):
    code, _, stderr = run_cli("check", tmp_path / "nope.h5")
    assert code == 1 and "file not found" in stderr and stderr.count("\n") == 1


def test_bad_file_in_a_subprocess_has_no_traceback(tmp_path, good):
    bad = tmp_path / "cut.h5"
    _truncated(good, bad)
    proc = subprocess.run([sys.executable, "-m", "shtools", "check", str(bad)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    assert proc.stdout == ""
    assert proc.stderr.startswith(f"error: {bad}: not a readable HDF5 file")
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1


def test_check_and_info_on_a_good_asset(run_cli, good):
    code, stdout, _ = run_cli("check", good)
    assert code == 0 and "ok (shtools/tables version 1)" in stdout
    code, stdout, _ = run_cli("info", good, "--json")
    assert code == 0
    summary = json.loads(stdout)
    assert summary["kind"] == "tables" and summary["version"] == 1
    shapes = {d["name"]: tuple(d["shape"]) for d in summary["datasets"]}
    assert shapes["vis_zh"] == (16, ORDER) and shapes["theta"] == (16,)
    theta = next(d for d in summary["datasets"] if d["name"] == "theta")
    assert 0 < theta["min"] < theta["max"] == pytest.approx(np.pi / 2)
    assert summary["attributes"]["parameters"] == {"order": ORDER, "samples": 16}
    code, stdout, _ = run_cli("info", good)
    assert code == 0 and "vis_zh" in stdout and "SH order      3" in stdout


# ------------------------------------------------------------------ determinism


def test_two_writes_are_byte_identical(run_cli, tmp_path):
    """Same parameters -> identical datasets AND identical files.

    Whole-file equality holds because write_asset stores no timestamps
    (track_times=False), writes attributes in sorted order and nothing
    time-dependent; it is stricter than the dataset equality docs/formats.md asks for.
    """
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    for path in (a, b):
        assert run_cli("tables", "log", "--order", ORDER, "--samples", 16, "-o", path)[0] == 0
    with h5py.File(a) as fa, h5py.File(b) as fb:
        for name in fa:
            assert fa[name][()].tobytes() == fb[name][()].tobytes()
    assert a.read_bytes() == b.read_bytes()


# ----------------------------------------------------------------- atomic writes


class _Exploding:
    """array-like whose conversion fails halfway through a write."""

    def __init__(self, exc):
        self.exc = exc

    def __array__(self, dtype=None, copy=None):
        raise self.exc


@pytest.mark.parametrize("exc", [RuntimeError("disk on fire"), KeyboardInterrupt()])
def test_interrupted_write_leaves_no_file(tmp_path, exc):
    target = tmp_path / "light.h5"
    # "a" sorts before "b": one dataset is already in the temporary file when "b" fails.
    datasets = {"a_written_first": np.ones(3), "b_fails": _Exploding(exc)}
    with pytest.raises(type(exc)):
        write_asset(target, "light", datasets, sh_order=1)
    assert list(tmp_path.iterdir()) == []


def test_failed_rewrite_keeps_the_old_file(tmp_path):
    target = tmp_path / "light.h5"
    write_light(target, np.ones((4, 3)))
    before = target.read_bytes()
    with pytest.raises(RuntimeError):
        write_asset(target, "light", {"coeffs": _Exploding(RuntimeError("x"))}, sh_order=2)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["light.h5"]


# ------------------------------------------------------------------------- diff


@pytest.fixture
def light_pair(tmp_path):
    rng = np.random.default_rng(0)
    coeffs = rng.normal(size=(9, 3))
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_light(a, coeffs, parameters={"order": 3})
    write_light(b, coeffs, parameters={"order": 3})
    return a, b, coeffs


def test_diff_identical(run_cli, light_pair):
    a, b, _ = light_pair
    code, stdout, stderr = run_cli("diff", a, b)
    assert code == 0 and stderr == ""
    assert "within tolerance" in stdout and "identical" in stdout


def test_diff_reports_the_worst_element(run_cli, light_pair):
    a, b, coeffs = light_pair
    bumped = coeffs.copy()
    bumped[5, 1] += 1e-3
    bumped[2, 0] *= 1 + 1e-7  # inside the default rtol 1e-5
    write_light(a, bumped, parameters={"order": 3})
    code, stdout, stderr = run_cli("diff", a, b, "--json")
    assert code == 1
    assert stderr.startswith(f"error: {a}: differs from {b}: 1 value(s) outside tolerance")
    result = json.loads(stdout)
    assert result["equal"] is False
    worst = result["worst"][0]
    assert worst["dataset"] == "coeffs" and worst["index"] == [5, 1]
    assert worst["a"] == bumped[5, 1] and worst["b"] == coeffs[5, 1]
    assert worst["abs"] == pytest.approx(1e-3, rel=1e-9)
    assert worst["rel"] == pytest.approx(1e-3 / abs(coeffs[5, 1]), rel=1e-9)
    (entry,) = result["datasets"]
    assert entry["outside"] == 1
    # a loose enough tolerance accepts it
    assert run_cli("diff", a, b, "--atol", 2e-3)[0] == 0
    # human output names the element
    code, stdout, _ = run_cli("diff", a, b)
    assert "coeffs [5,1]" in stdout and "1 of 27 outside" in stdout


def test_diff_ignores_generator_and_inputs_unless_asked(run_cli, light_pair, tmp_path):
    a, b, _ = light_pair
    with h5py.File(a, "r+") as f:
        f.attrs["generator"] = "shtools 9.9.9"
        f.attrs["inputs"] = json.dumps({"probe.hdr": "0" * 64})
    assert run_cli("diff", a, b)[0] == 0
    code, stdout, _ = run_cli("diff", a, b, "--inputs")
    assert code == 1 and "attribute inputs.probe.hdr differs" in stdout


def test_diff_reports_parameters_and_can_ignore_them(run_cli, light_pair):
    a, b, coeffs = light_pair
    write_light(a, coeffs, parameters={"order": 3, "window": "hann"})
    code, stdout, _ = run_cli("diff", a, b)
    assert code == 1 and "parameters.window differs" in stdout
    assert run_cli("diff", a, b, "--ignore", "window")[0] == 0


def test_diff_shape_kind_and_missing_dataset(run_cli, light_pair, tmp_path, good):
    a, b, _ = light_pair
    write_light(a, np.ones((16, 3)))
    code, stdout, _ = run_cli("diff", a, b)
    assert code == 1 and "shape differs: A (16, 3) vs B (9, 3)" in stdout
    code, stdout, _ = run_cli("diff", good, b)
    assert code == 1 and "kind differs: A is 'tables', B is 'light'" in stdout
    with h5py.File(b, "r+") as f:
        f.create_dataset("extra", data=np.zeros(2))
    write_light(a, np.ones((9, 3)))
    code, stdout, _ = run_cli("diff", a, b)
    assert code == 1 and "dataset extra is missing in A" in stdout


def test_diff_nan_equals_nan_but_not_a_number(run_cli, tmp_path):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    # field-like free-form datasets: the light schema does not forbid extras
    for path, extra in ((a, [np.nan, 1.0]), (b, [np.nan, 1.0])):
        write_asset(path, "light", {"coeffs": np.ones((1, 3)), "extra": np.array(extra)},
                    sh_order=1)
    assert run_cli("diff", a, b)[0] == 0
    write_asset(a, "light", {"coeffs": np.ones((1, 3)), "extra": np.array([0.0, 1.0])},
                sh_order=1)
    code, stdout, _ = run_cli("diff", a, b, "--json")
    assert code == 1
    assert json.loads(stdout)["worst"][0]["index"] == [0]


def test_diff_streams_blocks_and_keeps_global_indices(run_cli, tmp_path, monkeypatch):
    """With tiny blocks the worst elements still carry their index in the whole array."""
    import shtools.data_formats.compare as assets

    monkeypatch.setattr(assets, "BLOCK_ELEMENTS", 7)  # 4 rows of 3x3 -> one row per block
    rng = np.random.default_rng(9)
    ref = rng.uniform(1, 2, size=(4, 3, 3))
    new = ref.copy()
    new[2, 1, 0] += 0.5
    new[3, 2, 2] += 0.1
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    for path, extra in ((a, new), (b, ref)):
        write_asset(path, "light", {"coeffs": np.ones((1, 3)), "extra": extra}, sh_order=1)
    code, stdout, _ = run_cli("diff", a, b, "--json", "--show", 2)
    assert code == 1
    result = json.loads(stdout)
    assert [w["index"] for w in result["worst"]] == [[2, 1, 0], [3, 2, 2]]
    extra = next(d for d in result["datasets"] if d["name"] == "extra")
    assert extra["outside"] == 2 and extra["max_abs"] == pytest.approx(0.5)


def test_diff_relative_rmse_criterion(run_cli, light_pair):
    """rel RMSE = ||a - b|| / ||b||, computed here independently of the tool."""
    a, b, coeffs = light_pair
    bumped = coeffs * (1 + 1e-3)
    write_light(a, bumped, parameters={"order": 3})
    expected = np.linalg.norm(bumped - coeffs) / np.linalg.norm(coeffs)
    code, stdout, _ = run_cli("diff", a, b, "--rtol", 1e-2, "--json")
    assert code == 0
    assert json.loads(stdout)["datasets"][0]["rel_rmse"] == pytest.approx(expected, rel=1e-9)
    code, _, stderr = run_cli("diff", a, b, "--rtol", 1e-2, "--rel-rmse", 5e-4)
    assert code == 1 and "1 dataset(s) above the relative RMSE limit" in stderr
    assert run_cli("diff", a, b, "--rtol", 1e-2, "--rel-rmse", 2e-3)[0] == 0


def test_info_ranges_streamed_in_blocks_match_numpy(run_cli, good, monkeypatch):
    import shtools.data_formats.compare as assets

    monkeypatch.setattr(assets, "BLOCK_ELEMENTS", 5)  # many blocks per dataset
    code, stdout, _ = run_cli("info", good, "--json")
    assert code == 0
    with h5py.File(good) as f:
        for d in json.loads(stdout)["datasets"]:
            data = f[d["name"]][()]
            assert (d["min"], d["max"]) == (data.min(), data.max())
