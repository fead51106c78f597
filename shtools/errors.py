"""Errors that the command line reports as one line: ``error: <file>: <what to do>``.

Library code raises :class:`ShtoolsError` (or a subclass) for anything a user can
fix — a bad file, a bad parameter.  The CLI turns it into one line on stderr and a
non-zero exit; any other exception is a bug and shows a traceback only with
``--debug``.
"""

from __future__ import annotations

import os


class ShtoolsError(Exception):
    """A user-fixable problem, optionally tied to a file.

    Parameters
    ----------
    message : str
        What is wrong and what to do about it, in one sentence.
    path : str or os.PathLike, optional
        The file the problem is about; shown before the message.
    """

    def __init__(self, message: str, path: str | os.PathLike | None = None):
        self.message = str(message)
        self.path = None if path is None else os.fspath(path)
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message as the CLI prints it (without the ``error:`` prefix)."""
        text = " ".join(self.message.split())
        return f"{self.path}: {text}" if self.path else text


class AssetError(ShtoolsError):
    """An HDF5 asset is missing, unreadable, of the wrong kind or version, or malformed."""


class InputError(ShtoolsError):
    """An input file (mesh, image, scene) or parameter cannot be used."""
