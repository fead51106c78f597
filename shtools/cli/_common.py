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
