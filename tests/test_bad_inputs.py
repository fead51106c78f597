"""Every command x every bad-input family: one line, exit code, nothing written, nothing harmed.

The promise of the README: a bad input gives one line ``error: <file>: <what to
do>`` naming the file (or the option), a non-zero exit, no output file, no
temporary file left beside it, no input modified and no process left behind.

* ``CASES`` is the matrix (command x family: meshes, images, HDF5 assets, TOML,
  options, output paths), run in-process through :func:`shtools.cli.main.main`
  on one shared set of tiny inputs (``kit``, built once per test process).
  Every case checks all six promises (:func:`check_refused`).
* Behaviour that belongs to the process (signals, a full disk, worker
  processes, C libraries writing to stderr) runs ``python -m shtools`` in a
  subprocess.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from helpers.processes import alive, children, cmdline

from shtools.cli.main import main

# ---------------------------------------------------------------------------- the kit

SCENE = """
[settings]
order = 2
frames = {frames}

[environment]
light = "light.h5"

[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [4, 4], subdivisions = {subdivisions} }}
role = "receiver"

[[objects]]
name = "block"
mesh = "mesh.obj"
role = "blocker"
translate = [0, 1, 0]
blocker = {{ spheres = "spheres.h5" }}

[[objects]]
name = "ball"
primitive = {{ type = "sphere", radius = 0.4, subdivisions = 1, center = [1, 1, 0] }}
role = "blocker"
"""


def _run(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


class Kit:
    """Tiny valid inputs, bad variants of each, and their hashes."""

    def __init__(self, root: Path):
        import cv2
        import h5py
        import trimesh

        self.root = root
        k = root
        trimesh.creation.box(extents=[0.6, 0.6, 0.6]).export(k / "mesh.obj")
        (k / "scene.toml").write_text(SCENE.format(frames=2, subdivisions=4))
        cv2.imwrite(str(k / "env.hdr"), np.random.default_rng(0).random((8, 16, 3))
                    .astype(np.float32) + 0.1)
        for args in (("spheres", "fit", k / "mesh.obj", "-n", 2, "--method", "kmeans",
                      "-o", k / "spheres.h5"),
                     ("spheres", "tree", k / "spheres.h5", "-o", k / "tree.h5"),
                     ("tables", "log", "-n", 2, "--samples", 16, "-o", k / "tables.h5"),
                     ("light", "project", k / "env.hdr", "-n", 2, "-o", k / "light.h5"),
                     ("bake", k / "scene.toml", "-o", k / "baked.h5", "--processes", 1,
                      "--workers", 1)):
            code, _, err = _run(*args)
            assert code == 0, (args, err)
        # bad meshes
        (k / "folder.obj").mkdir()
        (k / "garbage.obj").write_bytes(bytes(range(256)) * 8)
        (k / "text.obj").write_text("hello\nthis is not a mesh\n")
        (k / "zero.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
        (k / "nan.obj").write_text("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        (k / "empty.obj").write_bytes(b"")
        (k / "latin1.obj").write_bytes(b"# caf\xe9\n" + (k / "mesh.obj").read_bytes())
        stl = io.BytesIO()
        trimesh.creation.box().export(stl, file_type="stl")
        (k / "trunc.stl").write_bytes(stl.getvalue()[:300])
        (k / "trunc_ascii.stl").write_text("solid x\nfacet normal 0 0 1\nouter loop\n")
        (k / "bad.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [')
        # bad images
        hdr = (k / "env.hdr").read_bytes()
        (k / "trunc.hdr").write_bytes(hdr[: len(hdr) // 2])
        (k / "huge.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n"
                                     b"-Y 20000 +X 40000\n" + bytes(64))
        (k / "huge.pfm").write_bytes(b"PF\n40000 20000\n-1.0\n" + bytes(64))
        (k / "image.png").write_bytes(b"\x89PNG\r\n")
        (k / "huge.sph").write_text("1000000000 8\n0 0 0 1 0\n")
        # bad assets
        (k / "text.h5").write_text("not hdf5")
        baked = (k / "baked.h5").read_bytes()
        (k / "trunc.h5").write_bytes(baked[: len(baked) // 2])
        for name, edit in (("version_str", lambda f: f.attrs.__setitem__("format_version", "1")),
                           ("order_str", lambda f: f.attrs.__setitem__("sh_order", "four")),
                           ("names_bad", lambda f: f.attrs.__setitem__("object_names", "[oops")),
                           ("fps_zero", lambda f: f.attrs.__setitem__("fps", 0.0))):
            (k / f"{name}.h5").write_bytes(baked)
            with h5py.File(k / f"{name}.h5", "r+") as f:
                edit(f)
        with h5py.File(k / "baked.h5", "r") as src, h5py.File(k / "zero_frames.h5", "w") as f:
            for key, value in src.attrs.items():
                f.attrs[key] = value
            for name in src:
                data = src[name][()]
                if name in ("radiance", "times", "frame_index"):
                    data = data[:0]
                f.create_dataset(name, data=data)
        self.hashes = {p: _sha(p) for p in k.iterdir() if p.is_file()}

    def intact(self) -> list[str]:
        """Names of kit files that changed or vanished (should be none)."""
        return [p.name for p, h in self.hashes.items() if not p.is_file() or _sha(p) != h]


@pytest.fixture(scope="session")
def kit(tmp_path_factory):
    return Kit(tmp_path_factory.mktemp("kit"))


def _leftover_processes() -> list[int]:
    """Processes this test process left running: its children, and what its fork server forked.

    multiprocessing's fork server and resource tracker stay by design (started once per
    process, like a thread pool; shtools.tasks.worker_context); their children would be
    workers left behind.
    """
    left = []
    for child in children():
        if b"multiprocessing." in (cmdline(child) or b""):
            left += children(child)
        else:
            left.append(child)
    return left


def _temporaries(*folders: Path) -> list[str]:
    return [p.name for d in folders for p in d.glob(".*.tmp")]


def check_refused(code, stdout, stderr, *, want_code, named, outputs, kit, folders=()):
    """The six promises of a refused command (see the module docstring)."""
    lines = stderr.strip().splitlines()
    assert code == want_code, (code, stderr)
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ") and "Traceback" not in stderr, stderr
    assert "internal error" not in lines[0], lines[0]
    for name in named:
        assert name in lines[0], (name, lines[0])
    for out in outputs:
        assert not Path(out).exists(), out
    assert _temporaries(kit.root, *folders) == []
    assert kit.intact() == []
    if sys.platform.startswith("linux"):
        assert _leftover_processes() == []


# ------------------------------------------------------------------------- the matrix
#: (id, argv with {k} = kit folder and {o} = output folder, exit code, texts the line
#: must contain).  Outputs are every {o}/... path of the argv.
CASES = [
    # --- meshes x spheres fit / eval / spheres import --mesh
    *[(f"fit-{name}", ["spheres", "fit", "{k}/" + name, "-n", "2", "-o", "{o}/s.h5"],
       2 if name == "folder.obj" else 1, [name, why]) for name, why in [
        ("missing.obj", "not found"), ("folder.obj", "directory"), ("garbage.obj", "binary"),
        ("text.obj", "no faces"), ("zero.obj", "face index 0"), ("nan.obj", "NaN"),
        ("empty.obj", "no faces"), ("trunc.stl", "truncated"),
        ("trunc_ascii.stl", "truncated"), ("bad.gltf", "JSON"), ("image.png", "unsupported")]],
    ("eval-mesh-garbage", ["eval", "--mesh", "{k}/garbage.obj", "--spheres", "{k}/spheres.h5",
                           "--grid", "4"], 1, ["garbage.obj"]),
    ("import-missing-sph", ["spheres", "import", "{k}/none.sph", "-o", "{o}/s.h5"], 1,
     ["none.sph", "not found"]),
    ("import-mesh-garbage", ["spheres", "import", "{k}/huge.sph", "--mesh", "{k}/garbage.obj",
                             "-o", "{o}/s.h5"], 1, ["huge.sph"]),
    # --- images x light project
    *[(f"light-{name}", ["light", "project", "{k}/" + name, "-n", "2", "-o", "{o}/l.h5"], 1,
       [name, why]) for name, why in [
        ("trunc.hdr", "cannot decode"), ("huge.hdr", "40000x20000"),
        ("huge.pfm", "40000x20000"), ("image.png", "unsupported"), ("missing.hdr", "not found"),
        ("mesh.obj", "unsupported")]],
    # --- HDF5 assets x info / check / diff / export / spheres tree / spheres export
    *[(f"{cmd}-{name}", [*cmd.split("_"), "{k}/" + name, *extra], 1, [name, why])
      for cmd, extra in [("info", []), ("check", []), ("diff", ["{k}/baked.h5"]),
                         ("export", ["-o", "{o}/x.png"])]
      for name, why in [("missing.h5", "not found"), ("text.h5", "HDF5"),
                        ("trunc.h5", "HDF5"), ("version_str.h5", "format_version"),
                        ("order_str.h5", "sh_order"), ("names_bad.h5", "object_names"),
                        ("zero_frames.h5", "0 frame"), ("fps_zero.h5", "fps")]],
    ("export-spheres-asset", ["export", "{k}/spheres.h5", "-o", "{o}/x.png"], 1,
     ["spheres.h5", "'spheres' asset"]),
    ("tree-baked-asset", ["spheres", "tree", "{k}/baked.h5", "-o", "{o}/t.h5"], 1,
     ["baked.h5", "'bake' asset"]),
    ("spheres-export-text", ["spheres", "export", "{k}/text.h5", "-o", "{o}/x.sph"], 1,
     ["text.h5"]),
    ("eval-spheres-tables", ["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/tables.h5"],
     1, ["tables.h5"]),
    # --- output paths: output == input, folders, empty, pairs
    ("out-bake-scene", ["bake", "{k}/scene.toml", "-o", "{k}/scene.toml"], 1,
     ["scene.toml", "also an input"]),
    ("out-bake-named-mesh", ["bake", "{k}/scene.toml", "-o", "{k}/mesh.obj"], 1,
     ["mesh.obj", "also an input"]),
    ("out-bake-named-spheres", ["bake", "{k}/scene.toml", "-o", "{k}/spheres.h5"], 1,
     ["spheres.h5", "also an input"]),
    ("out-bake-named-light", ["bake", "{k}/scene.toml", "-o", "{k}/light.h5"], 1,
     ["light.h5", "also an input"]),
    ("out-fit-mesh", ["spheres", "fit", "{k}/mesh.obj", "-n", "2", "-o", "{k}/mesh.obj"], 1,
     ["mesh.obj", "also an input"]),
    ("out-light-image", ["light", "project", "{k}/env.hdr", "-n", "2", "-o", "{k}/env.hdr"], 1,
     ["env.hdr", "also an input"]),
    ("out-tree-spheres", ["spheres", "tree", "{k}/spheres.h5", "-o", "{k}/spheres.h5"], 1,
     ["spheres.h5", "also an input"]),
    ("out-export-spheres", ["spheres", "export", "{k}/spheres.h5", "-o", "{k}/spheres.h5"], 1,
     ["spheres.h5", "also an input"]),
    ("out-export-bake", ["export", "{k}/baked.h5", "-o", "{k}/baked.h5"], 1,
     ["baked.h5", "also an input"]),
    ("out-field-mesh", ["field", "sample", "{k}/mesh.obj", "-o", "{k}/mesh.obj"], 1,
     ["mesh.obj", "also an input"]),
    ("out-transfer-mesh", ["transfer", "{k}/mesh.obj", "-o", "{k}/mesh.obj"], 1,
     ["mesh.obj", "also an input"]),
    ("out-import-mesh", ["spheres", "import", "{k}/none.sph", "--mesh", "{k}/mesh.obj", "-o",
                         "{k}/mesh.obj"], 1, ["mesh.obj", "also an input"]),
    ("out-plot-equals-o", ["tables", "log", "-n", "2", "-o", "{o}/t.h5", "--plot", "{o}/t.h5"],
     1, ["t.h5", "both -o and --plot"]),
    ("out-plot-bad-folder", ["tables", "log", "-n", "2", "-o", "{o}/t.h5", "--plot",
                             "{o}/none/p.png"], 1, ["p.png", "folder does not exist"]),
    ("out-empty", ["bake", "{k}/scene.toml", "-o", ""], 1, ["-o is empty"]),
    ("out-missing-folder", ["spheres", "fit", "{k}/mesh.obj", "-n", "2", "-o",
                            "{o}/none/s.h5"], 1, ["s.h5", "folder does not exist"]),
    ("out-folder", ["light", "project", "{k}/env.hdr", "-n", "2", "-o", "{o}"], 2,
     ["directory"]),
    # --- options
    *[(f"opt-{'-'.join(a for a in args if a.startswith('--'))[2:]}-{args[-1]}",
       [*base, *args], 2, [want]) for base, args, want in [
        (["light", "project", "{k}/env.hdr", "-n", "2", "-o", "{o}/l.h5"], ["--exposure", "2000"],
         "--exposure"),
        (["light", "project", "{k}/env.hdr", "-n", "2", "-o", "{o}/l.h5"], ["--exposure", "nan"],
         "--exposure"),
        (["light", "project", "{k}/env.hdr", "-n", "2", "-o", "{o}/l.h5"], ["--window-h", "nan"],
         "--window-h"),
        (["light", "project", "{k}/env.hdr", "-n", "2", "-o", "{o}/l.h5"], ["--rotate-y", "inf"],
         "--rotate-y"),
        (["spheres", "fit", "{k}/mesh.obj", "-n", "2", "-o", "{o}/s.h5"], ["--seed", "-1"],
         "--seed"),
        (["spheres", "fit", "{k}/mesh.obj", "-n", "2", "-o", "{o}/s.h5"], ["--thickness", "inf"],
         "--thickness"),
        (["spheres", "fit", "{k}/mesh.obj", "-o", "{o}/s.h5"], ["-n", "0"], "--count"),
        (["spheres", "tree", "{k}/spheres.h5", "-o", "{o}/t.h5"], ["--seed", "-1"], "--seed"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.png"], ["--zoom", "nan"], "--zoom"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.png"], ["--elevation", "nan"], "--elevation"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.png"], ["--exposure", "nan"], "--exposure"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.gif"], ["--fps", "0"], "--fps"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.gif"], ["--fps", "-5"], "--fps"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.png"], ["--columns", "-1"], "--columns"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.png"], ["--size", "100000", "100000"],
         "--size"),
        (["bake", "{k}/scene.toml", "-o", "{o}/b.h5"], ["--processes", "0"], "--processes"),
        (["tables", "log", "-o", "{o}/t.h5"], ["-n", "99"], "--order"),
        (["tables", "log", "-n", "2", "-o", "{o}/t.h5"], ["--samples", "10000000"],
         "--samples"),
        (["diff", "{k}/baked.h5", "{k}/baked.h5"], ["--rtol", "nan"], "--rtol"),
        (["diff", "{k}/baked.h5", "{k}/baked.h5"], ["--atol", "-1"], "--atol"),
        (["spheres", "fit", "{k}/mesh.obj", "-n", "2", "-o", "{o}/s.h5"],
         ["--iterations", "1000000000"], "--iterations"),
        (["spheres", "tree", "{k}/spheres.h5", "-o", "{o}/t.h5"], ["--branching", "1"],
         "--branching"),
        (["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/spheres.h5"],
         ["--n-dirs", "1000000000"], "--n-dirs"),
        (["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/spheres.h5"], ["--gap", "inf"],
         "--gap"),
        (["export", "{k}/baked.h5", "-o", "{o}/x.png"], ["--frame", "-1"], "--frame"),
        (["tables", "scaling", "-n", "2", "--function", "cone", "-o", "{o}/s.h5"],
         ["--alpha", "nan"], "--alpha"),
    ]],
    ("opt-export-pixels", ["export", "{k}/baked.h5", "-o", "{o}/x.png", "--size", "16000",
                           "16000"], 2, ["--size", "256,000,000 pixels", "GiB"]),
    ("opt-sph-huge-levels", ["spheres", "import", "{k}/huge.sph", "-o", "{o}/s.h5"], 1,
     ["huge.sph", "levels"]),
]

#: (id, scene text edit: old -> new, texts the line must contain): bake x TOML family.
SCENE_CASES = [
    ("toml-syntax", ("[settings]", "[settings"), ["invalid TOML"]),
    ("toml-unknown-key", ("order = 2", "ordr = 2"), ["did you mean 'order'"]),
    ("toml-frames-huge", ("frames = 2", "frames = 10000000"), ["frames"]),
    ("toml-frames-float", ("frames = 2", "frames = 1e9"), ["frames", "integer"]),
    ("toml-sphere-subdivisions", ("subdivisions = 1", "subdivisions = 14"), ["vertices"]),
    ("toml-plane-subdivisions", ("subdivisions = 4", "subdivisions = 200000"), ["vertices"]),
    ("toml-center-short", ("center = [1, 1, 0]", "center = [1, 2]"), ["'center'", "3 numbers"]),
    ("toml-center-string", ("center = [1, 1, 0]", 'center = "origin"'), ["'center'"]),
    ("toml-size-long", ("size = [4, 4]", "size = [1, 2, 3]"), ["'size'", "2 numbers"]),
    ("toml-size-string", ("size = [4, 4]", 'size = "big"'), ["'size'"]),
    ("toml-radius-negative", ("radius = 0.4", "radius = -1"), ["'radius'", "positive"]),
    ("toml-translate-huge", ("translate = [0, 1, 0]", "translate = [0, 1e308, 0]"),
     ["not finite or beyond"]),
    ("toml-mesh-folder", ('mesh = "mesh.obj"', 'mesh = "folder.obj"'), ["is a folder"]),
    ("toml-mesh-garbage", ('mesh = "mesh.obj"', 'mesh = "garbage.obj"'), ["garbage.obj"]),
    ("toml-spheres-bad", ('spheres = "spheres.h5"', 'spheres = "version_str.h5"'),
     ["version_str.h5"]),
    ("toml-light-kind", ('light = "light.h5"', 'light = "spheres.h5"'),
     ["spheres.h5", "expected a 'light' asset"]),
    ("toml-image-trunc", ('light = "light.h5"', 'image = "trunc.hdr"'), ["trunc.hdr"]),
    ("toml-image-huge", ('light = "light.h5"', 'image = "huge.hdr"'), ["huge.hdr"]),
]


def _fill(argv, kit, out):
    return [a.replace("{k}", str(kit.root)).replace("{o}", str(out)) for a in argv]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_command_refuses_bad_input(case, kit, tmp_path):
    _, argv, want_code, named = case
    argv = _fill(argv, kit, tmp_path)
    outputs = [a for a in argv if a.startswith(str(tmp_path)) and a != str(tmp_path)]
    code, out, err = _run(*argv)
    check_refused(code, out, err, want_code=want_code, named=named, outputs=outputs, kit=kit,
                  folders=[tmp_path])


@pytest.mark.parametrize("case", SCENE_CASES, ids=[c[0] for c in SCENE_CASES])
def test_bake_refuses_bad_scene(case, kit, tmp_path):
    _, (old, new), named = case
    text = SCENE.format(frames=2, subdivisions=4)
    assert old in text
    scene = kit.root / f"{case[0]}.toml"
    scene.write_text(text.replace(old, new, 1))
    out = tmp_path / "b.h5"
    code, stdout, err = _run("bake", scene, "-o", out)
    # a file the scene names is named itself; otherwise the scene file is
    inner = any(n.endswith((".obj", ".h5", ".hdr")) for n in named)
    check_refused(code, stdout, err, want_code=1, named=named if inner else [scene.name, *named],
                  outputs=[out], kit=kit, folders=[tmp_path])


def test_valid_latin1_obj_is_read(kit, tmp_path):
    """One non-UTF-8 byte in a comment is no reason to refuse an OBJ (no charset guessing)."""
    out = tmp_path / "s.h5"
    code, _, err = _run("spheres", "fit", kit.root / "latin1.obj", "-n", "2", "--method",
                        "kmeans", "-o", out)
    assert code == 0, err
    assert out.is_file() and kit.intact() == []


def test_read_only_output_folder_is_refused_before_work(kit, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        if os.access(folder, os.W_OK):
            pytest.skip("running as root: a 0555 folder is writable, so nothing to refuse "
                        "(test_read_only_mount_is_refused_before_work covers a read-only "
                        "mount where it can mount one)")
        for argv in (["spheres", "fit", kit.root / "mesh.obj", "-n", "2", "-o", folder / "s.h5"],
                     ["bake", kit.root / "scene.toml", "-o", folder / "b.h5"],
                     ["tables", "log", "-n", "2", "-o", folder / "t.h5"]):
            code, out, err = _run(*argv)
            check_refused(code, out, err, want_code=1, named=["cannot write"],
                          outputs=[argv[-1]], kit=kit, folders=[folder])
    finally:
        folder.chmod(0o755)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes (POSIX)")
def test_non_regular_outputs_are_never_replaced(kit, tmp_path):
    """``-o /dev/null`` used to replace the device node by a file (as root): a named pipe
    stands in for any non-regular file here, through the CLI and the library."""
    from shtools.data_formats import write_asset
    from shtools.errors import AssetError

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    code, out, err = _run("tables", "log", "-n", "2", "-o", pipe)
    check_refused(code, out, err, want_code=1, named=["pipe", "not a regular file"],
                  outputs=[], kit=kit, folders=[tmp_path])
    with pytest.raises(AssetError, match="not a regular file"):
        write_asset(pipe, "spheres", {"centers": np.zeros((1, 3)), "radii": np.ones(1)})
    assert pipe.is_fifo() and _temporaries(tmp_path) == []
    # as an input, a pipe would block the read forever
    for argv in (["spheres", "fit", pipe, "-n", "2", "-o", tmp_path / "s.h5"],
                 ["check", pipe], ["spheres", "import", pipe, "-o", tmp_path / "s.h5"]):
        code, out, err = _run(*argv)
        check_refused(code, out, err, want_code=1, named=["pipe", "not a regular file"],
                      outputs=[tmp_path / "s.h5"], kit=kit, folders=[tmp_path])


def test_export_sequence_size_is_estimated_first(kit, tmp_path, monkeypatch):
    """A GIF or contact sheet keeps every frame's image: refused past the limit, with
    the size (the limit lowered here so the 2-frame kit bake exceeds it)."""
    import shtools.export.writer as writer

    monkeypatch.setattr(writer, "MAX_SEQUENCE_PIXELS", 10_000)
    for name in ("x.gif", "x.png"):
        out = tmp_path / name
        code, stdout, err = _run("export", kit.root / "baked.h5", "--frames", "0:2", "-o", out,
                                 "--size", "100", "100")
        check_refused(code, stdout, err, want_code=1, named=[name, "20,000 pixels"],
                      outputs=[out], kit=kit, folders=[tmp_path])


def test_long_output_names_get_short_temporaries(tmp_path):
    """A 240-byte name plus '.PID@HOST.XXXXXXXX.tmp' would pass the 255-byte limit."""
    out = tmp_path / ("a" * 240 + ".h5")
    code, _, err = _run("tables", "log", "-n", "2", "--samples", "8", "-o", out)
    assert code == 0, err
    assert out.is_file() and _temporaries(tmp_path) == []
    code, _, err = _run("tables", "log", "-n", "2", "-o", tmp_path / ("b" * 256 + ".h5"))
    assert code == 1 and "longer than 255 bytes" in err


# ------------------------------------------------------------- temporaries, disk full
def test_stale_temporaries_of_dead_owners_are_removed(kit, tmp_path):
    from shtools.data_formats._base import _host

    out = tmp_path / "t.h5"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    dead_pid = int(dead.stdout)  # a process that has exited
    stale = tmp_path / f".t.h5.{dead_pid}@{_host()}.abcdefgh.tmp"
    live = tmp_path / f".t.h5.{os.getpid()}@{_host()}.abcdefgh.tmp"
    other_host = tmp_path / f".t.h5.{dead_pid}@elsewhere.abcdefgh.tmp"
    for p in (stale, live, other_host):
        p.write_bytes(b"partial")
    code, _, err = _run("tables", "log", "-n", "2", "--samples", "8", "-o", out)
    assert code == 0, err
    assert not stale.exists()  # its owner is gone
    assert live.exists() and other_host.exists()  # running, or another machine's


@pytest.mark.parametrize("command", ["tables", "light", "bake", "export"])
def test_injected_disk_full_is_one_line_and_keeps_the_old_output(command, kit, tmp_path,
                                                                monkeypatch):
    """ENOSPC while writing: one line naming the output, old file unchanged, no temporary."""
    from shtools.data_formats import _base

    def full(*_args, **_kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    real_open = open

    def failing_open(file, mode="r", *args, **kwargs):
        handle = real_open(file, mode, *args, **kwargs)
        if "w" in mode and ".tmp" in str(file):
            handle.write = full
        return handle

    from PIL import Image

    monkeypatch.setattr(_base, "open", failing_open, raising=False)
    monkeypatch.setattr(_base.os, "posix_fallocate", full)
    monkeypatch.setattr(Image.Image, "save", full)
    out = tmp_path / ("x.png" if command == "export" else "x.h5")
    out.write_bytes(b"old")
    argv = {"tables": ["tables", "log", "-n", "2", "--samples", "8"],
            "light": ["light", "project", kit.root / "env.hdr", "-n", "2"],
            "bake": ["bake", kit.root / "scene.toml", "--processes", "1", "--workers", "1"],
            "export": ["export", kit.root / "baked.h5"]}[command]
    code, stdout, err = _run(*argv, "-o", out)
    check_refused(code, stdout, err, want_code=1, named=[out.name, "no space left"],
                  outputs=[], kit=kit, folders=[tmp_path])
    assert out.read_bytes() == b"old"


@pytest.fixture
def tiny_disk():
    """A 64 KiB tmpfs (needs mount rights; skipped with the reason otherwise).

    Mounted outside pytest's numbered temporary folders: a mount left behind
    (a run killed before this teardown) made every later session fail while
    pytest removed its old folders (EBUSY).  A mount still busy at teardown
    is detached lazily rather than left."""
    import tempfile

    mount = Path(tempfile.mkdtemp(prefix="shtools-tiny-disk-"))
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)],
                          capture_output=True)
    if done.returncode != 0:
        mount.rmdir()
        pytest.skip("cannot mount a tmpfs here (no privileges); the injected ENOSPC test "
                    "covers the same paths")
    try:
        yield mount
    finally:
        if subprocess.run(["umount", str(mount)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(mount)], check=True)
        mount.rmdir()


def _shtools(*args, **kwargs):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "shtools", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=300, **kwargs)


def test_disk_full_on_a_real_tiny_disk(kit, tiny_disk, tmp_path):
    """A real full disk (HDF5 used to segfault at exit after __dealloc__ tracebacks)."""
    big = tmp_path / "big.hdr"
    import cv2

    cv2.imwrite(str(big), np.ones((64, 128, 3), np.float32))
    for argv, name in ((["tables", "log", "-n", "8"], "t.h5"),
                       (["light", "project", big, "-n", "8"], "l.h5"),
                       (["bake", kit.root / "scene.toml", "--processes", "1"], "b.h5"),
                       (["export", kit.root / "baked.h5", "--size", "600", "600"], "x.png")):
        filler = tiny_disk / "filler"
        filler.write_bytes(bytes(14 * 4096))  # leave about one 4 KiB page
        out = tiny_disk / name
        out.write_bytes(b"old")
        done = _shtools(*argv, "-o", out)
        check_refused(done.returncode, done.stdout, done.stderr, want_code=1,
                      named=[name, "no space left"], outputs=[], kit=kit, folders=[tiny_disk])
        assert out.read_bytes() == b"old"
        filler.unlink()
        out.unlink()


def test_read_only_mount_is_refused_before_work(kit, tiny_disk):
    """A read-only file system (EROFS) is refused up front, for root too."""
    done = subprocess.run(["mount", "-o", "remount,ro", str(tiny_disk)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot remount the tmpfs read-only: {done.stderr.strip()}")
    try:
        for argv in (["spheres", "fit", kit.root / "mesh.obj", "-n", "2", "-o",
                      tiny_disk / "s.h5"],
                     ["bake", kit.root / "scene.toml", "-o", tiny_disk / "b.h5"],
                     ["tables", "log", "-n", "2", "-o", tiny_disk / "t.h5", "--plot",
                      tiny_disk / "p.png"]):
            code, out, err = _run(*argv)
            check_refused(code, out, err, want_code=1, named=["cannot write"],
                          outputs=[a for a in argv if str(tiny_disk) in str(a)], kit=kit,
                          folders=[tiny_disk])
    finally:
        subprocess.run(["mount", "-o", "remount,rw", str(tiny_disk)], check=False)


# ---------------------------------------------------------------------- processes
#: Runs the CLI with workers forced for every frame size (the real threshold is 200k
#: sphere-receiver pairs; the test scene is tiny).
FORCE_WORKERS = textwrap.dedent("""
    import importlib, sys
    importlib.import_module("shtools.runtime.evaluator").MIN_PARALLEL_PAIRS = 0
    from shtools.cli.main import main
    sys.exit(main(sys.argv[1:]))
""")


def _long_bake(kit, tmp_path, args=("--processes", "2", "--workers", "1")):
    scene = tmp_path / "long.toml"
    # ~9.4k vertices: frames last long enough, even on an idle machine, to catch the workers
    text = SCENE.format(frames=400, subdivisions=96)
    for name in ("mesh.obj", "spheres.h5", "light.h5"):
        text = text.replace(f'"{name}"', f'"{kit.root / name}"')
    scene.write_text(text)
    out = tmp_path / "long.h5"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    # SIGINT back to its default: a parent that ignores it (pytest-xdist workers do)
    # passes SIG_IGN on, and Python then installs no KeyboardInterrupt handler
    proc = subprocess.Popen([sys.executable, "-c", FORCE_WORKERS, "bake", str(scene), "-o",
                             str(out), *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    workers = []
    while time.monotonic() < deadline and proc.poll() is None:
        # the workers are forked by multiprocessing's fork server, a child of the bake
        # started by exec (as is its resource tracker); all of them must go at the end
        helpers = [c for c in children(proc.pid) if b"multiprocessing." in (cmdline(c) or b"")]
        workers = [w for h in helpers for w in children(h)]
        if workers:
            workers += helpers
            break
        time.sleep(0.5)
    if not workers:
        proc.kill()
        pytest.fail(f"the bake never started a worker process: {proc.communicate()}")
    return proc, workers, out


def _wait_gone(pids, seconds=20.0):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and any(alive(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


needs_linux = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                 reason="reads child processes from /proc")


#: the two kinds of worker processes of a bake: processes sharing one frame
#: (shtools.runtime.parallel) and processes baking whole frames (shtools.tasks)
WORKER_KINDS = {"frame-parts": ("--processes", "2", "--workers", "1"),
                "frames": ("--processes", "1", "--workers", "2")}


@needs_linux
@pytest.mark.parametrize("sig, want", [(signal.SIGTERM, 143), (signal.SIGINT, 130),
                                       (signal.SIGHUP, 129)])
def test_signal_stops_bake_workers_and_output(sig, want, kit, tmp_path):
    # the frame-parts workers (shtools.runtime.parallel); the frame pool of
    # shtools.tasks is covered by tests/scene/test_distributed.py
    proc, workers, out = _long_bake(kit, tmp_path, WORKER_KINDS["frame-parts"])
    proc.send_signal(sig)
    try:
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:  # never leave the bake running when the check fails
            proc.kill()
            proc.communicate()
    left = _wait_gone(workers)
    for pid in left:  # clean up before failing: never leave a worker running
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    check_refused(proc.returncode, stdout, stderr, want_code=want,
                  named=["stopped by" if sig != signal.SIGINT else "interrupted"],
                  outputs=[out], kit=kit, folders=[tmp_path])
    assert left == []


@needs_linux
@pytest.mark.parametrize("kind", WORKER_KINDS)
def test_workers_die_with_a_killed_parent(kind, kit, tmp_path):
    """kill -9 of the bake: its workers (and fork server) must not run on (holding stdout)."""
    proc, workers, out = _long_bake(kit, tmp_path, WORKER_KINDS[kind])
    proc.kill()
    stderr = ""
    try:  # returns only once every holder of the pipes is gone
        stderr = proc.communicate(timeout=60)[1]
    except subprocess.TimeoutExpired:
        left = workers
    else:
        left = _wait_gone(workers)
    for pid in left:  # clean up before failing: never leave a worker running
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    assert left == []
    assert not out.exists()
    # the resource tracker frees the pools' semaphores without a warning about them
    assert "leaked" not in stderr, stderr
    # the killed run's temporary is recognisable and the next write removes it
    left = _temporaries(tmp_path)
    assert left and all(f".long.h5.{proc.pid}@" in name for name in left)
    code, _, err = _run("tables", "log", "-n", "2", "--samples", "8", "-o", out)
    assert code == 0, err
    assert _temporaries(tmp_path) == []


def test_bakes_are_the_same_bytes_for_any_process_count(kit, tmp_path, monkeypatch):
    """Fixed split, fixed reduction order: CI can compare a bake from any machine exactly."""
    import importlib

    from shtools.runtime.parallel import workers_supported

    monkeypatch.setattr(importlib.import_module("shtools.runtime.evaluator"),
                        "MIN_PARALLEL_PAIRS", 0)
    scene = tmp_path / "scene.toml"
    text = SCENE.format(frames=2, subdivisions=16)
    for name in ("mesh.obj", "spheres.h5", "light.h5"):
        text = text.replace(f'"{name}"', f'"{kit.root / name}"')
    scene.write_text(text)
    counts = ["1", "2", "3"] if workers_supported() else ["1"]
    data = {}
    for processes in counts:
        out = tmp_path / f"b{processes}.h5"
        # --workers 1: frames in this process, each shared by `processes` processes
        code, stdout, err = _run("bake", scene, "-o", out, "--processes", processes,
                                 "--workers", "1", "--json")
        assert code == 0, err
        assert json.loads(stdout)["processes"] == int(processes)  # the count is reported
        data[processes] = out.read_bytes()
    assert all(d == data["1"] for d in data.values())  # the whole file, byte for byte


# ----------------------------------------------------------------- clean stderr
@pytest.mark.parametrize("argv_name", ["trunc-hdr", "huge-translate"])
def test_no_library_noise_on_stderr(argv_name, kit, tmp_path):
    """OpenCV's C++ log lines and NumPy RuntimeWarnings never reach the user's stderr."""
    if argv_name == "trunc-hdr":
        argv = ["light", "project", kit.root / "trunc.hdr", "-n", "2", "-o", tmp_path / "l.h5"]
    else:
        scene = tmp_path / "far.toml"
        text = SCENE.format(frames=1, subdivisions=4).replace(
            "translate = [0, 1, 0]", "translate = [0, 1e308, 0]")
        for name in ("mesh.obj", "spheres.h5", "light.h5"):
            text = text.replace(f'"{name}"', f'"{kit.root / name}"')
        scene.write_text(text)
        argv = ["bake", scene, "-o", tmp_path / "b.h5", "--processes", "1"]
    done = _shtools(*argv)
    check_refused(done.returncode, done.stdout, done.stderr, want_code=1, named=[],
                  outputs=[argv[-1] if argv_name == "trunc-hdr" else argv[-3]], kit=kit,
                  folders=[tmp_path])
