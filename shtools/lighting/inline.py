"""Environment lights given directly as SH coefficients (scene files, scripts).

Two layouts are accepted:

* ``"flat"``: rows in the shtools flat index order ``i = l*l + l + m``, any
  order (``n*n`` rows).
* ``"rh"``: the 9-coefficient layout of Ramamoorthi & Hanrahan (2001), as
  printed in their table and in ``probes_sh.json``: ``L00, L1m1, L10, L11,
  L2m2, L2m1, L20, L21, L22``, either as 9 rows in that order or as a mapping
  from those names (``"L1-1"``/``"L2-1"``/``"L2-2"`` also accepted).  Their basis
  (``L1m1 ~ y``, ``L10 ~ z``, ``L11 ~ x``, ``L21 ~ xz``, ``L22 ~ x^2 - y^2``)
  is exactly the shtools basis for the same axis names, and the published sets
  are in a +y-up frame, so with ``frame="y-up"`` the rows are used as they are.

``frame="z-up"`` converts coefficients written in a Z-up frame (Blender,
many DCC tools) to the Y-up world: source +z becomes +y and source +y becomes -z.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from shtools.errors import InputError
from shtools.lighting.frames import Z_UP_TO_Y_UP, transform
from shtools.sh.basis import order_from_size

#: Names of the Ramamoorthi–Hanrahan coefficients, in the shtools flat order.
RH_NAMES = ("L00", "L1m1", "L10", "L11", "L2m2", "L2m1", "L20", "L21", "L22")
_RH_ALIASES = {"L1-1": "L1m1", "L2-1": "L2m1", "L2-2": "L2m2"}

FRAMES = ("y-up", "z-up")
LAYOUTS = ("flat", "rh")


def _rh_rows(values: Mapping) -> list:
    named = {_RH_ALIASES.get(str(k), str(k)): v for k, v in values.items()}
    unknown = sorted(set(named) - set(RH_NAMES))
    if unknown:
        raise InputError(f"unknown SH coefficient name(s) {', '.join(unknown)}; the "
                         f"Ramamoorthi–Hanrahan names are {', '.join(RH_NAMES)}")
    missing = [k for k in RH_NAMES if k not in named]
    if missing:
        raise InputError(f"missing SH coefficient(s) {', '.join(missing)}")
    return [named[k] for k in RH_NAMES]


def light_from_coefficients(values, *, layout: str = "flat", frame: str = "y-up",
                            scale: float = 1.0) -> np.ndarray:
    """RGB radiance SH of the Y-up world from inline coefficients.

    Parameters
    ----------
    values : array_like, shape (n*n, 3) or (n*n,), or mapping
        RGB (or grey, replicated to RGB) coefficients; a mapping of
        Ramamoorthi–Hanrahan names with ``layout="rh"``.
    layout : {"flat", "rh"}
        Row order (see the module notes); ``"rh"`` requires exactly 9 rows.
    frame : {"y-up", "z-up"}
        Frame the coefficients are written in.
    scale : float
        Multiplies every coefficient (e.g. an exposure factor).

    Returns
    -------
    ndarray, shape (n*n, 3)
        Radiance coefficients ``int L(s) y_i(s) ds`` in the Y-up world.

    Raises
    ------
    shtools.errors.InputError
        Wrong count (not a square ``n*n``), wrong names, NaN/inf, bad layout or frame.
    """
    if layout not in LAYOUTS:
        raise InputError(f"unknown SH layout '{layout}'; use one of {', '.join(LAYOUTS)}")
    if frame not in FRAMES:
        raise InputError(f"unknown SH frame '{frame}'; use one of {', '.join(FRAMES)}")
    if isinstance(values, Mapping):
        if layout != "rh":
            raise InputError("named SH coefficients need layout 'rh' (Ramamoorthi–Hanrahan)")
        values = _rh_rows(values)
    try:
        c = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("SH coefficients must be numbers: a list of [r, g, b] rows") from None
    if c.ndim == 1:
        c = np.repeat(c[:, None], 3, axis=1)
    if c.ndim != 2 or c.shape[1] != 3:
        raise InputError(f"SH coefficients must be n*n rows of [r, g, b], got shape {c.shape}")
    try:
        order_from_size(c.shape[0])
    except ValueError:
        raise InputError(f"{c.shape[0]} SH coefficient rows is not a square number n*n "
                         "(1, 4, 9, 16, ...)") from None
    if layout == "rh" and c.shape[0] != len(RH_NAMES):
        raise InputError(f"the Ramamoorthi–Hanrahan layout has 9 rows, got {c.shape[0]}")
    if not np.all(np.isfinite(c)):
        raise InputError("SH coefficients contain NaN or inf")
    if frame == "z-up":
        c = transform(c, Z_UP_TO_Y_UP)
    return c * float(scale)
