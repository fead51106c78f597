"""Refuse unusable output paths before any work: one call at the top of a command.

Every command that writes files calls :func:`guard_outputs` first, with EVERY
path it will write -- the ``-o`` file and its companions (a VAT's ``.glb`` and
``.pos.exr``, a numbered sequence ``NAME.0000.glb``) -- and every file it reads
(for ``bake``: the scene *and* the files the scene names)::

    from shtools.cli._outputs import guard_outputs, planned

    guard_outputs({"-o": output, "--plot": plot_path}, inputs=[mesh_path])
    guard_outputs(planned("-o", output, files), inputs=[baked])  # companions too

It raises :class:`~shtools.errors.InputError` (one line naming the output) when
an output

* is empty (``-o ''``), an existing folder, an existing device, pipe or socket
  (the atomic rename would replace ``/dev/null`` by a file), or a name longer
  than 255 bytes;
* is the same file as an input (``os.path.samefile`` where both exist, the
  resolved path otherwise) — writing it would destroy the input;
* is the same file as another output (``tables log --plot`` equal to ``-o``);
* exists and cannot be written by this user (a read-only file: the atomic
  rename would silently replace it);
* lies in a folder that does not exist or that this process cannot write
  (read-only mount, no permission) — found in a second, not after minutes of
  fitting.

``None`` outputs (an option that was not given) are skipped.  The check is a
guard, not a lock: the atomic writer (:func:`shtools.data_formats.atomic_path`)
still writes beside the target and renames, so a failure later leaves no file.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path

from shtools.errors import InputError


def planned(option: str, output: str | os.PathLike,
            files: Iterable[str | os.PathLike]) -> dict[str, Path]:
    """The outputs of an option that writes several files, labelled for :func:`guard_outputs`.

    Parameters
    ----------
    option : str
        The option naming the files (``"-o"``).
    output : path-like
        The path the user gave.
    files : iterable of path-like
        Every file the command will write for it (e.g. the planning function of
        ``export``, :func:`shtools.export.writer.output_files`), ``output`` itself
        included when it is written.

    Returns
    -------
    dict of str to Path
        ``{"-o": output, "-o (companion v.glb)": ...}`` in the order given.
    """
    out: dict[str, Path] = {}
    for f in files:
        f = Path(f)
        label = option if f == Path(output) else f"{option} (companion {f.name})"
        out.setdefault(label, f)
    return out


def guard_outputs(outputs: Mapping[str, str | os.PathLike | None],
                  inputs: Iterable[str | os.PathLike | None] = ()) -> None:
    """Check that every output can be written and harms no input (see module docstring).

    Parameters
    ----------
    outputs : mapping of str to path-like or None
        Option name (``"-o"``, ``"--plot"``) -> path it will write; ``None`` skipped.
    inputs : iterable of path-like or None
        Every file the command reads; ``None`` entries are skipped.

    Raises
    ------
    InputError
        The first problem found, naming the output path (or the option when empty).
    """
    from shtools.data_formats._base import same_file

    ins = [Path(p) for p in inputs if p is not None and os.fspath(p) != ""]
    seen: list[tuple[str, Path]] = []
    for option, value in outputs.items():
        if value is None:
            continue
        text = os.fspath(value)
        if not text.strip():
            raise InputError(f"{option} is empty; give an output file name")
        out = Path(text)
        if len(out.name.encode()) > 255:
            raise InputError(f"the file name is longer than 255 bytes; shorten {option}", out)
        if out.is_dir():
            raise InputError(f"is a folder; {option} needs a file name", out)
        if out.exists() and not out.is_file():
            # the atomic rename would replace a device (/dev/null) or a pipe by a file
            raise InputError(f"is not a regular file (a device, pipe or socket); {option} "
                             "needs a file path", out)
        if out.exists() and not os.access(out, os.W_OK):
            raise InputError(f"exists and is read-only; make it writable (chmod u+w) or "
                             f"choose another {option} path", out)
        for src in ins:
            if same_file(out, src):
                raise InputError(f"is also an input ({src}); writing it would destroy the "
                                 f"input, choose another {option} path", out)
        for other_option, other in seen:
            if same_file(out, other):
                raise InputError(f"is given as both {other_option} and {option}; give two "
                                 "different files", out)
        folder = out.parent if str(out.parent) else Path(".")
        if not folder.is_dir():
            raise InputError("output folder does not exist; create it first", out)
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"cannot write to the output folder '{folder}' (read-only or no "
                             "permission); choose a writable folder", out)
        seen.append((option, out))
