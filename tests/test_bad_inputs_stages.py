"""The bad-input promise for the later stages: every written file, every size, every value.

Same promises and helpers as ``tests/test_bad_inputs.py`` (one line naming the
file or option, exit status not 0 or 3, nothing written, no input changed):

* every file a command writes -- a VAT's ``.glb``/``.pos.exr``, a numbered
  ``NAME.0000.glb`` sequence, a preview -- is checked against the inputs and for
  writability before any work (``shtools.cli._outputs``);
* every request is costed from its options and refused past its limit with
  its size and ``--force`` (``shtools.cli._limits``);
* ``--scheduler`` is checked while the options are parsed;
* scene values have strict types, and a scene error names the scene file.

Read-only files are tested as the unprivileged user ``nobody`` (root may write
any file): those cases need ``setpriv`` and run as root, else they skip saying so.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from helpers.processes import unprivileged_prefix
from test_bad_inputs import SCENE, Kit, _sha, check_refused

from shtools.cli.main import main

TESTS = Path(__file__).resolve().parent



#: A receiver that moves: its VAT export has a positions texture NAME.pos.exr.
MOVING_SCENE = """
[settings]
order = 2
frames = 2

[environment]
light = "light.h5"

[[objects]]
name = "ground"
primitive = { type = "plane", size = [2, 2], subdivisions = 2 }
role = "receiver"
keyframes = [{ frame = 0, translate = [0, 0, 0] }, { frame = 1, translate = [0, 0.5, 0] }]
"""

LAMP = """
[[lights]]
name = "lamp"
position = [0.3, 2.5, 0.2]
radius = 0.1
color = [1, 1, 1]
shadows = "ssoc"
ssoc = { resolution = 64, filter = FILTER }
"""


def _run(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


class StageKit(Kit):
    """The bad-input kit plus a moving bake, a .glb mesh and a small shadow field."""

    def __init__(self, root: Path):
        import trimesh

        super().__init__(root)
        k = root
        (k / "moving.toml").write_text(MOVING_SCENE)
        trimesh.load(k / "mesh.obj").export(k / "mesh.glb")
        trimesh.creation.icosphere(subdivisions=6).export(k / "sphere.obj")  # 40962 vertices
        for args in (("bake", k / "moving.toml", "-o", k / "moving.h5", "--processes", 1,
                      "--workers", 1),
                     ("field", "sample", k / "mesh.obj", "-o", k / "mesh.field.h5",
                      "--order", 2, "--shells", 2, "--resolution", 4, "--min-resolution", 2,
                      "--map", 8,
                      "--no-self-visibility", "--workers", 1)):
            code, _, err = _run(*args)
            assert code == 0, (args, err)
        # inputs named like the outputs a command derives from its -o
        for name, src in (("v.glb", "baked.h5"), ("s.0000.glb", "baked.h5"),
                          ("s.0001.ply", "baked.h5"), ("m.pos.exr", "moving.h5"),
                          ("sp.png", "spheres.h5"), ("field.png", "mesh.field.h5")):
            shutil.copyfile(k / src, k / name)
        for name, text in (("garbage.json", "garbage{"), ("empty.json", ""),
                           ("list.json", "[1, 2]"), ("number.json", '{"address": 5}'),
                           ("no_address.json", '{"id": "x"}'),
                           ("udp.json", '{"address": "udp://127.0.0.1:1"}')):
            (k / name).write_text(text)
        self.hashes = {p: _sha(p) for p in k.iterdir() if p.is_file()}


@pytest.fixture(scope="module")
def kit(tmp_path_factory):
    return StageKit(tmp_path_factory.mktemp("stagekit"))


def _fill(argv, kit, out):
    return [a.replace("{k}", str(kit.root)).replace("{o}", str(out)) for a in argv]


# ------------------------------------------------------------------------- the matrix
SCHEDULERS = ["{k}/garbage.json", "{k}/empty.json", "{k}/list.json", "{k}/number.json",
              "{k}/no_address.json", "{k}/udp.json", "{k}/scene.toml", "udp://127.0.0.1:1",
              "tcp://", "tcp://127.0.0.1:abc", "tcp://127.0.0.1:0", "tcp://:8786", ""]
SCHEDULED = {
    "bake": ["bake", "{k}/scene.toml", "-o", "{o}/b.h5"],
    "field": ["field", "sample", "{k}/mesh.obj", "-o", "{o}/f.h5", "--shells", "2",
              "--resolution", "4", "--min-resolution", "2", "--map", "4"],
    "fit": ["spheres", "fit", "{k}/mesh.obj", "{k}/latin1.obj", "-n", "2", "-o", "{o}"],
}

#: (id, argv, exit code, texts the line must contain); outputs are the {o}/... paths.
CASES = [
    # --- every file written is checked against the inputs
    ("vat-glb-is-input", ["export", "{k}/v.glb", "-o", "{k}/v.exr"], 1,
     ["v.glb", "also an input"]),
    ("vat-pos-is-input", ["export", "{k}/m.pos.exr", "-o", "{k}/m.exr"], 1,
     ["m.pos.exr", "also an input"]),
    ("sequence-glb-is-input", ["export", "{k}/s.0000.glb", "--frames", "0:2", "--sequence",
                               "-o", "{k}/s.glb"], 1, ["s.0000.glb", "also an input"]),
    ("sequence-ply-is-input", ["export", "{k}/s.0001.ply", "--frames", "0:2", "-o",
                               "{k}/s.ply"], 1, ["s.0001.ply", "also an input"]),
    ("preview-over-mesh", ["spheres", "preview", "{k}/mesh.glb", "{k}/spheres.h5", "-o",
                           "{k}/mesh.glb"], 1, ["mesh.glb", "also an input"]),
    ("preview-over-spheres", ["spheres", "preview", "{k}/mesh.obj", "{k}/sp.png", "-o",
                              "{k}/sp.png"], 1, ["sp.png", "also an input"]),
    # --- values: finite, in range
    ("preview-elevation-nan", ["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o",
                               "{o}/p.png", "--elevation", "nan"], 2, ["--elevation"]),
    ("preview-azimuth-inf", ["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o",
                             "{o}/p.png", "--azimuth", "inf"], 2, ["--azimuth"]),
    ("transfer-floor-nan", ["transfer", "{k}/mesh.obj", "-o", "{o}/t.h5", "--floor", "nan"], 2,
     ["--floor"]),
    ("transfer-floor-negative", ["transfer", "{k}/mesh.obj", "-o", "{o}/t.h5", "--floor",
                                 "-0.1"], 2, ["--floor"]),
    ("field-seed-negative", ["field", "sample", "{k}/mesh.obj", "-o", "{o}/f.h5", "--seed",
                             "-1"], 2, ["--seed"]),
    ("eval-png-is-field", ["eval", "--mesh", "{k}/mesh.obj", "--field", "{k}/field.png", "--png",
                           "{k}/field.png"], 1, ["field.png", "also an input"]),
    ("eval-methods-typo", ["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/spheres.h5",
                           "--methods", "zz"], 2, ["--methods", "zz"]),
    ("eval-methods-order", ["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/spheres.h5",
                            "--methods", "auto@99"], 2, ["--methods", "auto@99"]),
    ("plot-not-png", ["tables", "log", "-n", "2", "-o", "{o}/t.h5", "--plot", "{o}/p.txt"], 1,
     ["p.txt", "--plot", ".png"]),
    *[(f"empty-input-{'-'.join(argv[:2])}", argv, 2, ["is empty"]) for argv in (
        ["transfer", "", "-o", "{o}/t.h5"], ["spheres", "fit", "", "-n", "2", "-o", "{o}/s.h5"],
        ["bake", "", "-o", "{o}/b.h5"], ["light", "project", "", "-n", "2", "-o", "{o}/l.h5"],
        ["export", "", "-o", "{o}/x.png"], ["info", ""],
        ["spheres", "preview", "{k}/mesh.obj", "", "-o", "{o}/p.png"],
        ["eval", "--mesh", "", "--spheres", "{k}/spheres.h5"])],
    # --- sizes: refused with the size and the way out
    ("field-resolution-huge", ["field", "sample", "{k}/mesh.obj", "-o", "{o}/f.h5", "--shells",
                               "1", "--resolution", "1048576", "--map", "4"], 2,
     ["--resolution", "4096"]),  # past the option's bound, before any size is planned
    ("field-all-huge", ["field", "sample", "{k}/mesh.obj", "-o", "{o}/f.h5", "--shells", "256",
                        "--resolution", "4096", "--map", "1024"], 1,
     ["mesh.obj", "GiB", "--force"]),
    ("field-rays-huge", ["field", "sample", "{k}/mesh.obj", "-o", "{o}/f.h5", "--shells", "256",
                         "--resolution", "64", "--map", "256", "--order", "1", "--workers",
                         "1"], 1, ["mesh.obj", "rays", "--force"]),
    ("preview-size-huge", ["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o",
                           "{o}/p.png", "--size", "100000", "100000"], 2,
     ["--size", "10,000,000,000 pixels", "GiB"]),
    ("preview-pixels", ["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o",
                        "{o}/p.png", "--size", "16384", "16384"], 2, ["--size", "pixels"]),
    ("preview-thin", ["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o",
                      "{o}/p.png", "--size", "8", "100000000"], 2, ["--size", "pixels"]),
    ("transfer-n-dirs-huge", ["transfer", "{k}/mesh.obj", "-o", "{o}/t.h5", "--n-dirs",
                              "1000000000"], 2, ["--n-dirs"]),
    ("transfer-rays", ["transfer", "{k}/sphere.obj", "-o", "{o}/t.h5", "--n-dirs", "1000000"],
     1, ["sphere.obj", "rays", "--force"]),
    ("scaling-samples", ["tables", "scaling", "-n", "16", "--function", "cone", "--samples",
                         "10000", "-o", "{o}/s.h5"], 1, ["s.h5", "GiB", "--force"]),
    ("scaling-nodes", ["tables", "scaling", "-n", "8", "--function", "midrange", "--nodes",
                       "100000", "-o", "{o}/s.h5"], 1, ["s.h5", "GiB", "--force"]),
    ("eval-references", ["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/spheres.h5",
                         "--grid", "1024", "--n-dirs", "100000"], 1,
     ["mesh.obj", "GiB", "--force"]),
    # --- schedulers: checked while parsing, before anything starts
    *[(f"scheduler-{cmd}-{i}", [*argv, "--scheduler", value], 2, ["--scheduler"])
      for cmd, argv in SCHEDULED.items() for i, value in enumerate(SCHEDULERS)],
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_stage_refuses_bad_input(case, kit, tmp_path):
    _, argv, want_code, named = case
    argv = _fill(argv, kit, tmp_path)
    outputs = [a for a in argv if a.startswith(str(tmp_path)) and a != str(tmp_path)]
    outputs += [tmp_path / "latin1.spheres.h5", tmp_path / "mesh.spheres.h5"]
    # the outputs a command would derive from -o (companions) must not appear either
    outputs += [kit.root / n for n in ("m.exr", "m.glb", "s.glb", "s.0001.glb", "s.ply",
                                       "s.0000.ply", "v.exr")]
    code, out, err = _run(*argv)
    check_refused(code, out, err, want_code=want_code, named=named, outputs=outputs, kit=kit,
                  folders=[tmp_path])


def test_scheduler_file_with_an_address_is_accepted_up_to_the_connection(kit, tmp_path):
    """A well-formed file passes the parse-time check; the refused connection is its own
    one line (exit 1), the scheduler file named."""
    pytest.importorskip("distributed")
    sched = tmp_path / "sched.json"
    sched.write_text(json.dumps({"address": "tcp://127.0.0.1:1"}))
    code, out, err = _run("field", "sample", kit.root / "mesh.obj", "-o", tmp_path / "f.h5",
                          "--shells", "2", "--resolution", "4", "--min-resolution", "2",
                          "--map", "4", "--scheduler", sched)
    check_refused(code, out, err, want_code=1, named=["sched.json", "cannot reach"],
                  outputs=[tmp_path / "f.h5"], kit=kit, folders=[tmp_path])


def test_force_passes_the_limit(kit, tmp_path, monkeypatch):
    """The limit is the only thing in the way: with --force the same request runs (a
    scaling table over the memory limit, lowered here so the run stays small)."""
    import shtools.cli._limits as limits

    out = tmp_path / "s.h5"
    argv = ["tables", "scaling", "-n", "2", "--function", "cone", "--samples", "4", "-o", out]
    monkeypatch.setattr(limits, "MEMORY_LIMIT", 1024)
    code, stdout, err = _run(*argv)
    check_refused(code, stdout, err, want_code=1, named=["s.h5", "--force"],
                  outputs=[out], kit=kit, folders=[tmp_path])
    code, _, err = _run(*argv, "--force")
    assert code == 0, err
    assert out.is_file()


# ------------------------------------------------------------------- companions, as nobody


@pytest.fixture
def open_folder(kit):
    """A folder any user may use (pytest's are private to their owner): ``in`` holds
    copies of the kit files the cases read, ``out`` is writable by all."""
    folder = Path(tempfile.mkdtemp(prefix="shtools-ro-"))
    try:
        folder.chmod(0o755)
        (folder / "in").mkdir(mode=0o755)
        for name in ("baked.h5", "moving.h5", "mesh.obj", "latin1.obj", "spheres.h5"):
            shutil.copyfile(kit.root / name, folder / "in" / name)
            (folder / "in" / name).chmod(0o644)
        (folder / "out").mkdir()
        (folder / "out").chmod(0o777)
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.mark.parametrize("argv, target", [
    (["export", "{k}/baked.h5", "-o", "{o}/out.exr"], "out.glb"),
    (["export", "{k}/baked.h5", "--frames", "0:2", "--sequence", "-o", "{o}/s.glb"],
     "s.0000.glb"),
    (["export", "{k}/baked.h5", "--frames", "0:2", "-o", "{o}/s.ply"], "s.0001.ply"),
    (["export", "{k}/moving.h5", "-o", "{o}/m.exr"], "m.pos.exr"),
    (["export", "{k}/baked.h5", "-o", "{o}/x.png"], "x.png"),
    (["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o", "{o}/p.png"], "p.png"),
    (["spheres", "fit", "{k}/mesh.obj", "{k}/latin1.obj", "-n", "2", "--method", "kmeans", "-o",
      "{o}"], "latin1.spheres.h5"),
    (["eval", "--mesh", "{k}/mesh.obj", "--spheres", "{k}/spheres.h5", "--grid", "4",
      "--n-dirs", "16", "--methods", "auto", "--png", "{o}/e.png"], "e.png"),
], ids=["vat-glb", "sequence-glb", "sequence-ply", "vat-pos", "png", "preview", "fit-batch",
        "eval-png"])
def test_read_only_companions_are_refused(argv, target, open_folder):
    prefix = unprivileged_prefix()
    out = open_folder / "out"
    ro = out / target
    ro.write_bytes(b"keep me")
    ro.chmod(0o444)
    argv = [a.replace("{k}", str(open_folder / "in")).replace("{o}", str(out)) for a in argv]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", HOME=str(out), MPLCONFIGDIR=str(out))
    done = subprocess.run([*prefix, sys.executable, "-m", "shtools", *argv],
                          capture_output=True, text=True, env=env, timeout=300, cwd=out)
    lines = done.stderr.strip().splitlines()
    assert done.returncode in (1, 2), done.stderr
    assert len(lines) == 1 and target in lines[0], done.stderr
    assert "read-only" in lines[0] or "not writable" in lines[0], lines[0]
    assert ro.read_bytes() == b"keep me"
    assert sorted(p.name for p in out.iterdir()) == [target]


# --------------------------------------------------------------------------- export --rig
def test_rig_is_checked_by_content_not_by_name(kit, tmp_path):
    """A modified rig under another name is refused; the baked rig under another name is
    the baked rig."""
    from helpers.rig import write_bending_tube

    write_bending_tube(tmp_path / "tube.glb")
    (tmp_path / "scene.toml").write_text(
        '[settings]\norder = 2\nframes = 1\n\n[environment]\ncoeffs = [[3.5, 3.5, 3.5], '
        '[0, 0, 0], [1, 1, 1], [0, 0, 0]]\n\n[[objects]]\nname = "tube"\nmesh = "tube.glb"\n'
        'role = "receiver"\nskin = { animation = 0 }\n')
    code, _, err = _run("bake", tmp_path / "scene.toml", "-o", tmp_path / "b.h5",
                        "--processes", 1, "--workers", 1)
    assert code == 0, err
    # the same mesh bent further: same vertex count, other bytes
    write_bending_tube(tmp_path / "tube_modified.glb", bend_degrees=45.0)
    assert _sha(tmp_path / "tube_modified.glb") != _sha(tmp_path / "tube.glb")
    out = tmp_path / "lit.glb"
    code, stdout, err = _run("export", tmp_path / "b.h5", "--frame", 0, "--rig",
                             f"tube={tmp_path / 'tube_modified.glb'}", "-o", out)
    check_refused(code, stdout, err, want_code=1, named=["tube_modified.glb", "sha256"],
                  outputs=[out], kit=kit, folders=[tmp_path])
    shutil.copyfile(tmp_path / "tube.glb", tmp_path / "renamed.glb")
    code, _, err = _run("export", tmp_path / "b.h5", "--frame", 0, "--rig",
                        f"tube={tmp_path / 'renamed.glb'}", "-o", out)
    assert code == 0, err
    assert out.is_file()


# ---------------------------------------------------------------------------- scenes
@pytest.mark.parametrize("value", ['"yes"', '"no"', "1", "0", '"true"'])
def test_ssoc_filter_must_be_a_bool(value, kit, tmp_path):
    scene = tmp_path / "lamp.toml"
    text = SCENE.format(frames=1, subdivisions=2) + LAMP.replace("FILTER", value)
    for name in ("mesh.obj", "spheres.h5", "light.h5"):
        text = text.replace(f'"{name}"', f'"{kit.root / name}"')
    scene.write_text(text)
    out = tmp_path / "b.h5"
    code, stdout, err = _run("bake", scene, "-o", out, "--processes", 1, "--workers", 1)
    check_refused(code, stdout, err, want_code=1,
                  named=["lamp.toml", "lights[0].ssoc.filter", "true or false"], outputs=[out],
                  kit=kit, folders=[tmp_path])


@pytest.mark.parametrize("old, new, named", [
    ("radius = 0.1", "radius = 1e308", "lights[0].radius"),
    ("radius = 0.1", "radius = inf", "lights[0].radius"),
    ("position = [0.3, 2.5, 0.2]", "position = [1e308, 2.5, 0.2]", "lights[0].position"),
    ("color = [1, 1, 1]", "color = [1e308, 1, 1]", "lights[0].color"),
    ('name = "lamp"', 'name = "lamp"\nintensity = 1e300', "lights[0].intensity"),
])
def test_light_values_are_bounded(old, new, named, kit, tmp_path):
    """Finite but huge light values overflowed the float32 runtime (an internal error, or
    a bake refused as 'NaN radiance' naming the output): refused at parse time."""
    scene = tmp_path / "lamp.toml"
    text = SCENE.format(frames=1, subdivisions=2) + LAMP.replace("FILTER", "true")
    for name in ("mesh.obj", "spheres.h5", "light.h5"):
        text = text.replace(f'"{name}"', f'"{kit.root / name}"')
    assert old in text
    scene.write_text(text.replace(old, new, 1))
    out = tmp_path / "b.h5"
    code, stdout, err = _run("bake", scene, "-o", out, "--processes", 1, "--workers", 1)
    check_refused(code, stdout, err, want_code=1, named=["lamp.toml", named], outputs=[out],
                  kit=kit, folders=[tmp_path])


def test_ssoc_table_lists_the_ssoc_keys():
    """The schema's table and the library's key list are the same keys."""
    from shtools.scene.light_shadows import SSOC_KEYS
    from shtools.scene.schema import SSOCTable

    assert set(SSOCTable.model_fields) == set(SSOC_KEYS)


def test_pose_error_names_the_scene(kit, tmp_path):
    """A shadow field under a parent's non-uniform scale is found while posing, deep in
    the runtime: the line still names the scene file."""
    scene = tmp_path / "stretched.toml"
    text = SCENE.format(frames=1, subdivisions=2).replace(
        'blocker = { spheres = "spheres.h5" }',
        f'blocker = {{ field = "{kit.root / "mesh.field.h5"}" }}\nparent = "ball"').replace(
        "center = [1, 1, 0] }", "center = [1, 1, 0] }\nscale = [1, 2, 1]")
    for name in ("mesh.obj", "light.h5"):
        text = text.replace(f'"{name}"', f'"{kit.root / name}"')
    scene.write_text(text)
    out = tmp_path / "b.h5"
    for argv in (["bake", scene, "-o", out, "--processes", 1, "--workers", 1],
                 ["eval", scene, "--n-dirs", 16, "--methods", "auto"]):
        code, stdout, err = _run(*argv)
        check_refused(code, stdout, err, want_code=1,
                      named=["stretched.toml", "'block'", "rigid pose"], outputs=[out], kit=kit,
                      folders=[tmp_path])


def test_defaults_are_within_the_limits():
    """The limits refuse huge requests, never the defaults: a default field sample and a
    default order-16 scaling table plan well below the memory limit."""
    from shtools.cli._limits import MEMORY_LIMIT, RAY_LIMIT
    from shtools.fields.build import FieldParameters, planned_cost

    cost = planned_cost(FieldParameters(), workers=64)
    assert cost["bytes"] < MEMORY_LIMIT / 2 and cost["rays"] < RAY_LIMIT / 10
    # the estimate counts the float64 samples of every shell: a lower bound by construction
    p = FieldParameters(shells=3, resolution=8, map_size=4, order=2)
    assert planned_cost(p)["bytes"] >= np.empty((3, 8, 8, 4)).nbytes


def test_out_of_memory_is_one_line(kit, tmp_path, monkeypatch):
    """Past the limits with --force, a MemoryError is one line naming the command (exit 1),
    not an internal error."""
    import shtools.sh.scaling as scaling

    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(scaling, "build_scaling_table", exhausted)
    out = tmp_path / "s.h5"
    code, stdout, err = _run("tables", "scaling", "-n", "2", "--function", "cone", "-o", out,
                             "--force")
    check_refused(code, stdout, err, want_code=1,
                  named=["out of memory", "tables scaling", "--force"], outputs=[out], kit=kit,
                  folders=[tmp_path])


@pytest.mark.parametrize("argv", [
    ["tables", "log", "-n", "2", "-o", "{o}/t.h5"],
    ["spheres", "fit", "{k}/mesh.obj", "-n", "2", "-o", "{o}/s.h5"],
    ["export", "{k}/baked.h5", "-o", "{o}/x.exr"],
    ["spheres", "preview", "{k}/mesh.obj", "{k}/spheres.h5", "-o", "{o}/p.png"],
], ids=["tables", "fit", "vat", "preview"])
def test_read_only_folder_is_refused_as_nobody(argv, open_folder):
    """A folder this user may not write is refused before any work (root may write any
    folder, so this runs as ``nobody``)."""
    prefix = unprivileged_prefix()
    out = open_folder / "out"
    out.chmod(0o555)
    argv = [a.replace("{k}", str(open_folder / "in")).replace("{o}", str(out)) for a in argv]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", HOME=str(open_folder),
               MPLCONFIGDIR=str(open_folder))
    done = subprocess.run([*prefix, sys.executable, "-m", "shtools", *argv],
                          capture_output=True, text=True, env=env, timeout=300,
                          cwd=open_folder)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1, done.stderr
    assert len(lines) == 1 and "cannot write to the output folder" in lines[0], done.stderr
    assert list(out.iterdir()) == []


def test_field_self_visibility_rays_are_costed(kit, tmp_path, monkeypatch):
    """The stored O_v casts every vertex's rays too (at most the first pass and the whole
    dense hemisphere set each): counted against the ray limit (lowered so the 8-vertex
    box's 8 x 1856 rays exceed it), with --no-self-visibility as a way out."""
    import shtools.cli._limits as limits
    from shtools.geometry.transfer import FIRST_DIRECTIONS, TRANSFER_DIRECTIONS

    per_vertex = FIRST_DIRECTIONS + TRANSFER_DIRECTIONS
    assert 8 * per_vertex > 10_000  # the lowered limit below

    monkeypatch.setattr(limits, "RAY_LIMIT", 10_000)
    out = tmp_path / "f.h5"
    argv = ["field", "sample", kit.root / "mesh.obj", "-o", out, "--shells", 2, "--resolution",
            4, "--min-resolution", 2, "--map", 4, "--order", 2, "--workers", 1]
    code, stdout, err = _run(*argv)
    check_refused(code, stdout, err, want_code=1,
                  named=["mesh.obj", "self-visibility", f"8 vertices x {per_vertex}",
                         "--force"],
                  outputs=[out], kit=kit, folders=[tmp_path])
    code, _, err = _run(*argv, "--no-self-visibility")
    assert code == 0, err
