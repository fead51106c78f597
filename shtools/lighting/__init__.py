"""Environment maps and inline coefficients to RGB radiance SH (Y-up world).

* :func:`project_environment` — lat-long HDR image to SH with exact per-pixel
  integrals, rotation, exposure and windowing (``shtools light project``).
* :func:`light_from_coefficients` — inline SH (flat or Ramamoorthi–Hanrahan
  layout, Y-up or Z-up frame), for scene files.
* :func:`project_latlong`, :func:`latlong_directions`, :func:`pixel_solid_angles`
  — the lat-long mapping of ``docs/conventions.md``.
* :func:`load_hdr_image` — HDR files as linear RGB.
"""

from shtools.lighting.environment import (
    check_latlong_shape,
    environment_rotation,
    project_environment,
)
from shtools.lighting.frames import frame_transform_matrix, rotation_about_y, transform
from shtools.lighting.images import load_hdr_image
from shtools.lighting.inline import RH_NAMES, light_from_coefficients
from shtools.lighting.latlong import latlong_directions, pixel_solid_angles, project_latlong

__all__ = [
    "RH_NAMES",
    "check_latlong_shape",
    "environment_rotation",
    "frame_transform_matrix",
    "latlong_directions",
    "light_from_coefficients",
    "load_hdr_image",
    "pixel_solid_angles",
    "project_environment",
    "project_latlong",
    "rotation_about_y",
    "transform",
]
