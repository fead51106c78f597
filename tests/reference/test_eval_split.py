"""``shtools eval``'s error split per receiver: sphere approximation, SHEXP, truncation,
ringing."""

from __future__ import annotations

import json
import math

import numpy as np
from helpers.scenes import ground, write_scene

from shtools.geometry.visibility import direction_quadrature
from shtools.reference.evaluation import _exact_environment, error_split
from shtools.runtime import ShadowSettings


def test_split_of_synthetic_radiance():
    mesh = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]])
    sph = mesh * np.array([[0.9], [1.0], [1.0], [1.1]])
    method = sph.copy()
    method[2] = [-0.1, 0.2, 0.3]
    rows = error_split(method, mesh, sph, np.array([0, 0, 1, 1]))
    assert [r["group"] for r in rows] == [0, 1] and [r["vertices"] for r in rows] == [2, 2]
    g0, g1 = rows
    # group 0: the method equals the spheres, so its whole error is the sphere approximation
    assert g0["shexp"] == 0.0 and g0["negative_vertices"] == 0 and g0["ringing"] == 0.0
    np.testing.assert_allclose(g0["total"], g0["sphere_approximation"], rtol=1e-12)
    np.testing.assert_allclose(g0["total"], math.sqrt(3 * 0.01) / math.sqrt(3 * 1 + 3 * 4))
    # group 1: one vertex with R = -0.1: the negative part relative to the reference norm
    assert g1["negative_vertices"] == 1
    np.testing.assert_allclose(g1["ringing"], 0.1 / math.sqrt(3 * 0.25 + 3 * 1.0))
    assert g1["truncation"] is None


def test_exact_integral_of_an_unshadowed_receiver_under_a_constant_sky():
    """A white Lambertian receiver that sees everything under a constant sky c reflects c
    (docs/conventions.md), whatever the normal; the quadrature integrates max(0, N.s)
    to ~1e-3 with 3000 nodes (a kink along a great circle)."""
    dirs, w = direction_quadrature(3000)
    normals = np.array([[0.0, 1.0, 0.0], [0.6, 0.0, 0.8]])
    c = np.array([1.0, 2.0, 0.5])
    env = np.zeros((16, 3))
    env[0] = c * math.sqrt(4 * math.pi)
    binary = np.ones((2, dirs.shape[0]), dtype=bool)
    got = _exact_environment(binary, dirs, w, normals, env, ShadowSettings(order=4))
    np.testing.assert_allclose(got, np.tile(c, (2, 1)), rtol=3e-3)


def test_cli_prints_the_split_per_receiver(tmp_path, run_cli):
    import trimesh

    from shtools.data_formats.spheres import write_spheres
    from shtools.geometry.sphere_set import SphereSet

    torus = trimesh.creation.torus(major_radius=0.6, minor_radius=0.25, major_sections=24,
                                   minor_sections=12)
    torus.export(tmp_path / "torus.obj")
    phi = np.linspace(0.0, 2 * math.pi, 12, endpoint=False)
    centers = 0.6 * np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
    write_spheres(tmp_path / "s.h5", SphereSet(centers, np.full(12, 0.3), 0.0, 1.0, "ring"))
    write_scene(
        tmp_path / "scene.toml", settings={"order": 3, "self_visibility": True},
        environment={"coeffs": [[5.0, 5.0, 5.0], [0.0] * 3, [3.0, 3.0, 3.0], *[[0.0] * 3] * 6]},
        objects=[ground(size=3, subdivisions=8),
                 {"name": "torus", "mesh": "torus.obj", "role": "both",
                  "blocker": {"spheres": "s.h5"}, "translate": [0.0, 0.9, 0.0],
                  "rotate": [30.0, 0.0, 0.0]}])
    code, out, err = run_cli("eval", tmp_path / "scene.toml", "--methods", "auto",
                             "--n-dirs", 600, "--json")
    assert code == 0, err
    split = {r["receiver"]: r for r in json.loads(out)["split"]}
    assert set(split) == {"ground", "torus"}
    for r in split.values():
        assert r["truncation"] is not None and r["truncation"] >= 0
    # exact self-shadowing: on the torus the method is far closer to the real mesh than
    # the sphere union it no longer uses there
    assert split["torus"]["total"] < split["torus"]["sphere_approximation"]
    code, out, err = run_cli("eval", tmp_path / "scene.toml", "--methods", "auto",
                             "--n-dirs", 300)
    assert code == 0 and "error split of auto per receiver" in out and "| torus |" in out
