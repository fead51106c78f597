"""The set-up cache (``shtools.cache``): hits, misses, keys, corruption, concurrency,
eviction, an unusable folder, and bakes that are the same bytes with and without it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import trimesh
from helpers.calls import count_calls
from helpers.rig import ground_scene_head
from helpers.scenes import torus_and_ring

from shtools.cache import SetupCache, cache_key, parse_size


def _counting(value):
    """A compute function returning ``value`` and counting its calls."""
    calls = []

    def compute():
        calls.append(1)
        return {"a": np.asarray(value, dtype=np.float32), "n": np.arange(3)}

    return compute, calls


def _cache(path, **kw):
    warnings = []
    return SetupCache(path, warn=warnings.append, **kw), warnings


def test_a_second_fetch_of_the_same_parts_is_a_hit_with_the_same_arrays(tmp_path):
    cache, warnings = _cache(tmp_path / "c")
    compute, calls = _counting([[1.5, 2.5]])
    parts = {"v": np.ones((4, 3)), "order": 6}
    first = cache.fetch("k", 1, parts, compute)
    second = cache.fetch("k", 1, {"v": np.ones((4, 3)), "order": 6}, compute)
    assert len(calls) == 1 and (cache.hits, cache.misses) == (1, 1)
    for name in first:
        assert second[name].dtype == first[name].dtype
        assert second[name].tobytes() == first[name].tobytes()
    assert warnings == []
    assert cache.info()["entries"] == 1 and cache.info()["kinds"] == {"k": 1}


def test_the_key_changes_with_array_bytes_dtype_settings_version_and_file_bytes(tmp_path):
    f = tmp_path / "mesh.obj"
    f.write_bytes(b"v 0 0 0\n")
    base = {"v": np.zeros(3), "order": 6, "file": f}
    key = cache_key("self_log", 1, base)
    assert cache_key("self_log", 1, dict(base)) == key
    changed = [
        cache_key("self_log", 1, {**base, "v": np.array([0.0, 0.0, 1e-300])}),
        cache_key("self_log", 1, {**base, "v": np.zeros(3, dtype=np.float32)}),
        cache_key("self_log", 1, {**base, "order": 5}),
        cache_key("self_log", 2, base),
        cache_key("fit", 1, base),
    ]
    f.write_bytes(b"v 0 0 1\n")  # same path, other bytes
    changed.append(cache_key("self_log", 1, base))
    assert len(set(changed) | {key}) == len(changed) + 1


@pytest.mark.parametrize("damage", ["flip", "truncate", "empty"])
def test_a_corrupt_entry_is_recomputed_with_one_warning_and_never_used(tmp_path, damage):
    cache, warnings = _cache(tmp_path / "c")
    compute, calls = _counting([3.0, 4.0])
    parts = {"x": 1}
    cache.fetch("k", 1, parts, compute)
    (path,) = (tmp_path / "c").rglob("*.entry")
    data = bytearray(path.read_bytes())
    if damage == "flip":
        data[-5] ^= 0xFF  # inside the payload: only the checksum can tell
    elif damage == "truncate":
        data = data[: len(data) // 2]
    else:
        data = bytearray()
    path.write_bytes(bytes(data))
    got = cache.fetch("k", 1, parts, compute)
    assert len(calls) == 2  # recomputed, not read
    np.testing.assert_array_equal(got["a"], [3.0, 4.0])
    assert len(warnings) == 1 and "corrupt" in warnings[0], warnings
    # rewritten whole: the next process reads it
    again, more = _cache(tmp_path / "c")
    again.fetch("k", 1, parts, compute)
    assert len(calls) == 2 and again.hits == 1 and more == []


def test_eviction_removes_the_least_recently_used_entries_first(tmp_path):
    probe, _ = _cache(tmp_path / "probe")
    probe.fetch("k", 1, {"i": -1}, lambda: {"a": np.zeros(1000)})
    size = probe.info()["bytes"]
    cache, warnings = _cache(tmp_path / "c", max_bytes=int(3.5 * size))  # room for 3
    for i in range(3):
        cache.fetch("k", 1, {"i": i}, lambda i=i: {"a": np.full(1000, float(i))})
    paths = {i: cache.path_of("k", cache_key("k", 1, {"i": i})) for i in range(3)}
    for age, i in ((300, 0), (200, 1), (100, 2)):  # entry 0 the oldest
        t = os.path.getmtime(paths[i]) - age
        os.utime(paths[i], (t, t))
    cache.fetch("k", 1, {"i": 0}, lambda: {"a": np.zeros(1000)})  # a hit refreshes entry 0
    assert cache.hits == 1
    cache.fetch("k", 1, {"i": 3}, lambda: {"a": np.full(1000, 3.0)})  # one must go: 1
    assert not paths[1].exists()
    assert paths[0].exists() and paths[2].exists()
    assert cache.info()["entries"] == 3 and cache.info()["bytes"] <= cache.max_bytes
    assert warnings == []


def test_an_unusable_folder_still_computes_with_one_warning(tmp_path):
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    cache, warnings = _cache(blocked / "cache")
    for i in range(3):
        compute, calls = _counting([float(i)])
        got = cache.fetch("k", 1, {"i": i}, compute)
        assert calls == [1] and got["a"][0] == i
    assert len(warnings) == 1 and "cannot write" in warnings[0], warnings


def test_a_full_disk_still_computes_with_one_warning(tmp_path, monkeypatch):
    import errno

    import shtools.cache as mod

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(mod.tempfile, "mkstemp", full)
    cache, warnings = _cache(tmp_path / "c")
    compute, calls = _counting([1.0])
    assert cache.fetch("k", 1, {}, compute)["a"][0] == 1.0 and calls == [1]
    assert len(warnings) == 1 and "No space left" in warnings[0]
    assert not list((tmp_path / "c").rglob("*.entry"))


def test_a_disabled_cache_reads_and_writes_nothing(tmp_path):
    cache, _ = _cache(tmp_path / "c", enabled=False)
    compute, calls = _counting([1.0])
    cache.fetch("k", 1, {}, compute)
    cache.fetch("k", 1, {}, compute)
    assert len(calls) == 2 and not (tmp_path / "c").exists()


_WRITER = textwrap.dedent("""
    import sys, numpy as np
    from shtools.cache import SetupCache
    cache = SetupCache(sys.argv[1], warn=lambda m: print("WARN", m))
    ok = 0
    for round in range(40):
        for i in range(4):
            got = cache.fetch("k", 1, {"i": i},
                              lambda i=i: {"a": np.full(20000, float(i))})
            ok += bool(np.all(got["a"] == i))
    print(ok, cache.hits, cache.misses)
""")


def test_two_processes_sharing_one_folder_read_only_whole_entries(tmp_path):
    """Concurrent writers of the same entries (and a bound that evicts while they read):
    every fetch returns the right arrays, nothing is reported corrupt, no temp file stays."""
    folder = tmp_path / "c"
    env = {**os.environ, "SHTOOLS_CACHE_SIZE": "300K"}  # two entries of ~160 KB: evicts
    procs = [subprocess.Popen([sys.executable, "-c", _WRITER, str(folder)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    for p, (out, err) in zip(procs, outs, strict=True):
        assert p.returncode == 0, err
        assert "WARN" not in out, out
        assert out.split()[0] == "160", out
    assert not [p for p in folder.rglob(".tmp-*")]


def test_parse_size():
    assert parse_size("2G") == 2 * 2**30
    assert parse_size("500M") == 500 * 2**20
    assert parse_size("1.5KiB") == 1536
    assert parse_size("1000") == 1000
    for bad in ("lots", "-1G", ""):
        with pytest.raises(ValueError):
            parse_size(bad)


# ------------------------------------------------------------------- bakes
def _torus_scene(folder: Path, settings: str = "", blocker: str = 'spheres = "ring.h5"'):
    torus_and_ring(folder, major=0.6, minor=0.25, sphere_radius=0.35)
    (folder / "scene.toml").write_text(ground_scene_head(
        settings, size=3, subdivisions=8, frames=1, fps=None) + f"""
[[objects]]
name = "torus"
mesh = "torus.obj"
role = "both"
blocker = {{ {blocker} }}
translate = [0.0, 0.7, 0.0]
rotate = [30.0, 0.0, 0.0]
""")
    return folder / "scene.toml"


def _bake(run_cli, scene, out, *extra):
    code, stdout, err = run_cli("bake", scene, "-o", out, "--workers", "1", "--processes", "1",
                                "--json", *extra)
    assert code == 0, err
    return json.loads(stdout), err


def _count_transfers(monkeypatch):
    import shtools.geometry.transfer as sv

    return count_calls(monkeypatch, sv, "hemisphere_transfer")


def test_a_second_bake_reads_its_self_visibility_and_writes_the_same_bytes(
        tmp_path, run_cli, monkeypatch):
    scene = _torus_scene(tmp_path)
    calls = _count_transfers(monkeypatch)
    cache = tmp_path / "cache"
    first, _ = _bake(run_cli, scene, tmp_path / "a.h5", "--cache", cache)
    assert first["cache"]["kinds"]["self_log"] == {"hits": 0, "misses": 1} and len(calls) == 1
    second, _ = _bake(run_cli, scene, tmp_path / "b.h5", "--cache", cache)
    assert second["cache"]["kinds"]["self_log"] == {"hits": 1, "misses": 0} and len(calls) == 1
    none, _ = _bake(run_cli, scene, tmp_path / "c.h5", "--cache", cache, "--no-cache")
    assert none["cache"]["enabled"] is False and len(calls) == 2
    assert (none["cache"]["hits"], none["cache"]["misses"]) == (0, 0)
    a, b, c = ((tmp_path / n).read_bytes() for n in ("a.h5", "b.h5", "c.h5"))
    assert a == b == c
    # the traced visibility is projected at the shading order and multiplied in after the
    # exp: another accumulation order reads the same entry
    scene_text = scene.read_text().replace("frames = 1\n", "frames = 1\nacc_order = 4\n")
    scene.write_text(scene_text)
    third, _ = _bake(run_cli, scene, tmp_path / "d.h5", "--cache", cache)
    assert third["cache"]["kinds"]["self_log"] == {"hits": 1, "misses": 0} and len(calls) == 2
    # other mesh bytes under the same file name are another entry
    mesh = trimesh.load(tmp_path / "torus.obj", process=False)
    mesh.vertices[0] += 1e-3
    mesh.export(tmp_path / "torus.obj")
    fourth, _ = _bake(run_cli, scene, tmp_path / "e.h5", "--cache", cache)
    assert fourth["cache"]["kinds"]["self_log"]["misses"] == 1 and len(calls) == 3


def test_a_still_scene_traces_its_ground_shadow_once_for_all_bakes(tmp_path, run_cli,
                                                                   monkeypatch):
    """A still object over a still ground: its traced shadow and the ground's neighbour
    lists come from the cache on the second bake (no trace, no Embree scene built), the
    same bytes; a moving object's trace is never stored."""
    import shtools.geometry.raycast as rc
    import shtools.scene.kept_traces as kept
    import shtools.scene.receiver_filter as rf
    import shtools.scene.traced_shadows as ts

    monkeypatch.setattr(rf, "_NEIGHBOURS", [])  # what this process searched before
    monkeypatch.setattr(kept, "_GROUND", {})
    traces = count_calls(monkeypatch, ts, "_trace_ground")
    built = count_calls(monkeypatch, rc.RayCaster, "__init__")
    scene = _torus_scene(tmp_path)
    cache = tmp_path / "cache"
    first, _ = _bake(run_cli, scene, tmp_path / "a.h5", "--cache", cache)
    kinds = first["cache"]["kinds"]
    assert kinds["traced_ground"] == kinds["filter_neighbours"] == {"hits": 0, "misses": 1}
    assert len(traces) == 1 and len(built) >= 1
    kept._GROUND.clear()  # a new process keeps nothing (run_cli runs in this one)
    rf._NEIGHBOURS.clear()
    n_built = len(built)
    second, _ = _bake(run_cli, scene, tmp_path / "b.h5", "--cache", cache)
    assert second["cache"]["kinds"]["traced_ground"] == {"hits": 1, "misses": 0}
    assert second["cache"]["misses"] == 0 and len(traces) == 1
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()
    # the caster of the torus over the ground is not built on a hit (the self-visibility
    # came from the cache too)
    assert len(built) == n_built
    text = scene.read_text().replace('translate = [0.0, 0.7, 0.0]\n', """translate = [0.0, 0.7, 0.0]
[[objects.keyframes]]
time = 0.0
translate = [0.0, 0.7, 0.0]
[[objects.keyframes]]
time = 1.0
translate = [0.2, 0.7, 0.0]
""")
    scene.write_text(text)
    rf._NEIGHBOURS.clear()
    moving, _ = _bake(run_cli, scene, tmp_path / "c.h5", "--cache", cache)
    assert "traced_ground" not in moving["cache"]["kinds"] and len(traces) == 2
    assert moving["cache"]["kinds"]["filter_neighbours"] == {"hits": 1, "misses": 0}
    # a moving ground's neighbour lists would be a new entry every frame: none is stored
    scene.write_text(text.replace('role = "receiver"\n', 'role = "receiver"\n'
                                  "[[objects.keyframes]]\ntime = 0.0\n"
                                  "[[objects.keyframes]]\ntime = 1.0\n"
                                  "translate = [0.0, 0.1, 0.0]\n", 1))
    rf._NEIGHBOURS.clear()
    ground_moves, _ = _bake(run_cli, scene, tmp_path / "d.h5", "--cache", cache)
    assert "filter_neighbours" not in ground_moves["cache"]["kinds"]


def test_the_default_cache_folder_comes_from_the_environment(tmp_path, run_cli, monkeypatch,
                                                             _setup_cache):
    scene = _torus_scene(tmp_path)
    _bake(run_cli, scene, tmp_path / "a.h5")
    code, out, err = run_cli("cache", "info", "--json")
    assert code == 0, err
    info = json.loads(out)
    assert Path(info["location"]) == _setup_cache
    # (the ground's neighbour lists too, unless this process searched them already)
    assert info["kinds"]["self_log"] == info["kinds"]["traced_ground"] == 1
    assert info["entries"] == sum(info["kinds"].values()) and info["bytes"] > 0
    monkeypatch.setenv("SHTOOLS_NO_CACHE", "1")
    summary, _ = _bake(run_cli, scene, tmp_path / "b.h5")
    assert summary["cache"]["enabled"] is False
    code, out, err = run_cli("cache", "clear")
    assert code == 0 and f"removed {info['entries']} entries" in out, (out, err)
    code, out, _ = run_cli("cache", "info")
    assert "0 entries" in out


def test_a_fit_on_the_fly_is_fitted_once(tmp_path, run_cli, monkeypatch):
    import shtools.geometry.sphere_fit as sf

    calls = []
    real = sf.fit_spheres

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(sf, "fit_spheres", counting)
    scene = _torus_scene(tmp_path, "self_visibility = false", blocker="fit = 6")
    cache = tmp_path / "cache"
    first, _ = _bake(run_cli, scene, tmp_path / "a.h5", "--cache", cache)
    second, _ = _bake(run_cli, scene, tmp_path / "b.h5", "--cache", cache)
    assert len(calls) == 1
    assert first["cache"]["kinds"]["fit"]["misses"] == 1
    assert second["cache"]["kinds"]["fit"]["hits"] == 1
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()
    scene.write_text(scene.read_text().replace("fit = 6", "fit = 6, seed = 1"))
    _bake(run_cli, scene, tmp_path / "c.h5", "--cache", cache)
    assert len(calls) == 2


def test_a_bake_with_an_unwritable_cache_succeeds_with_one_warning(tmp_path, run_cli):
    scene = _torus_scene(tmp_path)
    blocked = tmp_path / "file"
    blocked.write_text("x")
    _bake(run_cli, scene, tmp_path / "ref.h5", "--no-cache")
    _, err = _bake(run_cli, scene, tmp_path / "a.h5", "--cache", blocked / "sub")
    lines = [line for line in err.splitlines() if line.startswith("warning:")]
    assert len(lines) == 1 and "cannot write" in lines[0], err
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "ref.h5").read_bytes()


def test_a_corrupt_entry_in_a_bake_is_recomputed_with_one_warning(tmp_path, run_cli):
    scene = _torus_scene(tmp_path)
    cache = tmp_path / "cache"
    _bake(run_cli, scene, tmp_path / "a.h5", "--cache", cache)
    (entry,) = cache.rglob("*-self_log.entry")
    entry.write_bytes(entry.read_bytes()[:-100])
    summary, err = _bake(run_cli, scene, tmp_path / "b.h5", "--cache", cache)
    assert summary["cache"]["kinds"]["self_log"]["misses"] == 1
    assert sum(line.startswith("warning:") for line in err.splitlines()) == 1, err
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()


def test_a_midrange_scaling_table_is_built_once(tmp_path):
    """The mid-range environment's scaling table (built in memory when the scene names
    no scaling asset) comes back from the cache equal, scalars as the same Python values."""
    from shtools.scene.midrange import DEFAULT_KMAX, DEFAULT_SAMPLES, _scaling_table
    from shtools.sh.scaling import build_scaling_table

    cache, warnings = _cache(tmp_path / "c")
    first = _scaling_table(4, cache)
    second = _scaling_table(4, cache)
    assert (cache.hits, cache.misses) == (1, 1) and warnings == []
    # built independently, without a cache
    want = build_scaling_table(4, "midrange", samples=DEFAULT_SAMPLES,
                               k_range=(0.0, DEFAULT_KMAX))
    for table in (first, second):
        assert table.keys() == want.keys()
        for k, v in want.items():
            if isinstance(v, np.ndarray):
                assert table[k].dtype == v.dtype and table[k].tobytes() == v.tobytes(), k
            else:
                assert type(table[k]) is type(v) and table[k] == v, k
