"""Shading terms kept between frames (shtools.runtime.shading_cache) give the bytes of
shading computed afresh."""

from __future__ import annotations

import numpy as np

from shtools.reference.scenes import capsule_scene
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker, SphereLight
from shtools.runtime.shading import desaturate_negative, shade


def test_kept_light_terms_give_the_bytes_of_fresh_shading():
    """Rows that moved or turned and lights that moved or changed colour are refreshed;
    the rest is reused, and every frame equals shading without any cache, bit for bit.

    576 receivers: two whole blocks of the products and a ragged one
    (PRODUCT_BLOCK_ROWS), some rows changing in the first and some in the last, so
    kept blocks sit beside refreshed ones (OpenBLAS sums a row by its place in its
    block on some CPUs: a refresh of the changed rows alone would differ)."""
    sc = capsule_scene(grid=24)
    settings = ShadowSettings(order=4, processes=1)
    rt = ShadowRuntime(settings)
    v0, n0 = sc.vertices.copy(), sc.normals.copy()
    g = rt.visibility(v0, n0, [SphereBlocker(sc.centers, sc.radii)])
    lights = [SphereLight((1.0, 2.0, 0.5), 0.3, (3.0, 2.0, 1.0)),
              SphereLight((-1.5, 1.0, -0.5), 0.2, (0.5, 1.0, 2.0))]
    moved = v0.copy()
    moved[:40] += (0.0, 0.05, 0.0)  # some receivers move
    turned = n0.copy()  # others turn (their cosine transfer changes)
    turned[-70:-50] = turned[-70:-50, [1, 2, 0]]
    recoloured = [lights[0], SphereLight((-1.5, 1.0, -0.5), 0.25, (0.5, 1.5, 2.0))]
    frames = [(v0, n0, lights), (v0, n0, lights), (moved, n0, lights),
              (moved, n0, [SphereLight((1.1, 2.0, 0.5), 0.3, (3.0, 2.0, 1.0)), lights[1]]),
              (moved, n0, [lights[0], SphereLight((-1.5, 1.0, -0.5), 0.25, (0.5, 1.0, 2.0))]),
              (moved, n0, recoloured), (moved, turned, recoloured), (v0, turned, recoloured),
              (v0, n0, [])]
    for v, n, ls in frames:
        got = rt.shade(g, v, n, sc.env_sh, ls)
        want = desaturate_negative(shade(g, v, n, sc.env_sh, tuple(ls), order=4,
                                         window_kind=settings.resolved_window(),
                                         window_h=settings.window_h))
        np.testing.assert_array_equal(got, want)
    # the light terms are kept, not recomputed: a cache told that nothing moved
    # serves the old rows' terms, and the bytes then differ from fresh shading
    rt.shade(g, v0, n0, sc.env_sh, lights)
    rt._shading._rows[2][:] = moved  # the receivers its lit rows were made for
    want = desaturate_negative(shade(g, moved, n0, sc.env_sh, tuple(lights), order=4,
                                     window_kind=settings.resolved_window(),
                                     window_h=settings.window_h))
    assert not np.array_equal(rt.shade(g, moved, n0, sc.env_sh, lights), want)
