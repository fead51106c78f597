"""The traced shadow of a field light (the emission fraction), against area-sampled ray tracing."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shtools.fields.emitter import make_emitter
from shtools.fields.radiance import emitter_sphere
from shtools.reference.emitter import emitter_radiance, shaded_lamp, shadowed_and_free
from shtools.scene.lamp_shadow import Blockers, LampCaster, emission_visible_fraction

RADIANCE = (10.0, 9.0, 8.0)


@pytest.fixture(scope="module")
def lamp():
    bulb, shade = shaded_lamp()
    em = make_emitter(bulb, RADIANCE, [shade])
    c, r = emitter_sphere(em)
    return em, LampCaster(em.vertices, em.faces, em.emissive, c, r)


def _ground(n=21, size=2.0, y=0.0):
    xs = np.linspace(-size / 2, size / 2, n)
    X, Z = np.meshgrid(xs, xs)
    pts = np.c_[X.ravel(), np.full(X.size, y), Z.ravel()]
    return pts, np.tile([0.0, 1.0, 0.0], (len(pts), 1))


def _pose(deg_x=-90.0, deg_z=0.0, at=(0.0, 1.2, 0.0)):
    from scipy.spatial.transform import Rotation

    R = Rotation.from_euler("xyz", [deg_x, 0.0, deg_z], degrees=True).as_matrix()
    return R, np.asarray(at, dtype=float)


def test_fraction_matches_the_area_sampled_emitter_behind_a_ball(lamp):
    em, caster = lamp
    R, t = _pose(deg_z=35.0)
    ball = trimesh.creation.icosphere(3, radius=0.18)
    ball.apply_translation([0.15, 0.3, 0.1])
    pts, nrm = _ground(15, 1.4)
    blockers = Blockers([(ball.vertices, ball.faces)])
    frac = emission_visible_fraction(caster, R, t, 1.0, blockers, pts, nrm, n_samples=1024)
    world = em.vertices @ R.T + t
    shadowed, free = (r[:, 0] for r in shadowed_and_free(
        pts, nrm, em, world, [(ball.vertices, ball.faces)], n_samples=8192))
    lit = free > 0.05 * free.max()
    want = shadowed[lit] / free[lit]
    assert (want < 0.3).sum() >= 3 and (want > 0.999).sum() >= 30  # an umbra and open ground
    # two independent estimators (1024 cone strata vs 8192 area samples, through the
    # shade): a penumbra vertex's fraction carries up to ~1 % sampling noise in each
    # (0.13 % RMS, 1.0 % max measured)
    err = frac[lit] - want
    assert np.sqrt(np.mean(err ** 2)) < 0.006
    assert np.abs(err).max() < 0.03
    # where nothing is in the way the fraction is exactly 1 (the ratio shares its rays)
    assert np.all(frac[lit][want > 0.999999] > 0.98)


def test_nothing_between_the_receiver_and_the_lamp_leaves_it_whole(lamp):
    em, caster = lamp
    R, t = _pose()
    pts, nrm = _ground(11)
    assert np.all(emission_visible_fraction(caster, R, t, 1.0, None, pts, nrm) == 1.0)
    # a lid above the lamp is hit by rays that missed the lamp (none carry light) and
    # by none that reach it: the lamp's light is untouched (the segment ends at the lamp)
    lid = trimesh.creation.box((3.0, 0.1, 3.0))
    lid.apply_translation([0.0, 2.0, 0.0])
    frac = emission_visible_fraction(caster, R, t, 1.0, Blockers([(lid.vertices, lid.faces)]),
                                     pts, nrm)
    assert np.all(frac == 1.0)
    # the same slab between the lamp and the ground takes all of it
    lid.apply_translation([0.0, -1.4, 0.0])
    frac = emission_visible_fraction(caster, R, t, 1.0, Blockers([(lid.vertices, lid.faces)]),
                                     pts, nrm)
    free = emitter_radiance(pts, nrm, em.vertices @ R.T + t, em.faces, em.emissive,
                            em.radiance, [], n_samples=2048)[:, 0]
    assert np.all(frac[free > 0] == 0.0)


def test_a_scaled_lamp_casts_the_scaled_shadow(lamp):
    em, caster = lamp
    R, t = _pose(deg_z=20.0)
    ball = trimesh.creation.icosphere(3, radius=0.3)
    ball.apply_translation([0.2, 0.5, 0.0])
    pts, nrm = _ground(11, 3.0)
    s = 2.0  # the lamp twice as large: its triangles scaled about its origin
    frac = emission_visible_fraction(caster, R, t, s, Blockers([(ball.vertices, ball.faces)]),
                                     pts, nrm, n_samples=1024)
    world = (em.vertices * s) @ R.T + t
    shadowed, free = (r[:, 0] for r in shadowed_and_free(
        pts, nrm, em, world, [(ball.vertices, ball.faces)], n_samples=8192))
    lit = free > 0.05 * free.max()
    err = frac[lit] - shadowed[lit] / free[lit]
    assert (shadowed[lit] / free[lit] < 0.5).sum() >= 5  # the ball's shadow is on the grid
    assert np.sqrt(np.mean(err ** 2)) < 0.008  # as above: sampling noise (0.23 % measured)


def test_the_cone_cull_misses_no_blocker_in_the_way():
    """Every receiver some of whose cone rays pass through a blocker's bounding sphere
    before the lamp is kept (checked by brute force on the rays themselves)."""
    from shtools.reference.light_fraction import cap_directions

    rng = np.random.default_rng(3)
    ball = trimesh.creation.icosphere(2, radius=0.3)
    ball.apply_translation([0.2, 1.0, -0.1])
    blockers = Blockers([(ball.vertices, ball.faces)])
    c, r = blockers.centers[0], blockers.radii[0]
    pts = rng.uniform([-2, -0.5, -2], [2, 0.5, 2], (300, 3))
    lamp = np.array([0.0, 2.0, 0.0])
    rel = lamp - pts
    length = np.linalg.norm(rel, axis=1)
    axis = rel / length[:, None]
    alpha = np.arcsin(0.25 / length)
    kept = blockers.in_cone(pts, axis, np.cos(alpha), length)
    dirs = cap_directions(axis, alpha, 64, rng)  # (V, 64, 3)
    t = np.linspace(0, 1, 100)[None, None, :, None] * length[:, None, None, None]
    along = pts[:, None, None, :] + t * dirs[:, :, None, :]
    crosses = (np.linalg.norm(along - c, axis=-1) < r).any(axis=(1, 2))
    assert crosses.sum() >= 10 and (~kept).sum() >= 50  # both kinds on the grid
    assert np.all(kept[crosses])
