"""The bad-input promise for the newer surfaces: relight, the set-up cache, lamps.

Same promises and helpers as ``tests/test_bad_inputs.py`` (one line naming the
file or option, exit status not 0 or 3, nothing written, no input changed):

* ``cache clear`` removes the cache's own files only, whatever folder
  ``--cache`` names, and refuses a folder it cannot write while the options are
  parsed; ``--cache ''`` (the current folder) is refused by every command;
* ``bake`` and ``relight --lights`` refuse an output that is ANY file the scene
  names, a field light's ``srf`` asset included;
* a lamp's emission table is bounded like a scene light's colour, and the
  memory a source radiance field plans counts its three channels.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from test_bad_inputs import Kit, _run, _sha, check_refused

LAMP_FIELD = """
[[lights]]
name = "lamp"
field = "lamp.srf.h5"
position = [0, 2, 0]
"""

SMALL_FIELD = ["--shells", "2", "--resolution", "4", "--min-resolution", "2", "--map", "4",
               "--order", "2", "--workers", "1"]


class LampKit(Kit):
    """The bad-input kit plus a lamp (bulb mesh, emission table, srf asset) and a scene
    lit by it."""

    def __init__(self, root: Path):
        import trimesh

        k = root
        trimesh.creation.icosphere(subdivisions=1, radius=0.1).export(k / "bulb.obj")
        (k / "emission.toml").write_text("radiance = [5, 4, 3]\n")
        (k / "huge_emission.toml").write_text("radiance = [1e308, 1e308, 1]\n")
        code, _, err = _run("field", "sample", k / "bulb.obj", "--radiance",
                            k / "emission.toml", *SMALL_FIELD, "-o", k / "lamp.srf.h5")
        assert code == 0, err
        from test_bad_inputs import SCENE

        (k / "lamp_scene.toml").write_text(SCENE.format(frames=2, subdivisions=2) + LAMP_FIELD)
        (k / "user" / "js").mkdir(parents=True)
        (k / "user" / "js" / "app.js").write_text("console.log(1)\n")
        (k / "user" / "ab").mkdir()
        (k / "user" / "ab" / "notes.entry").write_text("mine\n")
        super().__init__(root)  # hashes every file above too
        self.huge_bake()
        self.hashes = {p: _sha(p) for p in k.iterdir() if p.is_file()}

    def huge_bake(self) -> None:
        """``huge.h5``: a bake declaring 10^4 frames x 10^7 vertices (2.6 TiB when read)
        in a few kB of HDF5 metadata (chunks never written)."""
        import h5py

        k = self.root
        with h5py.File(k / "baked.h5", "r") as src, h5py.File(k / "huge.h5", "w") as f:
            for key, value in src.attrs.items():
                f.attrs[key] = value
            T, V = 10**4, 10**7
            for name in src:
                shape = list(src[name].shape)
                if name in ("radiance", "visibility"):
                    shape[:2] = T, V
                elif name in ("vertices", "normals"):
                    shape[-2] = V
                elif name in ("times", "frame_index"):
                    shape[0] = T
                f.create_dataset(name, shape=tuple(shape), dtype=src[name].dtype, chunks=True)


@pytest.fixture(scope="module")
def kit(tmp_path_factory):
    return LampKit(tmp_path_factory.mktemp("lampkit"))


def test_cache_clear_removes_only_cache_files(kit):
    """``--cache`` naming a folder with other files: clear must leave them (it removed
    every file of every two-letter sub-folder)."""
    user = kit.root / "user"
    code, _, err = _run("cache", "clear", "--cache", user)
    assert code == 0, err
    assert (user / "js" / "app.js").is_file()
    assert (user / "ab" / "notes.entry").is_file()
    assert kit.intact() == []


@pytest.mark.parametrize("command", [["bake", "{k}/scene.toml", "-o", "{o}/b.h5"],
                                     ["cache", "clear"], ["cache", "info"]],
                         ids=["bake", "clear", "info"])
def test_empty_cache_option_is_refused(kit, tmp_path, command):
    """``--cache ''`` named the current folder (clear then swept it)."""
    argv = [a.replace("{k}", str(kit.root)).replace("{o}", str(tmp_path)) for a in command]
    code, out, err = _run(*argv, "--cache", "")
    check_refused(code, out, err, want_code=2, named=["--cache", "empty"],
                  outputs=[tmp_path / "b.h5"], kit=kit)


def test_cache_clear_under_a_file_is_refused(kit):
    """``cache clear`` of a folder that cannot exist (under a file) is refused while the
    options are parsed (it said 'removed 0 entries', exit 0).  A bake goes on without such
    a cache, with one warning (tests/test_cache.py)."""
    code, out, err = _run("cache", "clear", "--cache", kit.root / "mesh.obj" / "cache")
    check_refused(code, out, err, want_code=2, named=["--cache", "not a folder"],
                  outputs=[], kit=kit)


def test_read_only_cache_is_refused_as_nobody(kit, tmp_path):
    """As an unprivileged user, ``cache clear`` of a read-only cache is refused naming
    --cache (it said 'removed 0 entries', exit 0, and removed nothing)."""
    import subprocess
    import sys
    import tempfile

    from helpers.processes import unprivileged_prefix

    prefix = unprivileged_prefix()
    # a folder the child can enter but not write: pytest's own tmp_path is ours only
    with tempfile.TemporaryDirectory(dir="/tmp") as top:
        Path(top).chmod(0o755)
        cache = Path(top) / "cache"
        (cache / "ab").mkdir(parents=True)
        entry = cache / "ab" / ("ab" + "0" * 62 + "-mesh.entry")
        entry.write_bytes(b"x")
        for folder in (cache / "ab", cache):
            folder.chmod(0o555)
        try:
            run = subprocess.run(
                [*prefix, sys.executable, "-m", "shtools", "cache", "clear", "--cache",
                 str(cache)], capture_output=True, text=True, timeout=60,
                env={**os.environ, "HOME": "/tmp"})
        finally:
            for folder in (cache, cache / "ab"):
                folder.chmod(0o755)
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 2, run.stderr
        assert len(lines) == 1 and "--cache" in lines[0] and "cannot write" in lines[0]
        assert entry.is_file()


def test_field_light_scene_bakes(kit, tmp_path):
    """A scene with a field light bakes (it was an internal error: a field light has no
    occlusion-camera settings to record)."""
    code, _, err = _run("bake", kit.root / "lamp_scene.toml", "-o", tmp_path / "b.h5",
                        "--workers", "1", "--processes", "1")
    assert code == 0, err
    assert (tmp_path / "b.h5").is_file()
    assert kit.intact() == []


def test_bake_output_is_the_light_field(kit):
    """``-o`` the srf asset a ``[[lights]] field`` names: refused, the asset kept."""
    code, out, err = _run("bake", kit.root / "lamp_scene.toml", "-o", kit.root / "lamp.srf.h5",
                          "--workers", "1", "--processes", "1")
    check_refused(code, out, err, want_code=1, named=["lamp.srf.h5", "also an input"],
                  outputs=[], kit=kit)


def test_relight_output_is_a_file_the_scene_names(kit):
    """``relight --lights SCENE -o`` a mesh the scene names: refused before any work."""
    code, out, err = _run("relight", kit.root / "baked.h5", "--light", kit.root / "light.h5",
                          "--lights", kit.root / "lamp_scene.toml", "-o", kit.root / "mesh.obj")
    check_refused(code, out, err, want_code=1, named=["mesh.obj", "also an input"],
                  outputs=[], kit=kit)


def test_lamp_radiance_past_the_limit_is_refused(kit, tmp_path):
    """radiance = [1e308, ...] overflowed to an all-zero field, written with exit 0."""
    code, out, err = _run("field", "sample", kit.root / "bulb.obj", "--radiance",
                          kit.root / "huge_emission.toml", *SMALL_FIELD,
                          "-o", tmp_path / "l.srf.h5")
    check_refused(code, out, err, want_code=1, named=["huge_emission.toml", "radiance", "1e+15"],
                  outputs=[tmp_path / "l.srf.h5"], kit=kit)


def test_radiance_field_memory_counts_three_channels(kit, tmp_path):
    """128 shells x 256^2 samples x 16 coefficients: 2.1 GiB as an occlusion field (under
    the 4 GiB limit), but three times the coefficients as an RGB radiance field: refused
    for its memory with its size (the estimate counted one channel)."""
    args = ["--shells", "128", "--resolution", "256", "--map", "64", "--order", "4"]
    code, out, err = _run("field", "sample", kit.root / "bulb.obj", "--radiance",
                          kit.root / "emission.toml", *args, "-o", tmp_path / "l.srf.h5")
    check_refused(code, out, err, want_code=1,
                  named=["bulb.obj", "of memory", "48 SH coefficients", "--force"],
                  outputs=[tmp_path / "l.srf.h5"], kit=kit)


@pytest.mark.parametrize("command", [
    ["relight", "{k}/huge.h5", "--light", "{k}/light.h5", "-o", "{o}/r.h5"],
    ["export", "{k}/huge.h5", "-o", "{o}/r.glb"],
    ["view", "{k}/huge.h5", "--no-browser", "--port", "1"]], ids=["relight", "export", "view"])
def test_huge_bake_is_refused_with_its_size(kit, tmp_path, command):
    """A bake too big to read is refused from its metadata with its size and --force (it
    ended in a bare 'out of memory')."""
    argv = [a.replace("{k}", str(kit.root)).replace("{o}", str(tmp_path)) for a in command]
    code, out, err = _run(*argv)
    check_refused(code, out, err, want_code=1,
                  named=["huge.h5", "GiB of memory", "limit", "--force"],
                  outputs=[tmp_path / "r.h5", tmp_path / "r.glb"], kit=kit)


def test_relight_with_a_field_light_says_so(kit, tmp_path):
    """A field light in ``relight --lights`` is named as one (the line spoke of blocker
    meshes), refused before any work."""
    code, out, err = _run("relight", kit.root / "baked.h5", "--light", kit.root / "light.h5",
                          "--lights", kit.root / "lamp_scene.toml", "-o", tmp_path / "r.h5")
    check_refused(code, out, err, want_code=1,
                  named=["lamp_scene.toml", "'lamp' is a field light", "lamp.srf.h5"],
                  outputs=[tmp_path / "r.h5"], kit=kit)


ROOM = """
[settings]
order = 2

[[objects]]
name = "room"
primitive = {{ type = "box", extents = [6.0, 6.0, 6.0], subdivisions = 1 }}
role = "receiver"

[[lights]]
name = "lamp"
field = "{srf}"
position = [0, 1, 0]
"""


def test_a_lamp_inside_a_closed_receiver_is_refused(kit, tmp_path):
    """A lamp in a closed room that receives: one line naming the scene and the room."""
    scene = tmp_path / "room.toml"
    scene.write_text(ROOM.format(srf=kit.root / "lamp.srf.h5"))
    code, out, err = _run("bake", scene, "-o", tmp_path / "b.h5", "--workers", "1",
                          "--processes", "1")
    check_refused(code, out, err, want_code=1,
                  named=["room.toml", "lights[0] ('lamp')", "inside the receiver 'room'"],
                  outputs=[tmp_path / "b.h5"], kit=kit)


def test_a_version_1_lamp_asset_is_refused_by_the_traced_shadow(kit, tmp_path):
    """An srf file of the format's first version has no lamp mesh to trace to: one line
    naming it and the way out; the product path still bakes it."""
    import h5py

    old = tmp_path / "old.srf.h5"
    old.write_bytes((kit.root / "lamp.srf.h5").read_bytes())
    with h5py.File(old, "r+") as f:
        for name in ("lamp_vertices", "lamp_faces", "lamp_emissive"):
            del f[name]
        f.attrs["format_version"] = 1
    text = (kit.root / "lamp_scene.toml").read_text().replace('field = "lamp.srf.h5"',
                                                               f'field = "{old}"')
    text = text.replace('"light.h5"', f'"{kit.root / "light.h5"}"')
    text = text.replace('"mesh.obj"', f'"{kit.root / "mesh.obj"}"')
    text = text.replace('"spheres.h5"', f'"{kit.root / "spheres.h5"}"')
    scene = tmp_path / "old.toml"
    scene.write_text(text)
    code, out, err = _run("bake", scene, "-o", tmp_path / "b.h5", "--workers", "1",
                          "--processes", "1")
    check_refused(code, out, err, want_code=1,
                  named=["old.srf.h5", "no lamp mesh", 'shadows = "shexp"'],
                  outputs=[tmp_path / "b.h5"], kit=kit)
    scene.write_text(text.replace(f'field = "{old}"', f'field = "{old}"\nshadows = "shexp"'))
    code, _, err = _run("bake", scene, "-o", tmp_path / "b.h5", "--workers", "1",
                        "--processes", "1")
    assert code == 0, err
