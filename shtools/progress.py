"""The progress protocol of long library stages (fits, trees, bakes, exports).

A long stage takes ``progress``: a factory called as
``progress(iterable=None, *, total=None, desc=None, unit="it")`` that returns a
tqdm-like object (``update(n)``, ``set_postfix(...)``, ``close()``, the ``n``
and ``total`` counters, usable as a context manager and, given an iterable, as
an iterator).  The library never decides how progress is shown: the CLI passes
:func:`shtools.cli._common.progress` (a tqdm bar on a terminal, a log line
every ~10 s otherwise, nothing with ``--quiet``); Python callers pass their own
(``tqdm.tqdm`` itself fits) or nothing, which is :func:`silent`.

This module needs nothing beyond the standard library: tqdm comes with the
``cli`` extra only, and the stages of the other extras (``geometry``: sphere
fits and trees) run without it.
"""

from __future__ import annotations


class Silent:
    """A progress object that shows nothing and counts (what :func:`silent` returns)."""

    def __init__(self, iterable=None, *, total=None, desc=None, unit="it"):
        self.iterable = iterable
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)
        self.total, self.desc, self.unit, self.n = total, desc, unit, 0

    def __iter__(self):
        for item in self.iterable if self.iterable is not None else ():
            yield item
            self.n += 1

    def __len__(self) -> int:
        return int(self.total or 0)

    def update(self, n: float = 1) -> None:
        self.n += n

    def set_postfix(self, *args, **kwargs) -> None:
        """Accepted and ignored, as tqdm's with ``disable=True``."""

    def set_description(self, desc=None, refresh=True) -> None:
        self.desc = desc

    def close(self) -> None:
        """Nothing to release."""

    def __enter__(self) -> Silent:
        return self

    def __exit__(self, *exc) -> bool:
        return False


def silent(iterable=None, *, total=None, desc=None, unit="it") -> Silent:
    """A progress object that shows nothing (the library's default)."""
    return Silent(iterable, total=total, desc=desc, unit=unit)
