"""Helpers shared by the CLI commands: output option, JSON summaries, progress."""

from __future__ import annotations

import json
import sys

import click
import numpy as np

output_option = click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False, writable=True),
    help="Output file (written atomically).",
)
json_option = click.option(
    "--json", "as_json", is_flag=True, help="Print a machine-readable JSON summary on stdout."
)


def _default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def report(summary: dict, as_json: bool, human: str | None = None) -> None:
    """Print the stage summary: JSON on stdout with ``--json``, else a human line."""
    if as_json:
        click.echo(json.dumps(summary, indent=2, sort_keys=True, default=_default))
    elif human:
        click.echo(human)


def progress(iterable=None, *, total=None, desc=None):
    """A tqdm progress bar on stderr, shown only when stderr is a terminal."""
    from tqdm.auto import tqdm

    return tqdm(
        iterable, total=total, desc=desc, file=sys.stderr, disable=not sys.stderr.isatty(),
        leave=False,
    )


def setting_type(name: str, settings_cls=None) -> click.ParamType:
    """The click type (range or choice) of setting ``name``, from the settings schema.

    Options of a command that set a runtime setting use this, so the CLI accepts
    exactly what :class:`shtools.runtime.ShadowSettings` accepts.
    """
    from shtools.runtime.settings import ShadowSettings, limits_of

    cls = settings_cls or ShadowSettings
    lim = limits_of(cls, name)
    if lim.kind == "choice":
        return click.Choice(lim.choice_values())
    lo, hi = lim.lo, lim.hi
    if lo is None and lim.lo_field is not None:  # bounded by another setting: its own bound
        lo = limits_of(cls, lim.lo_field).lo
    if hi is None and lim.hi_field is not None:
        hi = limits_of(cls, lim.hi_field).hi
    if lim.kind == "int":
        return click.IntRange(lo, hi, min_open=lim.lo_open, max_open=lim.hi_open)
    if lim.kind == "float":
        return click.FloatRange(lo, hi, min_open=lim.lo_open, max_open=lim.hi_open)
    raise ValueError(f"setting {name!r} ({lim.kind}) has no command-line type")
