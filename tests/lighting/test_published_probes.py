"""Real data: the Uffizi probe against the published Ramamoorthi–Hanrahan-style set.

probes_sh.json (see ../shared/data/SOURCES.md) gives, for probes/uffizi.hdr,
(a) coefficients computed at pixel centres in ITS frame
    x = sin t cos p, y = cos t, z = -sin t sin p, and
(b) the published 2-decimal Uffizi set, which matches (a) to about 1 % after one
    scale factor (the image is ~10x brighter than the probe R&H used).
Our world frame is (-sin t sin p, cos t, sin t cos p): the JSON frame is ours with
x and z swapped, a reflection, so we project with that reflection to compare.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from shtools.lighting import RH_NAMES, check_latlong_shape, load_hdr_image, project_latlong

#: ours -> probes_sh.json frame (swap x and z; a reflection, det -1)
TO_JSON_FRAME = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


@pytest.fixture
def probes(shared_data):
    return json.loads((shared_data / "probes_sh.json").read_text()), shared_data


def _values(entry):
    return np.array([entry["values"][name] for name in RH_NAMES])


@pytest.mark.data
def test_probes_are_latlong_maps(probes):
    """SOURCES.md says lat-long, row 0 up: every probe is 2:1 (no angular maps)."""
    _, data = probes
    for path in sorted((data / "probes").glob("*.hdr")):
        check_latlong_shape(load_hdr_image(path).shape, path)


@pytest.mark.data
def test_uffizi_matches_the_computed_and_the_published_set(probes):
    meta, data = probes
    image = load_hdr_image(data / "probes" / "uffizi.hdr")
    ours = project_latlong(image, 3, rotation=TO_JSON_FRAME)

    computed = _values(meta["computed_from_included_hdr"]["probes"]["probes/uffizi.hdr"])
    # Their pixel-centre rule vs our exact pixel integrals differ by O(1/H^2) of
    # the largest coefficient (~3e-4 at H = 128); 5-decimal rounding adds 5e-6.
    np.testing.assert_allclose(ours, computed, atol=2e-3 * np.abs(computed).max())

    published = _values(meta["published"]["probes"]["uffizi_gallery"])
    scale = float(np.sum(ours * published) / np.sum(ours * ours))
    rel = np.linalg.norm(scale * ours - published) / np.linalg.norm(published)
    # The notes report scale 0.1004 and 1.0 % over all 27 numbers; the published
    # values have 2 decimals (up to 0.005 each, ~0.8 % of the vector's norm).
    assert scale == pytest.approx(0.1004, rel=5e-3)
    assert rel < 0.015

    # Mind the frame: without the reflection (our own world frame) it does not fit.
    own = project_latlong(image, 3)
    own_scale = float(np.sum(own * published) / np.sum(own * own))
    own_rel = np.linalg.norm(own_scale * own - published) / np.linalg.norm(published)
    assert own_rel > 0.2


def test_mirror_and_quarter_turn_give_the_json_frame():
    """``--mirror --rotate-y 90`` is exactly the probes_sh.json frame (documented)."""
    from shtools.lighting import environment_rotation

    np.testing.assert_allclose(environment_rotation(90.0, mirror=True), TO_JSON_FRAME,
                               atol=1e-15)
