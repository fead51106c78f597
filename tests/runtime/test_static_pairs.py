"""Static spheres x static receivers kept between frames (shtools.runtime.static_pairs)."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.errors import InputError
from shtools.geometry.sphere_tree import build_tree
from shtools.reference import sphere_union_visibility
from shtools.reference.scenes import capsule_scene
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker

SETTINGS = dict(order=4, acc_order=6, vertices_per_cluster=40, chunk_pairs=2048, processes=1)


def _ball(center, radius, count=60):
    """Receivers on a sphere (Fibonacci points) with outward normals."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    s = np.sqrt(1.0 - z * z)
    n = np.column_stack([s * np.cos(phi), z, s * np.sin(phi)])
    return np.asarray(center) + radius * n, n


class Scene:
    """A static capsule over a static ground, and a moving ball with receivers on it."""

    def __init__(self):
        sc = capsule_scene(grid=20)
        self.ground_v, self.ground_n = sc.vertices, sc.normals
        self.capsule = (sc.centers, sc.radii, build_tree(sc.centers, sc.radii))
        self.ball_c = np.array([[0.0, 0.0, 0.0], [0.15, 0.05, 0.0], [-0.15, 0.05, 0.0]])
        self.ball_r = np.array([0.2, 0.12, 0.12])
        self.ball_tree = build_tree(self.ball_c, self.ball_r)

    def frame(self, t: float, *, flags: bool, capsule_shift=(0.0, 0.0, 0.0)):
        where = np.array([0.3 * np.sin(t) - 0.4, 0.9, 0.3 * np.cos(t)])
        bv, bn = _ball(where, 0.25)
        v = np.vstack([self.ground_v, bv])
        n = np.vstack([self.ground_n, bn])
        c, r, tree = self.capsule
        blockers = [SphereBlocker(c + np.asarray(capsule_shift), r,
                                  tree=(tree.parent, tree.leaf), static=flags),
                    SphereBlocker(self.ball_c + where, self.ball_r,
                                  tree=(self.ball_tree.parent, self.ball_tree.leaf))]
        groups = np.r_[np.zeros(len(self.ground_v), int), np.ones(len(bv), int)]
        kw = {"static_receivers": groups == 0} if flags else {}
        return v, n, groups, blockers, kw


def test_static_pairs_give_the_visibility_of_a_frame_without_flags():
    """The kept static sum plus the frame's other pairs is the same sum over the same
    pairs (regrouped), so flagged and unflagged frames agree to float32 rounding, and
    both are as close to sphere-union ray tracing."""
    scene = Scene()
    plain = ShadowRuntime(ShadowSettings(**SETTINGS))
    kept = ShadowRuntime(ShadowSettings(**SETTINGS))
    v, _, groups, _, _ = scene.frame(0.0, flags=False)
    clusters = plain.clusters(v, groups)
    for t in (0.0, 0.7, 1.4):
        v, n, _, blockers, _ = scene.frame(t, flags=False)
        want = plain.visibility(v, n, blockers, clusters)
        v, n, _, blockers, kw = scene.frame(t, flags=True)
        got = kept.visibility(v, n, blockers, clusters, **kw)
        # float32 log sums of ~30 terms regrouped, then an exp of norm up to ~10:
        # differences of a few float32 ulps of the sum, amplified by the squarings
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-4 * np.abs(want).max())
        assert kept.last_stats["pairs"] < plain.last_stats["pairs"]  # static pairs kept
    centers = np.vstack([b.centers for b in blockers])
    radii = np.concatenate([b.radii for b in blockers])
    ref = sphere_union_visibility(v, n, centers, radii, 4)

    def median_err(g):
        return np.median(np.linalg.norm(g - ref, axis=1) / np.linalg.norm(ref, axis=1))

    # the same error against rays to within the rounding above
    assert abs(median_err(got) - median_err(want)) < 1e-3


def test_kept_sum_never_depends_on_earlier_frames():
    """A runtime that evaluated other frames first (and a static blocker that moved
    while flagged static) gives the bytes of a fresh runtime on the same frame."""
    scene = Scene()
    warm = ShadowRuntime(ShadowSettings(**SETTINGS))
    v, _, groups, _, _ = scene.frame(0.0, flags=True)
    clusters = warm.clusters(v, groups)
    for t in (0.3, 0.9):
        v, n, _, blockers, kw = scene.frame(t, flags=True)
        warm.visibility(v, n, blockers, clusters, **kw)
    for shift in ((0.0, 0.0, 0.0), (0.05, 0.0, 0.0)):  # the second one is a cache miss
        v, n, _, blockers, kw = scene.frame(2.0, flags=True, capsule_shift=shift)
        got = warm.visibility(v, n, blockers, clusters, **kw)
        fresh = ShadowRuntime(ShadowSettings(**SETTINGS))
        want = fresh.visibility(v, n, blockers, clusters, **kw)
        np.testing.assert_array_equal(got, want)
    # a moved static blocker is not served from the kept sum: it matches no flags
    plain = ShadowRuntime(ShadowSettings(**SETTINGS))
    v, n, _, blockers, _ = scene.frame(2.0, flags=False, capsule_shift=(0.05, 0.0, 0.0))
    np.testing.assert_allclose(got, plain.visibility(v, n, blockers, clusters), rtol=0,
                               atol=2e-4 * np.abs(got).max())  # rounding, as above


def test_static_receivers_must_be_one_bool_per_row():
    scene = Scene()
    rt = ShadowRuntime(ShadowSettings(**SETTINGS))
    v, n, _, blockers, _ = scene.frame(0.0, flags=True)
    with pytest.raises(InputError, match="static_receivers must be a bool mask"):
        rt.visibility(v, n, blockers, static_receivers=np.ones(len(v) - 1, bool))
    with pytest.raises(InputError, match="static_receivers must be a bool mask"):
        rt.visibility(v, n, blockers, static_receivers=np.ones(len(v), int))
