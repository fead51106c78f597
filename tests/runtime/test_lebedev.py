"""The runtime's Lebedev product rules against SciPy's (the runtime itself stays NumPy only,
so its orbit constants are written out; this file is not among the core-install tests)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import lebedev_rule as scipy_rule

from shtools.runtime.fast_exp import lebedev_rule


@pytest.mark.parametrize("degree", [9, 15])
def test_lebedev_rules_are_scipys(degree):
    dirs, w = lebedev_rule(degree)
    ref_dirs, ref_w = scipy_rule(degree)
    ref_dirs = ref_dirs.T
    # the same node set and weights (1e-14: the constants are printed to double precision)
    match = np.argmin(np.linalg.norm(dirs[:, None] - ref_dirs[None], axis=2), axis=1)
    assert sorted(match) == list(range(ref_dirs.shape[0]))
    np.testing.assert_allclose(dirs, ref_dirs[match], atol=1e-14)
    np.testing.assert_allclose(w, ref_w[match], rtol=1e-13)
