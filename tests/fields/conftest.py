"""Fixtures the field tests share."""

import math

import pytest
import trimesh


@pytest.fixture(scope="module")
def standing_torus() -> trimesh.Trimesh:
    """A torus (major radius 1, minor 0.4) standing on its rim on the plane y = 0.05
    (the deformable-field tests' blocker; a fresh mesh per test module)."""
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.4, major_sections=32,
                                   minor_sections=16)
    torus.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    torus.apply_translation([0.0, 1.45, 0.0])
    return torus
