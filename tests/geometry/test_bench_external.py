"""bench_spheres --external: another fitter's spheres scored like ours.

The external "fitter" here is a tiny script that writes one sphere about the centre
of a unit icosphere; its outside volume has a closed form (a ball that holds the
polyhedron minus the polyhedron's exact volume), which the benchmark's evaluators
must reproduce.
"""

from __future__ import annotations

import sys
import tempfile
import textwrap
from unittest import mock

import numpy as np
import pytest
import trimesh

from benchmarks import bench_spheres

WRITER = textwrap.dedent("""
    import json, sys
    mesh, n, out, radius = sys.argv[1:5]
    assert open(mesh, "rb").read(3) == b"ply", "the mesh is handed over as PLY"
    if out.endswith(".sph"):  # spheretree layout: root, then level 1 with N spheres
        open(out, "w").write(f"2 1\\n0 0 0 {radius} 0\\n0 0 0 {radius} 0\\n")
    else:
        json.dump({"centers": [[0.0, 0.0, 0.0]] * int(n), "radii": [float(radius)] * int(n),
                   "cpu": 0.25, "wall": 0.5}, open(out, "w"))
""")


@pytest.fixture(autouse=True)
def _fewer_monte_carlo_points(monkeypatch):
    # 100k box points for V(T) and 20k per ball: ~0.3 % and ~0.8 % relative noise on E
    monkeypatch.setattr(bench_spheres, "MC_VOLUME", 100_000)
    monkeypatch.setattr(bench_spheres, "MC_PER_SPHERE", 20_000)


@pytest.fixture(scope="module")
def icosphere():
    # vertices on the unit sphere, so the ball of radius 1 about the origin is the
    # smallest one about it that holds the whole surface
    return trimesh.creation.icosphere(subdivisions=2)


def _run(tmp_path, mesh, radius, out="{out}", n=1):
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    name, argv = bench_spheres.parse_external(
        f"ext={sys.executable} {script} {{mesh}} {{n}} {out} {radius}")
    scratch = tmp_path / "scratch"  # the run's temporary files go here, and must go away
    scratch.mkdir(exist_ok=True)  # (a test may run several)
    with mock.patch.object(tempfile, "tempdir", str(scratch)):
        rows = bench_spheres.run({"ico": (None, mesh)}, [n], methods=(),
                                 externals={name: argv}, log=lambda *a, **k: None)
    assert list(scratch.iterdir()) == []
    assert [r["method"] for r in rows] == ["ext"]
    return rows[0]


def _ratio(mesh, radius):
    """Closed-form E of a ball about the origin that holds the whole polyhedron."""
    return (4.0 / 3.0 * np.pi * radius**3 - mesh.volume) / mesh.volume


def test_bounding_ball_scores_its_closed_form(tmp_path, icosphere):
    row = _run(tmp_path, icosphere, 1.2)
    expected = _ratio(icosphere, 1.2)
    # flux E: quadrature of the ball's surface, accurate to well below 1 %
    assert row["E"] == pytest.approx(expected, rel=1e-2)
    # Monte Carlo E: ~0.9 % relative noise with the points above; 3 sigma
    assert row["E_mc"] == pytest.approx(expected, rel=3e-2)
    assert row["coverage"] == 1.0
    assert row["spheres"] == 1 and row["distinct"] == 1
    # already bounding: growing it changes nothing beyond the evaluator's accuracy
    assert row["E_bounding"] == pytest.approx(expected, rel=1e-2)
    # the program's own timings are reported, not the process's
    assert (row["cpu"], row["wall"]) == (0.25, 0.5)


def test_inner_ball_is_grown_to_hold_the_surface(tmp_path, icosphere):
    row = _run(tmp_path, icosphere, 0.5)
    assert row["E"] == pytest.approx(0.0, abs=1e-3)  # wholly inside: nothing outside
    assert row["coverage"] == 0.0
    # made bounding: at least the unit ball (every vertex lies on it); the cover grows
    # by whole steps, so allow up to 5 % more radius than the exact minimum
    assert _ratio(icosphere, 1.0) * (1 - 1e-2) <= row["E_bounding"] <= _ratio(icosphere, 1.05)


def test_sph_output_and_duplicates_counted(tmp_path, icosphere):
    row = _run(tmp_path, icosphere, 1.2, out="{out}.sph")
    assert row["E"] == pytest.approx(_ratio(icosphere, 1.2), rel=1e-2)
    assert row["cpu"] >= 0.0  # no timings in .sph: the process was timed
    row = _run(tmp_path, icosphere, 1.2, n=3)  # three copies of one ball
    assert row["spheres"] == 3 and row["distinct"] == 1


def test_bad_specs_and_failures_are_one_line_errors(tmp_path, icosphere):
    for spec in ("no-equals-sign", "=python x.py {out}", "name=python x.py"):
        with pytest.raises(SystemExit, match="expected NAME=COMMAND"):
            bench_spheres.parse_external(spec)
    argv = [sys.executable, "-c", "import sys; sys.exit('boom')", "{out}"]
    with pytest.raises(SystemExit, match=r"external fitter failed .*boom"):
        bench_spheres.run({"ico": (None, icosphere)}, [1], methods=(), externals={"x": argv},
                          log=lambda *a, **k: None)
