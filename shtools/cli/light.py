"""``shtools light``: environment lights to SH assets (``light project``)."""

from __future__ import annotations

import time

import click
import numpy as np

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    option_type,
    output_option,
    report,
    setting_type,
)


@click.group()
def light():
    """Environment lighting as RGB radiance SH."""


@light.command("project")
@click.argument("image", type=InputPath())
@click.option("--order", "-n", type=setting_type("order"), required=True,
              help="SH order n (the scene's settings.order).")
@output_option
@click.option("--window", type=setting_type("window"),
              default="none", show_default=True,
              help="Per-band window against ringing (cosine: the paper's filter).")
@click.option("--window-h", type=setting_type("window_h"), default=None,
              help="Window width in bands (default: 2n for cosine, n otherwise).")
@click.option("--rotate-y", type=option_type("rotate_y"), default=0.0, show_default=True,
              metavar="DEG",
              help="Rotate the environment about +y (right-hand rule; +90 turns the image "
              "centre from -z to -x).")
@click.option("--mirror", is_flag=True,
              help="Mirror the image left-right first (for maps stored mirrored).")
@click.option("--exposure", type=option_type("exposure"), default=0.0, show_default=True,
              metavar="EV",
              help="Scale radiance by 2**EV.")
@json_option
@errors_name("image")
def project(image, order, output, window, window_h, rotate_y, mirror, exposure, as_json):
    """Project a lat-long (equirectangular) HDR IMAGE to RGB radiance SH.

    IMAGE is .hdr/.pic/.pfm/.exr, twice as wide as high, row 0 straight up,
    image centre towards -z in the Y-up world (docs/conventions.md).  Every
    basis function is integrated exactly over every pixel.
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.lighting.environment import project_environment_to_file

    guard_outputs({"-o": output}, [image])
    start = time.perf_counter()
    coeffs, info = project_environment_to_file(image, order, output, window=window,
                                               window_h=window_h, rotate_y=rotate_y,
                                               exposure=exposure, mirror=mirror)
    seconds = time.perf_counter() - start
    mean = coeffs[0] / np.sqrt(4.0 * np.pi)  # average radiance over the sphere
    summary = {"output": output, "image": image, "order": order, **info,
               "mean_radiance": mean.round(6).tolist(),
               "brightest_direction": _dominant_direction(coeffs),
               "seconds": round(seconds, 3)}
    d = summary["brightest_direction"]
    human = (f"wrote {output}: order {order} from {image} ({info['width']}x{info['height']} "
             f"lat-long); mean radiance RGB ({mean[0]:.4g}, {mean[1]:.4g}, {mean[2]:.4g})")
    if d is not None:
        human += f"; light mostly from ({d[0]:+.2f}, {d[1]:+.2f}, {d[2]:+.2f})"
    report(summary, as_json, human)


#: Rec. 709 luminance weights, for the dominant light direction.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _dominant_direction(coeffs):
    """Unit direction of the luminance's band-1 part (x, y, z), or None at order 1."""
    if coeffs.shape[0] < 4:
        return None
    lum = coeffs @ LUMINANCE
    v = np.array([lum[3], lum[1], lum[2]])  # y(1,1) ~ x, y(1,-1) ~ y, y(1,0) ~ z
    norm = np.linalg.norm(v)
    return None if norm == 0 else (v / norm).round(4).tolist()
