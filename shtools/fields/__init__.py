"""Adaptive shadow fields (Tamura et al.): sampling, reduction, quantization.

* :mod:`~shtools.fields.sampling` -- bounding sphere, shells, the direction map,
  cone-culled object visibility and OCVs;
* :mod:`~shtools.fields.reduction` -- the per-shell reduction of Sec. 4 and eq. (1);
* :mod:`~shtools.fields.quantize` -- 8-bit quantization per shell and coefficient;
* :mod:`~shtools.fields.build` -- :func:`sample_field`, what ``shtools field sample`` runs.

The runtime lookup is :mod:`shtools.runtime.fields` (NumPy + h5py only); the asset
is :mod:`shtools.data_formats.field`.  Nothing here imports :mod:`shtools.reference`.
"""

from shtools.fields.build import (
    FieldParameters,
    FieldReport,
    SampledShells,
    build_field,
    log_ocvs,
    sample_field,
    sample_shells,
)
from shtools.fields.quantize import dequantize, quantize
from shtools.fields.reduction import l1_error, reduce_shell
from shtools.fields.sampling import (
    bounding_sphere,
    cone_mask,
    direction_map,
    object_visibility,
    sample_ocvs,
    shell_radii,
)

__all__ = [
    "FieldParameters",
    "FieldReport",
    "SampledShells",
    "bounding_sphere",
    "build_field",
    "cone_mask",
    "dequantize",
    "direction_map",
    "l1_error",
    "log_ocvs",
    "object_visibility",
    "quantize",
    "reduce_shell",
    "sample_field",
    "sample_ocvs",
    "sample_shells",
    "shell_radii",
]
