"""The sphere fit's fast paths give the same numbers as the straightforward
forms they replace, bit for bit (they reorder memory, not arithmetic), so the
fit's spheres do not change when they are used.  The straightforward forms are
themselves checked against closed forms and Monte Carlo in test_outside_volume.py."""

from __future__ import annotations

import numpy as np
import trimesh

from shtools.geometry.outside_volume import (
    FOUR_PI,
    FluxSamples,
    OutsideVolume,
    solid_angle,
)
from shtools.geometry.sphere_fit.cover import _unique_rows


def test_winding_number_is_the_sum_of_solid_angles(torus_mesh):
    """Winding numbers (coordinate-row form) equal Σ solid_angle / 4π exactly,
    and are 1 inside and 0 outside the torus (independent: the geometry)."""
    ov = OutsideVolume(torus_mesh)
    probes = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.3, 2.5, 0.1], [0.0, -1.0, 0.05]])
    got = ov.winding_number(probes)
    rel_probes = (probes - ov.origin) / ov.scale
    straight = np.array([np.sum(solid_angle(*(ov.triangles - p).transpose(1, 0, 2))) / FOUR_PI
                         for p in rel_probes])
    np.testing.assert_array_equal(got, straight)
    inside = np.array([torus_mesh.contains(probes[i:i + 1])[0] for i in range(len(probes))])
    # 1e-9: a closed mesh's winding number is an integer up to rounding of ~F terms
    np.testing.assert_allclose(got, inside.astype(float), atol=1e-9)


def test_batched_sample_volumes_equal_the_single_sphere_sum(torus_mesh):
    flux = FluxSamples.from_mesh(torus_mesh, max_edge=0.05, max_samples=3000)
    rng = np.random.default_rng(3)
    centers = rng.uniform(-1.5, 1.5, (9, 3))
    radii = rng.uniform(0.0, 1.2, 9)
    single = np.array([flux.intersection_volume(c, r) for c, r in zip(centers, radii,
                                                                      strict=True)])
    np.testing.assert_array_equal(flux.intersection_volume_each(centers, radii), single)


def test_unique_rows_equals_numpy_unique():
    rng = np.random.default_rng(5)
    rows = np.round(rng.normal(size=(5000, 3)), 1)  # many repeats and ties per column
    rows = np.vstack([rows, rows[::7], trimesh.creation.icosphere(1).vertices])
    np.testing.assert_array_equal(_unique_rows(rows), np.unique(rows, axis=0))
