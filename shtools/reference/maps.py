"""False-colour comparison maps of an evaluation (``shtools eval --png``; needs matplotlib)."""

from __future__ import annotations

import math

import numpy as np

#: What the maps show, with units: the radiance is in the light's own units (the
#: HDR probe's or the inline coefficients' radiance), linear.
RADIANCE_LABEL = "luminance of outgoing radiance\n(units of the light's radiance, linear)"
ERROR_LABEL = "method - mesh reference\n(same units)"


def write_comparison_png(path, vertices, out: dict) -> None:
    """Top view (x, z) of references and methods, radiance above and error below.

    Parameters
    ----------
    path : path-like
        PNG file, written atomically.
    vertices : ndarray, shape (V, 3)
        Receiver positions.
    out : dict
        :func:`shtools.reference.evaluation.evaluate`'s result.
    """
    import matplotlib.pyplot as plt

    from shtools.data_formats import atomic_path

    fig = comparison_figure(vertices, out)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)


def comparison_figure(vertices, out: dict):
    """The matplotlib figure of :func:`write_comparison_png`: one colour bar per row."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def lum(rgb):
        return rgb @ np.array([0.2126, 0.7152, 0.0722])

    panels = [("mesh (ray traced)", out["mesh_radiance"]),
              ("spheres (ray traced)", out["spheres_radiance"])]
    panels += [(r.method, r.radiance) for r in out["results"]]
    ref = lum(out["mesh_radiance"])
    vmax = max(float(np.percentile(lum(p), 99.5)) for _, p in panels) or 1.0
    emax = max(float(np.abs(lum(p) - ref).max()) for _, p in panels) or 1.0
    cols = len(panels)
    size = 2.6
    fig, axes = plt.subplots(2, cols, figsize=(size * cols + 1.6, 2 * size + 0.6),
                             squeeze=False, layout="constrained")
    x, z = vertices[:, 0], vertices[:, 2]
    dot = max(1.0, 4e4 / max(1, len(x)))
    for k, (name, rad) in enumerate(panels):
        ax = axes[0, k]
        top = ax.scatter(x, z, c=lum(rad), s=dot, marker="s", cmap="inferno", vmin=0,
                         vmax=vmax, linewidths=0)
        ax.set_title(name, fontsize=9)
        err = lum(rad) - ref
        ax2 = axes[1, k]
        bottom = ax2.scatter(x, z, c=err, s=dot, marker="s", cmap="coolwarm", vmin=-emax,
                             vmax=emax, linewidths=0)
        rms = math.sqrt(float(np.mean(err**2)) / max(float(np.mean(ref**2)), 1e-300))
        ax2.set_title(f"error vs mesh (rel. RMSE {rms:.3f})", fontsize=8)
        for a in (ax, ax2):
            a.set_aspect("equal")
            a.set_xticks([])
            a.set_yticks([])
    # one bar per row: every panel of a row shares its colour scale
    for row, mappable, label in ((0, top, RADIANCE_LABEL), (1, bottom, ERROR_LABEL)):
        bar = fig.colorbar(mappable, ax=axes[row, :].tolist(), shrink=0.9)
        bar.set_label(label, fontsize=8)
        bar.ax.tick_params(labelsize=7)
    return fig
