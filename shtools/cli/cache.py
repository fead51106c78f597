"""``shtools cache info|clear``: the set-up cache (:mod:`shtools.cache`), and the
``--cache DIR`` / ``--no-cache`` options of the commands that use it."""

from __future__ import annotations

import click

from shtools.cli._common import json_option, report


class CacheFolder(click.Path):
    """``--cache DIR``: a folder path, not empty (the current folder), not a file; with
    ``writable`` (``cache clear``) one this user can write, or create (its nearest
    existing parent is writable), refused while the options are parsed.  A bake's cache
    is not required to be writable: the bake goes on without it, with one warning
    (docs/cache.md)."""

    def __init__(self, writable: bool = False):
        super().__init__(file_okay=False)
        self.needs_write = writable

    def convert(self, value, param, ctx):
        import os
        from pathlib import Path

        if not str(value).strip():
            self.fail("is empty; give a cache folder", param, ctx)
        value = super().convert(value, param, ctx)
        if self.needs_write:
            folder = Path(value).expanduser().absolute()
            try:
                while not folder.exists() and folder != folder.parent:
                    folder = folder.parent
            except OSError as exc:  # a parent this user may not enter
                self.fail(f"cannot reach '{folder}' ({exc.strerror}); choose a folder you "
                          "can write or pass --no-cache", param, ctx)
            if not folder.is_dir():
                self.fail(f"'{value}' lies under '{folder}', which is not a folder", param, ctx)
            if not os.access(folder, os.W_OK | os.X_OK):
                self.fail(f"cannot write to '{folder}' (read-only or no permission); choose "
                          "a writable folder or pass --no-cache", param, ctx)
        return value


def cache_options(f):
    """``--cache DIR`` and ``--no-cache`` (passed as ``cache_dir`` and ``no_cache``)."""
    f = click.option("--no-cache", is_flag=True,
                     help="Compute the set-up (self-visibility, fits, projected images) "
                          "without reading or writing the set-up cache; same bytes.")(f)
    return click.option("--cache", "cache_dir", metavar="DIR", type=CacheFolder(),
                        default=None,
                        help="Set-up cache folder (default: $SHTOOLS_CACHE, else "
                             "$XDG_CACHE_HOME/shtools, else ~/.cache/shtools).")(f)


def _warn(message: str) -> None:
    click.echo(f"warning: {message}", err=True)


def open_cache(cache_dir, no_cache: bool = False):
    """The :class:`~shtools.cache.SetupCache` the options name (warnings on stderr)."""
    from shtools.cache import SetupCache

    if cache_dir is None:
        cache = SetupCache.from_environment(warn=_warn)
    else:
        cache = SetupCache(cache_dir, warn=_warn)
    if no_cache:
        cache.enabled = False
    return cache


@click.group("cache")
def cache():
    """The set-up cache: what bakes compute before their frames, kept by content.

    A second bake of unchanged inputs reads its set-up (exact self-visibility,
    sphere fits, projected environment images) from here.  Location:
    $SHTOOLS_CACHE, else $XDG_CACHE_HOME/shtools, else ~/.cache/shtools; size
    bound $SHTOOLS_CACHE_SIZE (default 2G, least recently used entries go
    first); SHTOOLS_NO_CACHE=1 or `bake --no-cache` turn it off.
    """


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"  # pragma: no cover


@cache.command("info")
@click.option("--cache", "cache_dir", metavar="DIR", type=CacheFolder(),
              default=None, help="Cache folder (default: as `shtools bake` uses).")
@json_option
def info(cache_dir, as_json):
    """Location, size and entries of the set-up cache."""
    summary = open_cache(cache_dir).info()
    kinds = ", ".join(f"{n} {k}" for k, n in summary["kinds"].items())
    report(summary, as_json,
           f"{summary['location']}: {summary['entries']} entries"
           f"{f' ({kinds})' if kinds else ''}, {_size(summary['bytes'])} of at most "
           f"{_size(summary['max_bytes'])}"
           f"{'' if summary['enabled'] else ' (off: SHTOOLS_NO_CACHE is set)'}")


@cache.command("clear")
@click.option("--cache", "cache_dir", metavar="DIR", type=CacheFolder(writable=True),
              default=None, help="Cache folder (default: as `shtools bake` uses).")
@json_option
def clear(cache_dir, as_json):
    """Remove every entry of the set-up cache."""
    c = open_cache(cache_dir)
    removed = c.clear()
    report({"location": str(c.location), "removed": removed}, as_json,
           f"removed {removed} entries from {c.location}")
