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


class Deferred(Silent):
    """A progress object that makes the real one only once its stage has lasted ``delay``.

    Counts as :class:`Silent` until an update arrives ``delay`` seconds after it
    was made; then it calls ``factory(total=, desc=, unit=)``, passes it the count
    so far and forwards every later call.  A stage shorter than ``delay`` shows
    nothing and never calls the factory, so it imports nothing of it (tqdm, for
    the CLI's :func:`shtools.cli._common.progress`, costs more than relighting a
    small bake).  A bar shown its first ``delay`` seconds would only flicker.

    Parameters
    ----------
    factory : callable
        A progress factory (this module's protocol).
    delay : float
        Seconds.
    clock : callable
        Seconds now (``time.monotonic``).
    """

    def __init__(self, factory, delay: float, iterable=None, *, total=None, desc=None,
                 unit="it", clock=None):
        import time

        super().__init__(iterable, total=total, desc=desc, unit=unit)
        self.factory, self.delay = factory, float(delay)
        self.clock = clock or time.monotonic
        self.start = self.clock()
        self.bar = None
        self.postfix: tuple | None = None

    def __iter__(self):
        for item in self.iterable if self.iterable is not None else ():
            yield item
            self.update(1)

    def update(self, n: float = 1) -> None:
        self.n += n
        if self.bar is not None:
            self.bar.update(n)
        elif self.clock() - self.start >= self.delay:
            self.bar = self.factory(total=self.total, desc=self.desc, unit=self.unit)
            if self.postfix is not None:
                self.bar.set_postfix(*self.postfix[0], **self.postfix[1])
            self.bar.update(self.n)

    def set_postfix(self, *args, **kwargs) -> None:
        self.postfix = (args, kwargs)
        if self.bar is not None:
            self.bar.set_postfix(*args, **kwargs)

    def set_description(self, desc=None, refresh=True) -> None:
        self.desc = desc
        if self.bar is not None:
            self.bar.set_description(desc, refresh)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def __exit__(self, *exc) -> bool:
        if self.bar is not None:
            return bool(self.bar.__exit__(*exc))
        return False


def deferred(factory, delay: float = 1.0):
    """The progress factory of :class:`Deferred` objects: ``factory`` once a stage has
    lasted ``delay`` seconds."""
    def make(iterable=None, *, total=None, desc=None, unit="it") -> Deferred:
        return Deferred(factory, delay, iterable, total=total, desc=desc, unit=unit)

    return make
