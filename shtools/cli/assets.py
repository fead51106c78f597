"""``shtools info`` / ``check`` / ``diff``: inspect, validate and compare assets.

``diff`` is the CI regression tool: it compares every dataset of two assets of
the same kind with ``|a - b| <= atol + rtol * |b|`` (B is the reference, e.g. the
golden file), ignores provenance that legitimately differs between builds
(``generator``; ``inputs`` unless ``--inputs``), reports shape, dtype, kind and
parameter mismatches, prints the worst differences and exits 1 when anything is
outside tolerance.
"""

from __future__ import annotations

import click

from shtools.cli._common import InputPath, json_option, option_type, report
from shtools.data_formats import read_asset
from shtools.data_formats.compare import compare_assets, frame_numbers, short, summarize_asset
from shtools.errors import AssetError


def _asset_arg(name):
    return click.argument(name, type=InputPath())


# ---------------------------------------------------------------------------- info


@click.command()
@_asset_arg("asset")
@json_option
def info(asset, as_json):
    """Summarise ASSET: kind, version, provenance and every dataset.

    The file is validated first; an invalid file is an error (see `shtools check`).
    """
    summary = summarize_asset(asset)
    report(summary, as_json, _format_info(summary))


def _format_info(s: dict) -> str:
    lines = [f"{s['path']}: shtools/{s['kind']} version {s['version']}"]
    attrs = s["attributes"]
    if "sh_order" in attrs:
        lines.append(f"  SH order      {attrs['sh_order']} ({attrs.get('sh_convention', '?')})")
    lines.append(f"  generator     {attrs.get('generator', '?')}")
    inputs = attrs.get("inputs") or {}
    lines.append("  inputs        " + (", ".join(
        f"{name} (sha256 {digest[:12]}…)" for name, digest in sorted(inputs.items())) or "none"))
    params = attrs.get("parameters") or {}
    lines.append("  parameters    " + (", ".join(
        f"{k}={short(v)}" for k, v in sorted(params.items())) or "none"))
    extra = {k: v for k, v in attrs.items() if k not in _STANDARD_ATTRS}
    for k, v in sorted(extra.items()):
        lines.append(f"  {k:<13} {short(v)}")
    lines.append(f"  datasets ({len(s['datasets'])}):")
    width = max((len(d["name"]) for d in s["datasets"]), default=4)
    for d in s["datasets"]:
        shape = str(tuple(d["shape"]))
        rng = ""
        if d.get("min") is not None:
            rng = f"  range [{d['min']:.6g}, {d['max']:.6g}]"
        if d.get("nonfinite"):
            rng += f"  {d['nonfinite']} non-finite"
        lines.append(f"    {d['name']:<{width}}  {shape:<16} {d['dtype']:<8}{rng}")
    return "\n".join(lines)


_STANDARD_ATTRS = {"format", "format_version", "sh_order", "sh_convention", "generator",
                   "inputs", "parameters"}


# --------------------------------------------------------------------------- check


@click.command()
@_asset_arg("asset")
@json_option
def check(asset, as_json):
    """Validate ASSET; exit 1 with the one-line reason when it is not usable."""
    a = read_asset(asset, load=False)
    summary = {"path": asset, "kind": a.kind, "version": a.version, "valid": True}
    report(summary, as_json, f"{asset}: ok (shtools/{a.kind} version {a.version})")


# ---------------------------------------------------------------------------- diff


@click.command()
@_asset_arg("a")
@_asset_arg("b")
@click.option("--rtol", type=option_type("tolerance"), default=1e-5, show_default=True,
              help="Relative tolerance, relative to B (the reference).")
@click.option("--atol", type=option_type("tolerance"), default=1e-8, show_default=True,
              help="Absolute tolerance.")
@click.option("--inputs", "compare_inputs", is_flag=True,
              help="Also require the recorded input hashes to match.")
@click.option("--ignore", "ignore", multiple=True, metavar="NAME",
              help="Ignore a dataset, root attribute or parameter key (repeatable).")
@click.option("--rel-rmse", "rel_rmse", type=option_type("tolerance"), default=None,
              metavar="R", help="Also require every dataset's relative RMSE "
              "||a - b|| / ||b|| to be <= R (e.g. for baked radiance).")
@click.option("--show", type=option_type("show"), default=10, show_default=True,
              help="How many of the worst differing elements to print.")
@click.option("--frames", "frames_text", metavar="A:B[:S]", default=None,
              help="Bake assets: compare only these scene frames (both must hold them).")
@json_option
def diff(a, b, rtol, atol, rel_rmse, compare_inputs, ignore, show, frames_text, as_json):
    """Compare assets A and B dataset by dataset (B is the reference).

    An element passes when |a - b| <= atol + rtol*|b|; NaN equals NaN.  The
    generator version is ignored, provenance (input hashes, input file names
    in the parameters) too unless --inputs.  Exit 0 when everything is within
    tolerance, 1 otherwise.
    """
    frames = None if frames_text is None else frame_numbers(frames_text)
    result = compare_assets(a, b, rtol=rtol, atol=atol, compare_inputs=compare_inputs,
                            ignore=set(ignore), worst=show, rel_rmse=rel_rmse, frames=frames)
    report(result, as_json, _format_diff(result))
    if not result["equal"]:
        n_out = sum(d.get("outside", 0) or 0 for d in result["datasets"])
        n_prob = len(result["problems"])
        n_rmse = sum(d["status"].startswith("relative RMSE") for d in result["datasets"])
        what = [f"{n_out} value(s) outside tolerance"] if n_out else []
        what += [f"{n_rmse} dataset(s) above the relative RMSE limit"] if n_rmse else []
        what += [f"{n_prob} structural/attribute difference(s)"] if n_prob else []
        raise AssetError(f"differs from {b}: {', '.join(what)} (details on stdout)", a)


def _format_diff(r: dict) -> str:
    lines = []
    verdict = "within tolerance" if r["equal"] else "DIFFERENT"
    lines.append(f"{r['a']} vs {r['b']} (reference): {verdict} "
                 f"(rtol {r['rtol']:g}, atol {r['atol']:g})")
    for problem in r["problems"]:
        lines.append(f"  ! {problem}")
    if r["datasets"]:
        width = max(len("dataset"), *(len(d["name"]) for d in r["datasets"]))
        lines.append(f"  {'dataset':<{width}}  {'shape':<14} {'max abs':>10} {'max rel':>10} "
                     f"{'rel RMSE':>10} {'outside':>9}  status")
        for d in r["datasets"]:
            shape = str(tuple(d["shape"])) if "shape" in d else "-"
            lines.append(
                f"  {d['name']:<{width}}  {shape:<14} {_num(d.get('max_abs')):>10} "
                f"{_num(d.get('max_rel')):>10} {_num(d.get('rel_rmse')):>10} "
                f"{d.get('outside', '-'):>9}  {d['status']}"
            )
    if r["worst"]:
        lines.append("  worst differences (most outside tolerance first):" if not r["equal"] else
                     "  largest differences (all within tolerance):")
        width = max(len(w["dataset"]) for w in r["worst"])
        for w in r["worst"]:
            idx = "[" + ",".join(map(str, w["index"])) + "]"
            lines.append(
                f"    {w['dataset']:<{width}} {idx:<14} a={w['a']:<12.7g} b={w['b']:<12.7g} "
                f"abs={w['abs']:.3g} rel={w['rel']:.3g}"
            )
    return "\n".join(lines)


def _num(v) -> str:
    if v is None:
        return "-"
    return f"{v:.3g}"
