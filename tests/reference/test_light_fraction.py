"""The ray-traced visible fraction of a spherical light against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shtools.errors import InputError
from shtools.reference.light_fraction import light_visible_fraction


def _cap_overlap(a, b, d):
    """Intersection solid angle of two caps (Tovchigrechko & Vakser 2001), partial overlap."""
    t1 = np.arccos((np.cos(d) - np.cos(a) * np.cos(b)) / (np.sin(a) * np.sin(b)))
    t2 = np.arccos((np.cos(b) - np.cos(d) * np.cos(a)) / (np.sin(d) * np.sin(a)))
    t3 = np.arccos((np.cos(a) - np.cos(d) * np.cos(b)) / (np.sin(d) * np.sin(b)))
    return 2 * (np.pi - t1 - np.cos(a) * t2 - np.cos(b) * t3)


def test_fraction_behind_a_sphere_equals_the_cap_overlap():
    sph = trimesh.creation.icosphere(5, radius=0.5)
    sph.apply_translation([0.0, 1.5, 0.0])
    light, r = np.array([0.0, 4.0, 0.0]), 0.4
    x = np.linspace(0.65, 1.05, 8)  # receivers across the penumbra on y = 0
    pts = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    nrm = np.tile([0.0, 1.0, 0.0], (len(x), 1))
    got = light_visible_fraction(pts, nrm, [sph], light, r, n_samples=1024)
    dl, do = light - pts, np.array([0.0, 1.5, 0.0]) - pts
    Dl, Do = np.linalg.norm(dl, axis=1), np.linalg.norm(do, axis=1)
    a, b = np.arcsin(r / Dl), np.arcsin(0.5 / Do)
    gam = np.arccos(np.einsum("ij,ij->i", dl / Dl[:, None], do / Do[:, None]))
    assert np.all((gam < a + b) & (gam > np.abs(a - b)))  # every receiver in the penumbra
    want = 1 - _cap_overlap(a, b, gam) / (2 * np.pi * (1 - np.cos(a)))
    # 32 x 32 strata: a smooth boundary crosses ~2*32 of 1024 strata, each off by <= 1/1024,
    # so |error| <= 64/1024 ~ 0.06 in the worst case and ~1/sqrt(64)/1024*64 ~ 0.01 typically;
    # the icosphere (level 5) is 0.1 % smaller than the sphere
    np.testing.assert_allclose(got.fraction, want, atol=0.02)


def test_unshadowed_radiance_is_the_spherical_light_form_factor():
    pts = np.zeros((3, 3))
    nrm = np.array([[0.0, 1.0, 0.0], [np.sin(0.6), np.cos(0.6), 0.0], [0.0, 0.0, 1.0]])
    far = trimesh.creation.box([0.1, 0.1, 0.1])
    far.apply_translation([50.0, 0.0, 0.0])  # hits nothing
    light, r = np.array([0.0, 2.0, 0.0]), 0.2
    got = light_visible_fraction(pts, nrm, [far], light, r, n_samples=4096)
    np.testing.assert_array_equal(got.fraction, 1.0)
    np.testing.assert_array_equal(got.radiance, got.unshadowed)
    # above the horizon: (1/pi) * pi sin^2(alpha) cos(beta); Monte Carlo over 64 x 64 strata
    # of a smooth integrand: relative error << 1e-3
    sin2 = (r / 2.0) ** 2
    np.testing.assert_allclose(got.unshadowed[:2], sin2 * np.array([1.0, np.cos(0.6)]),
                               rtol=2e-3)
    # the light straddles the horizon of the third receiver: half of a symmetric cap
    # is above it, weighted by cos; bounded by the full-cap cosine integral
    assert 0 < got.unshadowed[2] < sin2 * np.sin(np.arcsin(r / 2.0))


def test_bad_radius_and_receiver_inside_the_light():
    sph = trimesh.creation.icosphere(2)
    with pytest.raises(InputError, match="radius > 0"):
        light_visible_fraction(np.zeros((1, 3)), [[0, 1, 0]], [sph], [0, 5, 0], 0.0)
    with pytest.raises(InputError, match="inside the spherical light"):
        light_visible_fraction([[0.0, 5.0, 0.0]], [[0, 1, 0]], [sph], [0, 5, 0], 1.0)
