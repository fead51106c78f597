"""The runtime's import rule (docs/architecture.md "Layers").

numpy, h5py, shtools.sh, shtools.data_formats only.
"""

from __future__ import annotations

from helpers.processes import forbidden_imports


def test_import_runtime_loads_no_geometry_stack():
    code = (
        "import shtools.runtime\n"
        "from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker\n"
        "rt = ShadowRuntime(ShadowSettings(order=2, hierarchy=False))\n"
        "import numpy as np\n"
        "g = rt.visibility(np.zeros((2, 3)), np.tile([0.0, 1.0, 0.0], (2, 1)),\n"
        "                  [SphereBlocker([[0.0, 2.0, 0.0]], [0.5])])\n"
        "rt.shade(g, np.zeros((2, 3)), np.tile([0.0, 1.0, 0.0], (2, 1)), np.ones((4, 3)))\n"
    )
    bad = forbidden_imports(code)
    assert bad == [], f"shtools.runtime pulled in {bad}"
