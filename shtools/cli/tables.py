"""``shtools tables``: precomputed tables the runtime needs (``tables log``, ``tables scaling``)."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

import click

from shtools.cli._common import (
    json_option,
    option_error,
    option_type,
    output_option,
    report,
    setting_type,
)
from shtools.cli._limits import check_memory, force_option
from shtools.errors import InputError


@click.group()
def tables():
    """Precompute lookup tables (cap log and OL exponential tables, SH scaling matrices)."""


@tables.command("log")
@click.option("--order", "-n", type=setting_type("acc_order"),
              required=True, help="SH order n (the accumulation order of the runtime).")
@output_option
@click.option(
    "--samples",
    type=option_type("log_samples"),
    default=256,
    show_default=True,
    help="Number of cap radii theta in (0, pi/2].",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, writable=True),
    default=None,
    help="Also draw the OL a/b curves against ||f_hat|| (like Figure 3 of Ren et al. 2006) "
    "into this PNG.",
)
@json_option
def log_cmd(order, output, samples, plot_path, as_json):
    """Write the cap log tables and the OL tables for SH order N.

    The asset holds cap visibility (vis_zh) and its log by eigen-inversion
    (log_zh) over theta in (0, pi/2], and the OL tables ol_norm, ol_a, ol_b.
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats import atomic_path
    from shtools.data_formats.tables import TABLE_KEYS, write_tables
    from shtools.sh.tables import build_log_tables

    guard_outputs({"-o": output, "--plot": plot_path})
    if plot_path and Path(plot_path).suffix.lower() != ".png":
        raise InputError("--plot writes a PNG; give a file name ending in .png", plot_path)
    if plot_path and order < 2:
        raise option_error("--order 1 has no band above DC, so there are no OL curves to "
                           "plot; use --order 2 or more with --plot")
    start = time.perf_counter()
    built = build_log_tables(order, samples=samples)
    # both outputs or neither: the plot is drawn into its temporary file first and
    # renamed into place only after the asset was written
    with (atomic_path(plot_path) if plot_path else contextlib.nullcontext()) as plot_tmp:
        if plot_path:
            plot_ol_curves({**{k: built[k] for k in TABLE_KEYS}, "order": order}, plot_tmp,
                           atomic=False)
        write_tables(output, built, order, parameters={"samples": samples})
    seconds = time.perf_counter() - start
    summary = {
        "output": output,
        "order": order,
        "samples": samples,
        "theta_count": len(built["theta"]),
        "ol_count": len(built["ol_norm"]),
        "ol_norm_max": float(max(built["ol_norm"])) if len(built["ol_norm"]) else 0.0,
        "seconds": round(seconds, 3),
    }
    if plot_path:
        summary["plot"] = plot_path
    human = (
        f"wrote {output}: order {order}, {summary['theta_count']} cap radii, "
        f"{summary['ol_count']} OL samples (||f_hat|| up to {summary['ol_norm_max']:.2f}) "
        f"in {seconds:.2f} s"
    )
    if plot_path:
        human += f"; plot {plot_path}"
    report(summary, as_json, human)


@tables.command("scaling")
@click.option("--order", "-n", type=option_type("scaling_order"), required=True, help="SH order n.")
@click.option("--function", "function", type=click.Choice(["cone", "midrange"]),
              required=True,
              help="Angular map: 'cone' (deformable shadow fields, k = d/r) or 'midrange' "
              "(environment on a sphere of radius R, k = d/R).")
@click.option("--alpha", "alpha_deg", type=option_type("alpha_deg"), default=45.0,
              show_default=True,
              help="Cone half-angle in degrees (cone only; Wang et al. use 45).")
@click.option("--energy-preserving", is_flag=True,
              help="Energy-preserving scaling (Lambda = sin(phi) phi', keeps the integral).")
@click.option("--samples", type=option_type("scaling_samples"), default=40, show_default=True,
              help="Number K of sampled k.")
@click.option("--k-range", nargs=2, type=option_type("k"), default=None, metavar="LO HI",
              help="Sampled k range [default: 0.125 8 for cone, 0 0.95 for midrange].")
@click.option("--interpolation", type=click.Choice(["linear", "linear-log-k"]),
              default="linear", show_default=True,
              help="Rule in k between samples, recorded for the reader (log-k: cone only).")
@click.option("--nodes", type=option_type("nodes"), default=None,
              help="Gauss-Legendre nodes in theta per matrix entry [default: 400, doubled "
              "until the estimated error is below 1e-12].")
@output_option
@force_option("4 GiB of memory")
@json_option
def scaling_cmd(order, function, alpha_deg, energy_preserving, samples, k_range,
                interpolation, nodes, output, force, as_json):
    """Write SH scaling matrices M(k) sampled in k (Wang et al. 2005).

    Each M(k) keeps m; the asset stores its n(2n^2+1)/3 allowed entries per k,
    computed by 1-D Gauss-Legendre integrals in theta, with the quadrature error
    estimated against twice the nodes.
    """
    import math

    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats.scaling import write_scaling
    from shtools.sh.scaling import (
        build_scaling_table,
        check_alpha,
        check_interpolation,
        k_samples,
    )

    guard_outputs({"-o": output})
    if k_range is not None and not k_range[0] < k_range[1]:
        raise option_error(f"--k-range {k_range[0]:g} {k_range[1]:g} is inverted or empty; "
                           "give LO < HI")
    # the library's own rules, before any work, each refused as its option
    alpha = math.radians(alpha_deg)
    checks = [("--interpolation " + interpolation,
               lambda: check_interpolation(function, interpolation))]
    if k_range is not None:
        checks.append((f"--k-range {k_range[0]:g} {k_range[1]:g}",
                       lambda: k_samples(function, samples, *k_range)))
    if function == "cone":  # (a tiny --alpha is 0 in radians)
        checks.append((f"--alpha {alpha_deg:g}", lambda: check_alpha(alpha)))
    for option, check in checks:
        try:
            check()
        except ValueError as exc:
            raise option_error(f"{option}: {exc}") from None
    _check_scaling_memory(order, samples, nodes, force, output)
    start = time.perf_counter()
    table = build_scaling_table(
        order, function, alpha=alpha, energy_preserving=energy_preserving,
        samples=samples, k_range=None if k_range is None else tuple(k_range),
        interpolation=interpolation, nodes=nodes,
    )
    params = {"order": order, "function": function, "energy_preserving": energy_preserving,
              "samples": samples, "k_range": [float(table["k"][0]), float(table["k"][-1])],
              "interpolation": interpolation, "nodes": table["quadrature_nodes"]}
    if function == "cone":
        params["alpha_degrees"] = alpha_deg
    write_scaling(output, table, parameters=params)
    seconds = time.perf_counter() - start
    summary = {"output": output, **params, "k_spacing": table["k_spacing"],
               "entries": len(table["rows"]), "quadrature_error": table["quadrature_error"],
               "out_of_range": table["out_of_range"], "seconds": round(seconds, 3)}
    human = (f"wrote {output}: order {order} {function}"
             f"{f' alpha {alpha_deg:g} deg' if function == 'cone' else ''}"
             f"{' energy-preserving' if energy_preserving else ''}, {samples} k in "
             f"[{table['k'][0]:g}, {table['k'][-1]:g}] ({table['k_spacing']}), "
             f"{len(table['rows'])} entries, quadrature error {table['quadrature_error']:.1e} "
             f"in {seconds:.2f} s")
    report(summary, as_json, human)


def _check_scaling_memory(order: int, samples: int, nodes: int | None, force: bool,
                          output) -> None:
    """Refuse a scaling table past the memory limit (:mod:`shtools.cli._limits`).

    Each quadrature pass holds, per sampled k and node, the Legendre parts of
    the n^2 coefficients and of the n(2n^2+1)/3 pattern entries (float64), about
    twice over while they are combined; the estimate takes the error check's
    pass at twice the starting nodes (the automatic doubling can go higher).
    """
    from shtools.sh.scaling import DEFAULT_NODES

    q = 2 * (nodes or DEFAULT_NODES)
    entries = order * (2 * order * order + 1) // 3
    nbytes = 2 * samples * q * (order * order + entries) * 8
    check_memory("tables scaling", nbytes,
                 f"{samples} samples x {q} quadrature nodes x {order * order + entries} "
                 "values x 16 bytes", "lower --samples, --nodes or --order", force=force,
                 path=output)


#: ||f_hat|| up to which the paper finds OL accurate at order 4 (Section 4.2).
OL_ACCURATE_NORM = 4.8


def cap_ol_points(tab: dict):
    """Per-cap (||f_hat||, a, b) by eq. 24, straight from ``vis_zh``/``log_zh``.

    Parameters
    ----------
    tab : dict
        As :func:`shtools.data_formats.tables.read_tables` returns.

    Returns
    -------
    norm, a, b : ndarray, shape (T,)
    """
    import numpy as np

    order = tab["vis_zh"].shape[1]
    l = np.arange(order)
    unscale = np.sqrt((2 * l + 1) / (4 * np.pi))  # g_l = g*_l sqrt((2l+1)/4pi)
    g = tab["vis_zh"] * unscale
    f = tab["log_zh"] * unscale
    # Coefficient vectors are zh_l * y_lm(s); summing over m gives the zonal dot products
    # weighted by 1 (sum_m y_lm(s)^2 (4pi/(2l+1)) = 1 after the unscaling above).
    dc = np.exp(-f[:, 0] / np.sqrt(4 * np.pi))
    a = dc * g[:, 0] / np.sqrt(4 * np.pi)
    ff = np.sum(f[:, 1:] ** 2, axis=1)
    norm = np.sqrt(ff)
    with np.errstate(invalid="ignore", divide="ignore"):
        b = dc * np.sum(g[:, 1:] * f[:, 1:], axis=1) / ff
    return norm, a, b


def plot_ol_curves(tab: dict, path, *, atomic: bool = True) -> None:
    """Draw the OL coefficients a and b against ||f_hat|| (cf. Ren et al. 2006, Fig. 3).

    Lines are the tabulated ``ol_a``/``ol_b``; dots are eq. 24 evaluated on each
    cap of the cap tables, with the cap radius on a secondary axis.  Written as a
    PNG, atomically unless ``atomic=False`` (``path`` is then already a temporary).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from shtools.data_formats import atomic_path

    order = int(tab["order"])
    norm, a, b = cap_ol_points(tab)
    fig, (ax, ax_theta) = plt.subplots(
        2, 1, figsize=(7.5, 6.2), height_ratios=(3, 1.2), sharex=True, layout="constrained"
    )
    ax.plot(tab["ol_norm"], tab["ol_a"], color="tab:blue", lw=2, label="a  (table ol_a)")
    ax.plot(tab["ol_norm"], tab["ol_b"], color="tab:red", lw=2, label="b  (table ol_b)")
    step = max(1, len(norm) // 40)
    ax.plot(norm[::step], a[::step], "o", ms=3.5, mfc="none", color="tab:blue",
            label="a of single caps (eq. 24)")
    ax.plot(norm[::step], b[::step], "s", ms=3.5, mfc="none", color="tab:red",
            label="b of single caps (eq. 24)")
    ax.axhline(1.0, color="0.6", lw=0.8, ls=":", label="two-term series 1 + f (a = b = 1)")
    xmax = float(max(np.nanmax(tab["ol_norm"]), np.nanmax(norm)))
    if OL_ACCURATE_NORM < xmax:
        for axis in (ax, ax_theta):
            axis.axvline(OL_ACCURATE_NORM, color="0.3", lw=0.8, ls="--")
        ax.text(OL_ACCURATE_NORM, 0.98,
                r"OL accurate for $\|\hat{\mathbf{f}}\| < 4.8$ (order 4, paper)  ",
                transform=ax.get_xaxis_transform(), va="top", ha="right", fontsize=8,
                color="0.3")
    ax.set_ylabel("OL coefficient")
    ax.set_title(f"Optimal linear (OL) exponential coefficients, SH order {order}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", framealpha=0.9)
    ax_theta.plot(norm, np.degrees(tab["theta"]), color="0.2")
    ax_theta.set_ylabel("cap radius (deg)")
    ax_theta.set_xlabel(
        r"$\|\hat{\mathbf{f}}\|$  (norm of the cap's log vector without its DC term)"
    )
    ax_theta.grid(alpha=0.3)
    ax_theta.set_xlim(0, xmax * 1.02)
    try:
        with atomic_path(path) if atomic else contextlib.nullcontext(path) as tmp:
            fig.savefig(tmp, dpi=130, format="png")
    finally:
        plt.close(fig)
