"""Errors that the command line reports as one line: ``error: <file>: <what to do>``.

Library code raises :class:`ShtoolsError` (or a subclass) for anything a user can
fix — a bad file, a bad parameter.  The CLI turns it into one line on stderr and a
non-zero exit; any other exception is a bug and shows a traceback only with
``--debug``.
"""

from __future__ import annotations

import errno
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


#: errno values that mean "the disk cannot take the output" -> what to tell the user.
DISK_ERRORS = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EROFS: "the file system is read-only",
    errno.EFBIG: "file too large for the file system (or the process's file-size limit)",
}


def disk_error_reason(exc: BaseException | None) -> str | None:
    """The reason when ``exc`` (or an exception it wraps) is a disk-full-like OSError.

    h5py reports the C library's errno only in its message text
    (``"... errno = 28, error message = 'No space left on device'"``), so the
    text is searched too.
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError):
            if exc.errno in DISK_ERRORS:
                return DISK_ERRORS[exc.errno]
            text = str(exc)
            for code, reason in DISK_ERRORS.items():
                if f"errno = {code}," in text or os.strerror(code) in text:
                    return reason
        exc = exc.__cause__ or exc.__context__
    return None
