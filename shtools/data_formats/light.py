"""The ``light`` asset: an environment light as RGB radiance SH coefficients.

Dataset ``coeffs (n*n, 3) f8``: coefficient ``i`` (flat index ``l*l + l + m``,
docs/conventions.md, Y-up world) of the radiance ``L(s)`` for the R, G, B
channels, i.e. ``L(s) = coeffs.T @ basis(s, n)``.  Root attribute ``sh_order`` is
``n``; ``source`` says where it came from (``"image"`` or ``"inline"``).  How the
coefficients were made (window, rotation, exposure, mapping) is in ``parameters``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from shtools.data_formats._base import DatasetSpec, Schema, read_asset, register, write_asset
from shtools.errors import AssetError

KIND = "light"
VERSION = 1


def _check(f, ctx: dict) -> None:
    order = int(ctx["attrs"]["sh_order"])
    size = ctx["dims"].get("C")
    if size != order * order:
        raise AssetError(
            f"'coeffs' has {size} rows but sh_order {order} needs {order * order}; "
            "rebuild the light",
            ctx["path"],
        )


SCHEMA = register(
    Schema(
        kind=KIND,
        version=VERSION,
        has_sh=True,
        datasets=(DatasetSpec("coeffs", ("C", 3)),),
        check=_check,
    )
)


def write_light(
    path: str | os.PathLike,
    coeffs,
    *,
    source: str = "inline",
    inputs: Mapping[str, str | os.PathLike] | None = None,
    parameters: Mapping[str, Any] | None = None,
) -> os.PathLike:
    """Write a ``light`` asset atomically.

    Parameters
    ----------
    path : path-like
        Output file.
    coeffs : array_like, shape (n*n, 3)
        RGB radiance SH coefficients.
    source : str
        ``"image"`` (projected from an environment map) or ``"inline"``.
    inputs : mapping, optional
        Input files (e.g. ``{"image": "probe.hdr"}``); their sha256 is recorded.
    parameters : mapping, optional
        How the coefficients were made, recorded as JSON.

    Returns
    -------
    pathlib.Path
    """
    from shtools.sh.basis import order_from_size

    c = np.asarray(coeffs, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"coeffs must have shape (n*n, 3), got {c.shape}")
    order = order_from_size(c.shape[0])
    if not np.all(np.isfinite(c)):
        raise ValueError("coeffs contain NaN or inf")
    return write_asset(
        path,
        KIND,
        {"coeffs": c},
        sh_order=order,
        attrs={"source": str(source)},
        inputs=inputs,
        parameters=parameters,
    )


def read_light(path: str | os.PathLike) -> tuple[np.ndarray, dict]:
    """Read and validate a ``light`` asset.

    Returns
    -------
    coeffs : ndarray, shape (n*n, 3)
        RGB radiance SH coefficients (float64).
    attrs : dict
        Root attributes (``sh_order``, ``source``, ``parameters``, ``inputs``, ...).
    """
    asset = read_asset(path, KIND)
    return np.asarray(asset.data["coeffs"], dtype=np.float64), asset.attrs


def check_light_window(attrs: Mapping[str, Any], window: str | None, path, what: str) -> None:
    """Refuse a light projected with a window of its own that shading windows again.

    The runtime windows the light with the shading's ``window`` setting; a
    light projected with ``--window`` would be windowed twice.

    Parameters
    ----------
    attrs : mapping
        The light's root attributes (:func:`read_light`).
    window : str or None
        The shading's window setting.
    path : path-like
        The light, named in the error.
    what : str
        Where ``window`` is set, e.g. ``"the scene's settings.window"``.

    Raises
    ------
    AssetError
    """
    own = (attrs.get("parameters") or {}).get("window") or "none"
    if own != "none" and window is not None:
        raise AssetError(f"light was projected with --window {own} and {what} is "
                         f"'{window}', so the bake would window it twice; re-project it "
                         "without --window (the bake windows lighting and visibility "
                         "together) or set window = \"none\"", path)
