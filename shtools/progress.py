"""The progress protocol of long library stages (fits, trees, bakes, exports).

A long stage takes ``progress``: a factory called as
``progress(iterable=None, *, total=None, desc=None, unit="it")`` that returns a
tqdm-like object (``update(n)``, ``set_postfix(...)``, ``close()``, usable as a
context manager and, given an iterable, as an iterator).  The library never
decides how progress is shown: the CLI passes
:func:`shtools.cli._common.progress` (a bar on a terminal, a log line every
~10 s otherwise, nothing with ``--quiet``); Python callers pass their own or
nothing, which is :func:`silent`.
"""

from __future__ import annotations


def silent(iterable=None, *, total=None, desc=None, unit="it"):
    """A progress object that shows nothing (the library's default)."""
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=True)
