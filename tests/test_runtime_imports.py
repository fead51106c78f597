"""The runtime's import rule (docs/architecture.md "Layers").

numpy, h5py, shtools.sh, shtools.data_formats only.
"""

from __future__ import annotations

import json
import subprocess
import sys

#: Packages a pipeline embedding shtools.runtime must not need.
FORBIDDEN = ("trimesh", "pymeshlab", "igl", "scipy", "embreex", "matplotlib", "click")


def test_import_runtime_loads_no_geometry_stack():
    code = (
        "import json, sys\n"
        "import shtools.runtime\n"
        "from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker\n"
        "rt = ShadowRuntime(ShadowSettings(order=2, hierarchy=False))\n"
        "import numpy as np\n"
        "g = rt.visibility(np.zeros((2, 3)), np.tile([0.0, 1.0, 0.0], (2, 1)),\n"
        "                  [SphereBlocker([[0.0, 2.0, 0.0]], [0.5])])\n"
        "rt.shade(g, np.zeros((2, 3)), np.tile([0.0, 1.0, 0.0], (2, 1)), np.ones((4, 3)))\n"
        "print(json.dumps(sorted(m for m in sys.modules)))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    bad = sorted({m for m in loaded if m.split(".")[0] in FORBIDDEN})
    assert bad == [], f"shtools.runtime pulled in {bad}"
