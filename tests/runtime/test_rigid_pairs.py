"""Rigid objects' own pairs kept in object space (shtools.runtime.rigid_pairs)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from shtools.errors import InputError
from shtools.geometry.sphere_tree import build_tree
from shtools.reference import sphere_union_visibility
from shtools.reference.scenes import capsule_scene
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.rigid_pairs import SNAP_BITS, object_frame

SETTINGS = dict(order=4, acc_order=6, vertices_per_cluster=40, chunk_pairs=2048, processes=1)


def _fibonacci(count):
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    s = np.sqrt(1.0 - z * z)
    return np.column_stack([s * np.cos(phi), z, s * np.sin(phi)])


class Scene:
    """A lumpy rigid creature (its receivers on its spheres' outer surface) turning and
    moving over a static capsule and a static ground."""

    def __init__(self):
        sc = capsule_scene(grid=16)
        self.ground_v, self.ground_n = sc.vertices, sc.normals
        self.capsule = (sc.centers, sc.radii, build_tree(sc.centers, sc.radii))
        # no symmetry: distinct principal moments and third moments
        self.body_c = np.array([[0.0, 0.0, 0.0], [0.22, 0.04, 0.0], [-0.12, 0.1, 0.05],
                                [0.05, -0.06, 0.16], [0.3, 0.12, -0.08]])
        self.body_r = np.array([0.16, 0.1, 0.09, 0.08, 0.06])
        self.tree = build_tree(self.body_c, self.body_r)
        pts, nrm = [], []
        for c, r in zip(self.body_c, self.body_r, strict=True):
            d = _fibonacci(40)
            p = c + (r + 1e-3) * d
            outside = np.all(np.linalg.norm(p[:, None] - self.body_c[None], axis=2)
                             > self.body_r[None] + 1e-4, axis=1)
            pts.append(p[outside])
            nrm.append(d[outside])
        self.body_v, self.body_n = np.vstack(pts), np.vstack(nrm)

    def frame(self, t: float, *, flags: bool, bend: float = 0.0):
        rot = Rotation.from_rotvec([0.7 * np.sin(t), 1.3 * t, 0.4 * np.cos(0.5 * t)]).as_matrix()
        where = np.array([0.3 * np.sin(t) - 0.3, 0.7, 0.3 * np.cos(t)])
        body_c = self.body_c.copy()
        body_c[-1, 1] += bend  # a non-rigid change of the sphere set
        v = np.vstack([self.ground_v, self.body_v @ rot.T + where])
        n = np.vstack([self.ground_n, self.body_n @ rot.T])
        c, r, tree = self.capsule
        blockers = [SphereBlocker(c, r, tree=(tree.parent, tree.leaf), static=flags),
                    SphereBlocker(body_c @ rot.T + where, self.body_r,
                                  tree=(self.tree.parent, self.tree.leaf))]
        groups = np.r_[np.zeros(len(self.ground_v), int), np.ones(len(self.body_v), int)]
        # with the flags, the ground's pairs with the capsule are kept too (the kept
        # static sum is the read-only base the rigid sums are added to)
        kw = {"rigid_receivers": np.where(groups == 1, 1, -1),
              "static_receivers": groups == 0} if flags else {}
        return v, n, groups, blockers, kw


def test_object_frame_of_a_turned_copy_gives_the_same_snapped_inputs():
    """The object frame follows the object: a turned and moved copy's object-space
    centres are equal bit for bit after the snap."""
    rng = np.random.default_rng(3)
    c = rng.normal(size=(30, 3)) * [1.0, 0.6, 0.3]
    o, axes, step = object_frame(c)
    assert np.allclose(axes.T @ axes, np.eye(3)) and np.linalg.det(axes) > 0
    local = np.rint((c - o) @ axes / step) * step
    for seed in range(5):
        rot = Rotation.random(random_state=seed).as_matrix()
        moved = c @ rot.T + rng.normal(size=3)
        o2, axes2, step2 = object_frame(moved)
        assert step2 == step
        np.testing.assert_allclose(axes2, rot @ axes, atol=1e-12)
        np.testing.assert_array_equal(np.rint((moved - o2) @ axes2 / step2) * step2, local)
    assert step == 2.0 ** (np.floor(np.log2(np.linalg.norm(c - c.mean(0), axis=1).max()))
                           - SNAP_BITS)


def test_rigid_pairs_give_the_visibility_of_a_frame_without_flags():
    """The kept object-space sum turned into the world is the same sum over the same
    pairs (made in another frame), so flagged and unflagged frames agree to float32
    rounding and are as close to sphere-union ray tracing."""
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
        # float32 pair geometry in another frame (ulp-level changes of 1 - cos(theta),
        # which the piecewise-constant ratio table can turn into one cell's step) and
        # a float32 rotation, amplified by the exp; measured ~6e-6 of the largest
        # value.  (Receivers exactly on their own sphere's axis inside it, where
        # 1 - cos(theta) loses half its digits to cancellation, can differ more: not
        # in this scene, whose receivers lie just outside the spheres.)
        err = np.abs(got - want).max(axis=1)
        assert err.max() < 1e-4 * np.abs(want).max()
        assert kept.last_stats["pairs"] < plain.last_stats["pairs"]  # own pairs kept
    centers = np.vstack([b.centers for b in blockers])
    radii = np.concatenate([b.radii for b in blockers])
    ref = sphere_union_visibility(v, n, centers, radii, 4)

    def median_err(g):
        return np.median(np.linalg.norm(g - ref, axis=1) / np.linalg.norm(ref, axis=1))

    assert abs(median_err(got) - median_err(want)) < 1e-3  # the same error against rays


def test_kept_sum_never_depends_on_earlier_frames():
    """A runtime that evaluated other frames first gives the bytes of a fresh runtime on
    the same frame, whether the object kept its shape (kept sum turned) or not (made
    again), and the kept sum is reused across turns."""
    scene = Scene()
    warm = ShadowRuntime(ShadowSettings(**SETTINGS))
    v, _, groups, _, _ = scene.frame(0.0, flags=True)
    clusters = warm.clusters(v, groups)
    calls = []
    kept_sum = warm._kept_sum
    def counted(pts, nrm, spheres, *args, **kwargs):
        if len(spheres) == 1:  # an object's own sum (the static sum has both blockers)
            calls.append(1)
        return kept_sum(pts, nrm, spheres, *args, **kwargs)

    warm._kept_sum = counted
    for t in (0.3, 0.9):
        v, n, _, blockers, kw = scene.frame(t, flags=True)
        warm.visibility(v, n, blockers, clusters, **kw)
    assert len(calls) == 1  # made once, turned in the second frame
    for bend in (0.0, 0.03):  # the second one changes the object: made again
        v, n, _, blockers, kw = scene.frame(2.0, flags=True, bend=bend)
        got = warm.visibility(v, n, blockers, clusters, **kw)
        fresh = ShadowRuntime(ShadowSettings(**SETTINGS))
        want = fresh.visibility(v, n, blockers, clusters, **kw)
        np.testing.assert_array_equal(got, want)
    assert len(calls) == 2


def test_rigid_receivers_must_name_a_sphere_blocker_per_row():
    scene = Scene()
    rt = ShadowRuntime(ShadowSettings(**SETTINGS))
    v, n, _, blockers, kw = scene.frame(0.0, flags=True)
    with pytest.raises(InputError, match="rigid_receivers must be an int array"):
        rt.visibility(v, n, blockers, rigid_receivers=kw["rigid_receivers"][1:])
    with pytest.raises(InputError, match="rigid_receivers must be an int array"):
        rt.visibility(v, n, blockers, rigid_receivers=kw["rigid_receivers"] > 0)
    with pytest.raises(InputError, match="names blocker 5"):
        rt.visibility(v, n, blockers, rigid_receivers=np.where(kw["rigid_receivers"] > 0, 5, -1))
