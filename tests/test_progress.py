"""Progress in logs: long stages print count/total, elapsed and ETA lines on a non-TTY stderr.

The stages run as real subprocesses with stderr captured through a pipe (not a
terminal), as in a Makefile or CI log.  ``SHTOOLS_PROGRESS_INTERVAL=0`` makes
every update a line, so the test does not need a 10-second stage.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import trimesh

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "tests" / "golden"

#: ``desc: n/total unit (p%), MM:SS elapsed, ETA MM:SS[, postfix]``
LINE = re.compile(r"^(?P<desc>[\w -/]+): (?P<n>\d+)/(?P<total>\d+) (?P<unit>\w+) "
                  r"\((?P<pct>\d+)%\), \d\d:\d\d elapsed, ETA (\d\d:\d\d|\?)")


def _run(args, tmp_path, interval="0", quiet=False):
    env = dict(os.environ, SHTOOLS_PROGRESS_INTERVAL=interval)
    env.pop("SHTOOLS_QUIET", None)
    cmd = [sys.executable, "-m", "shtools", *(["--quiet"] if quiet else []), *map(str, args)]
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc.stderr.splitlines()


def _parsed(lines, desc):
    return [m.groupdict() for line in lines if (m := LINE.match(line)) and m["desc"] == desc]


def test_fit_and_tree_log_progress_with_total_and_eta(tmp_path):
    mesh = trimesh.creation.torus(1.0, 0.35, major_sections=24, minor_sections=12)
    mesh.export(tmp_path / "torus.obj")
    lines = _run(["spheres", "fit", "torus.obj", "-n", 6, "--iterations", 6, "-o", "s.h5"],
                 tmp_path)
    fit = _parsed(lines, "fit")
    assert fit, lines
    # the total is the round budget (--iterations) and the count never exceeds it
    assert {f["total"] for f in fit} == {"6"}
    assert all(int(f["n"]) <= 6 and f["unit"] == "rounds" for f in fit)
    counts = [int(f["n"]) for f in fit]
    assert counts == sorted(counts) and counts[-1] > 0
    # the search's objective, labelled so: not the E of the final line (another quantity)
    rounds = [line for line in lines if LINE.match(line) and int(LINE.match(line)["n"]) > 0]
    assert rounds and all("objective=" in line and "E=" not in line for line in rounds)

    lines = _run(["spheres", "tree", "s.h5", "--branching", 2, "-o", "t.h5"], tmp_path)
    tree = _parsed(lines, "tree")
    # 6 leaves at branching 2: levels of 6, 3, 2 spheres are clustered
    assert tree and tree[-1]["n"] == tree[-1]["total"] == "11", lines


def test_bake_logs_setup_and_frames_and_quiet_silences(tmp_path):
    for name in ("scene.toml", "post_spheres.h5"):
        shutil.copy(GOLDEN / name, tmp_path / name)
    lines = _run(["bake", "scene.toml", "-o", "b.h5", "--processes", 1], tmp_path)
    setup, frames = _parsed(lines, "bake set-up"), _parsed(lines, "bake")
    # three objects, the environment, the tables
    assert setup and setup[-1]["n"] == setup[-1]["total"] == "5", lines
    assert frames and frames[-1]["n"] == frames[-1]["total"] == "4", lines
    assert frames[-1]["pct"] == "100" and frames[-1]["unit"] == "frames"

    lines = _run(["export", "b.h5", "--frames", "0:4", "-o", "sheet.png", "--size", 32, 24],
                 tmp_path)
    render = _parsed(lines, "render")
    assert render and render[-1]["n"] == render[-1]["total"] == "4", lines

    quiet = _run(["bake", "scene.toml", "-o", "c.h5", "--processes", 1], tmp_path, quiet=True)
    assert not any(LINE.match(line) for line in quiet), quiet


def test_short_stages_stay_silent_at_the_default_interval(tmp_path):
    """A stage shorter than the 10-second interval prints no progress line at all."""
    for name in ("scene.toml", "post_spheres.h5"):
        shutil.copy(GOLDEN / name, tmp_path / name)
    lines = _run(["bake", "scene.toml", "-o", "b.h5", "--frames", "0:1", "--processes", 1],
                 tmp_path, interval="10")
    assert not any(LINE.match(line) for line in lines), lines


def test_library_stages_run_without_tqdm():
    """`pip install 'shtools[geometry]'` has no tqdm (the cli extra's): a sphere fit with
    the library's default progress runs in a process where importing tqdm fails."""
    code = (
        "import sys\n"
        "sys.modules['tqdm'] = None  # import tqdm -> ImportError, as when not installed\n"
        "import trimesh\n"
        "from shtools.geometry.sphere_fit import fit_spheres\n"
        "fit = fit_spheres(trimesh.creation.box(extents=[1, .5, .5]), 2, max_iterations=2)\n"
        "assert 'tqdm' not in sys.modules or sys.modules['tqdm'] is None\n"
        "print(len(fit.radii))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, OPENBLAS_NUM_THREADS="1"))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["2"]


def test_silent_progress_counts_like_tqdm():
    from shtools.progress import silent

    with silent(range(3), desc="x") as bar:
        assert list(bar) == [0, 1, 2] and bar.n == 3 and bar.total == 3
    bar = silent(total=5)
    bar.update(2)
    bar.set_postfix(E=1.0)
    bar.update(min(4, bar.total) - bar.n)  # the sphere fit's idiom
    assert bar.n == 4
    bar.close()


def test_deferred_progress_shows_only_stages_longer_than_its_delay():
    """A stage shorter than the delay never makes the real bar; a longer one makes it at
    the first update past the delay, with the count, total and postfix so far, and
    forwards the rest."""
    from shtools.progress import Deferred

    made = []

    class Bar:
        def __init__(self, **kwargs):
            self.kwargs, self.n, self.postfix, self.closed = kwargs, 0, None, False
            made.append(self)

        def update(self, n=1):
            self.n += n

        def set_postfix(self, *args, **kwargs):
            self.postfix = kwargs

        def close(self):
            self.closed = True

        def __exit__(self, *exc):
            self.close()
            return False

    now = [0.0]
    clock = lambda: now[0]  # noqa: E731  seconds of a stage, set by the test
    with Deferred(Bar, 1.0, total=10, desc="relight", unit="frames", clock=clock) as short:
        now[0] = 0.9
        short.update(10)
    assert made == [] and short.n == 10
    now[0] = 0.0
    with Deferred(Bar, 1.0, total=10, desc="relight", unit="frames", clock=clock) as long:
        now[0] = 1.0
        long.update(3)
        long.set_postfix(E=0.5)
        now[0] = 1.5
        long.update(4)
        assert len(made) == 1  # once only
        long.update(3)
    bar, = made
    assert bar.kwargs == {"total": 10, "desc": "relight", "unit": "frames"}
    assert bar.n == 10 and bar.postfix == {"E": 0.5} and bar.closed
