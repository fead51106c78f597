"""De-ringing: negative radiance from SH ringing is desaturated toward luminance."""

from __future__ import annotations

import numpy as np

from shtools.reference.scenes import ground_grid
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.shading import LUMINANCE, desaturate_negative
from shtools.sh import project, sphere_quadrature


def test_desaturation_keeps_luminance_and_zeroes_the_smallest_channel():
    # row 2 is the blue blotch (-0.014, 0, 0.035): its luminance is negative
    rgb = np.array([[-0.014, 0.010, 0.035], [0.2, 0.3, 0.4], [-0.014, 0.000, 0.035],
                    [-0.1, 0.5, 0.2]])
    out = desaturate_negative(rgb)
    lum_in, lum_out = rgb @ LUMINANCE, out @ LUMINANCE
    np.testing.assert_array_equal(out[1], rgb[1])  # no negative channel: untouched
    for k in (0, 3):  # Y > 0: luminance kept to round-off, smallest channel exactly 0
        assert lum_in[k] > 0
        np.testing.assert_allclose(lum_out[k], lum_in[k], rtol=1e-12)
        assert out[k].min() == 0.0 and (out[k] >= 0).all()
    assert lum_in[2] < 0 and (out[2] == 0).all()  # Y <= 0: black


def test_deringing_leaves_no_negative_channel_under_a_hard_coloured_sun():
    """A small, strong red sun behind a sphere: order-4 ringing makes R negative on the
    ground around the shadow unless de-ringing is on."""
    order = 4
    sun = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    dirs, w = sphere_quadrature(60)
    lobe = np.maximum(dirs @ sun, 0.0) ** 200
    env = project(np.stack([0.05 + 400.0 * lobe, 0.1 + 0.0 * lobe, 0.3 + 0.0 * lobe]),
                  dirs, w, order).T
    v, n = ground_grid(40, (0.0, 0.0), 2.0)
    blocker = [SphereBlocker([0.8 * sun / sun[1]], [0.7])]  # measured: 19 negative vertices
    raw = ShadowRuntime(ShadowSettings(order=order, deringing="none", processes=1))
    rad_raw = raw.shade(raw.visibility(v, n, blocker), v, n, env)
    assert (rad_raw.min(axis=1) < 0).sum() > 0  # the case really rings
    rt = ShadowRuntime(ShadowSettings(order=order, processes=1, deringing="desaturate"))
    rad = rt.shade(rt.visibility(v, n, blocker), v, n, env)
    assert (rad >= 0).all()
    np.testing.assert_allclose(desaturate_negative(rad_raw), rad, rtol=1e-6, atol=1e-9)
