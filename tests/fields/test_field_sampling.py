"""Field sampling: the direction map, the cone cull, OCVs against closed forms and ray tracing."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.fields import FieldParameters, cone_mask, direction_map, sample_field
from shtools.fields.sampling import bounding_sphere, object_visibility, sample_ocvs, shell_radii
from shtools.geometry.raycast import RayCaster
from shtools.sh import basis, cap


def test_direction_map_weights_are_exact_solid_angles():
    dirs, w = direction_map(64)
    assert dirs.shape == (4096, 3) and w.sum() == pytest.approx(4 * math.pi, rel=1e-12)
    # projection of the constant is (sqrt(4 pi), 0, ...) up to the midpoint rule in
    # theta (phi is exact): the cell-centred map integrates z^2 with O(1/M^2) error
    y = basis(dirs, 3)
    c = w @ y
    assert c[0] == pytest.approx(math.sqrt(4 * math.pi), rel=1e-12)
    assert np.abs(c[1:]).max() < 2e-3


def test_cone_cull_casts_only_what_can_hit_and_changes_nothing():
    mesh = trimesh.creation.box(extents=(1.0, 0.4, 0.7))
    caster = RayCaster(mesh.vertices, mesh.faces)
    center, radius = bounding_sphere(mesh.vertices)
    dirs, _ = direction_map(24)
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(40, 3))
    pts *= (radius * rng.uniform(1.05, 5, 40) / np.linalg.norm(pts, axis=1))[:, None]
    pts += center
    stats = {}
    culled = object_visibility(caster, center, radius, pts, dirs, stats=stats)
    full = caster.visibility(pts, dirs)  # every ray cast
    assert np.array_equal(culled, full)  # the cull is exact, not an approximation
    assert stats["rays"] < 0.6 * pts.shape[0] * dirs.shape[0]
    # every blocked direction lies inside the cone
    assert not np.any(~full & ~cone_mask(pts, center, radius, dirs))


def test_ocv_of_a_sphere_matches_the_closed_form_cap():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    caster = RayCaster(mesh.vertices, mesh.faces)
    dirs, w = direction_map(64)
    pts = np.array([[0, 0, 1.5], [2.0, 1.0, -0.5], [0, -4.0, 0], [-1.1, 0.2, 0.1]])
    g = sample_ocvs(caster, np.zeros(3), 1.0, pts, dirs, w, 4)
    d = np.linalg.norm(pts, axis=1)
    want = cap(np.arcsin(1.0 / d), -pts / d[:, None], 4)
    # the 64 x 64 map cuts the cap's edge (binary function, midpoint cells) and the
    # icosphere is inscribed in the unit sphere: ~1e-2 per coefficient at worst
    assert np.abs(g - want).max() < 2.5e-2


def test_sample_field_on_a_small_box(tmp_path):
    mesh = trimesh.creation.box(extents=(1.0, 0.5, 0.25))
    params = FieldParameters(shells=8, resolution=16, map_size=24, order=3, min_resolution=4)
    fld, rep = sample_field(mesh, params)
    assert fld.n_shells == 8
    _center, vr = bounding_sphere(mesh.vertices)
    assert np.allclose(fld.shell_radii, shell_radii(vr, 8)) and fld.shell_radii[0] == 0.2 * vr
    assert set(fld.resolution.tolist()) <= {4, 8, 16}
    assert fld.attrs["closed"] is True
    # shells 0-4 lie inside the bounding sphere (every ray cast), 5-7 outside (culled)
    assert rep.rays < rep.rays_uncull
