"""Helpers shared by the CLI commands: output option, JSON summaries, progress."""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import sys

import click
import numpy as np

from shtools import field_limits
from shtools.cli._limits import ImageSize

output_option = click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False, writable=True),
    help="Output file (written atomically).",
)
class InputPath(click.Path):
    """A file the command reads: not a folder, not an empty string (which would name the
    current folder); whether it exists and what it holds, its reader checks."""

    def __init__(self):
        super().__init__(dir_okay=False)

    def convert(self, value, param, ctx):
        if not str(value).strip():
            self.fail("is empty; give a file path", param, ctx)
        return super().convert(value, param, ctx)


json_option = click.option(
    "--json", "as_json", is_flag=True, help="Print a machine-readable JSON summary on stdout."
)


@contextlib.contextmanager
def naming(path):
    """A one-line error raised in the block without a file names ``path`` (the scene, the
    mesh): deep library code (a pose, a blocker) knows the object, not the file."""
    from shtools.errors import ShtoolsError

    try:
        yield
    except ShtoolsError as exc:
        if exc.path is not None or path is None:
            raise
        raise type(exc)(exc.message, path) from None


def errors_name(param: str):
    """Decorator of a command: a one-line error without a file names the file given as
    its parameter ``param`` (see :func:`naming`)."""
    def decorate(f):
        @functools.wraps(f)
        def wrapper(*args, **kwargs):
            with naming(kwargs.get(param)):
                return f(*args, **kwargs)
        return wrapper
    return decorate


def _checked_scheduler(ctx, param, value):
    """``--scheduler``: checked while the options are parsed, before anything starts."""
    from shtools.errors import InputError
    from shtools.tasks import check_scheduler

    try:
        check_scheduler(value)
    except InputError as exc:
        raise click.BadParameter(exc.one_line(), ctx, param) from None
    return value


def scheduler_options(unit: str):
    """``--scheduler`` and ``--workers`` of a stage whose ``unit`` (frames, shells,
    meshes) are independent tasks (:mod:`shtools.tasks`, docs/scale-out.md)."""
    from shtools.tasks import MAX_LOCAL_WORKERS

    def decorate(f):
        f = click.option(
            "--workers", type=click.IntRange(min=1, max=MAX_LOCAL_WORKERS), default=None,
            help=f"Local worker processes for {unit} (default: one per core; 1 = one after "
                 "the other in this process); with --scheduler local, the cluster's size.")(f)
        return click.option(
            "--scheduler", default=None, metavar="local|tcp://HOST:PORT|FILE",
            callback=_checked_scheduler,
            help=f"Run {unit} on Dask: 'local' starts a LocalCluster here, an address or a "
                 "scheduler file joins an existing cluster (pip install "
                 "'shtools[distributed]'; docs/scale-out.md).  Default: worker processes on "
                 "this machine's cores.")(f)
    return decorate


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


#: environment variables by which a user sets the BLAS thread count
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def one_blas_thread():
    """Limit BLAS to one thread for the block (threadpoolctl), unless the user set a count.

    shtools parallelises above BLAS (worker processes, passes over many small
    matrices), and threaded OpenBLAS spins on small products -- the demo bake
    took 32 s instead of 2.3 s with one other busy job on a 2-core machine.
    Forked worker processes inherit the limit.  Library code never changes it:
    only ``main()`` of the CLI and the demo call this.
    """
    if any(v in os.environ for v in BLAS_THREAD_VARIABLES):
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


#: Seconds between two progress log lines when stderr is not a terminal
#: (``SHTOOLS_PROGRESS_INTERVAL`` overrides it, e.g. for tests).
LOG_INTERVAL = 10.0

#: Set by ``shtools --quiet`` (or ``SHTOOLS_QUIET=1``): no progress output at all.
_quiet = False


def set_quiet(quiet: bool) -> None:
    """Silence (or re-enable) every progress bar and log line of this process."""
    global _quiet
    _quiet = bool(quiet)


def _log_class():
    from tqdm import tqdm

    class LogLines(tqdm):
        """tqdm that prints a whole line per display (for logs: no carriage returns).

        Nothing for a stage shorter than ``delay``; then at most one line per
        ``mininterval`` seconds as the work advances and a final one when it
        ends (not after an error, whose one line must stay the last), e.g.
        ``fit: 40/120 rounds (33%), 00:12 elapsed, ETA 00:24, objective=0.930``.
        """

        _failed = False

        def __exit__(self, exc_type, exc_value, traceback):
            self._failed = exc_type is not None
            return super().__exit__(exc_type, exc_value, traceback)

        def display(self, msg=None, pos=None):
            if msg == "":  # tqdm clearing the bar: nothing to clear in a log
                return False
            self.fp.write((msg if msg is not None else self.__str__()) + "\n")
            self.fp.flush()
            return True

        def close(self):
            # the final count: only after earlier lines, unless the last one showed it
            shown = getattr(self, "last_print_t", 0.0) >= self.start_t + self.delay
            if (not self.disable and not self._failed and shown
                    and getattr(self, "last_print_n", None) != self.n):
                self._ema_dt = lambda: None  # the final line shows the overall rate
                self.display()
            self.leave = False
            super().close()

        @property
        def format_dict(self):
            d = super().format_dict
            known = d["total"] is not None
            d["bar_format"] = (
                "{desc}: {n_fmt}/{total_fmt} {unit} ({percentage:.0f}%), {elapsed} elapsed, "
                "ETA {remaining}{postfix}" if known
                else "{desc}: {n_fmt} {unit}, {elapsed} elapsed{postfix}")
            return d

    return LogLines


def progress(iterable=None, *, total=None, desc=None, unit="it"):
    """Progress of a long stage on stderr: THE one place that decides how it shows.

    * stderr is a terminal: a tqdm bar with count, total, rate and ETA (cleared
      when done);
    * otherwise (Makefiles, CI, ``2> log``): a stage that lasts longer than
      :data:`LOG_INTERVAL` seconds prints a line every :data:`LOG_INTERVAL`
      seconds while it advances and one when it ends -- each with count/total,
      elapsed time and ETA (short stages stay silent);
    * ``shtools --quiet`` or ``SHTOOLS_QUIET=1``: nothing.

    Parameters and the returned object follow tqdm (``update``, ``set_postfix``,
    ``close``, context manager, iteration); library stages take this function
    as their ``progress`` argument (see :mod:`shtools.progress`).
    """
    import os

    from tqdm import tqdm

    quiet = _quiet or os.environ.get("SHTOOLS_QUIET", "") not in ("", "0")
    desc = desc or "working"
    if quiet:
        return tqdm(iterable, total=total, desc=desc, unit=unit, disable=True)
    if sys.stderr.isatty():
        return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr, leave=False,
                    dynamic_ncols=True)
    interval = float(os.environ.get("SHTOOLS_PROGRESS_INTERVAL", LOG_INTERVAL))
    return _log_class()(iterable, total=total, desc=desc, unit=unit, file=sys.stderr,
                        mininterval=interval, maxinterval=max(interval, 1e-3), miniters=1,
                        delay=interval, ascii=True)


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
    if lim.kind == "float":  # finite too (click's FloatRange lets nan through)
        return FiniteRange(lo, hi, min_open=lim.lo_open, max_open=lim.hi_open)
    raise ValueError(f"setting {name!r} ({lim.kind}) has no command-line type")


class FiniteRange(click.FloatRange):
    """A float option in a range that also refuses ``nan`` and ``inf`` (click accepts them)."""

    name = "finite number"

    def convert(self, value, param, ctx):
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


class PowerOfTwo(click.IntRange):
    """An integer option that must be a power of two, at least ``lo`` (and at most ``hi``)."""

    name = "power of two"

    def __init__(self, lo: int = 1, hi: int | None = None):
        super().__init__(max(1, lo), hi)

    def convert(self, value, param, ctx):
        # the range's own message would read "not in the range a power of two, x>=2"
        rv = click.INT.convert(value, param, ctx)
        if rv < self.min or (self.max is not None and rv > self.max) or rv & (rv - 1):
            top = "" if self.max is None else f" and <= {self.max}"
            lowest = 1 << max(0, self.min - 1).bit_length()  # the smallest allowed
            if rv < lowest:
                near = [lowest]
            elif self.max is not None and rv > self.max:
                near = [1 << (self.max.bit_length() - 1)]  # the largest allowed
            else:  # the powers of two on either side
                near = [x for x in (1 << (rv.bit_length() - 1), 1 << rv.bit_length())
                        if self.max is None or x <= self.max]
            hint = f" (e.g. {' or '.join(map(str, near))})" if near else ""
            self.fail(f"must be a power of two >= {self.min}{top}, got {rv}{hint}.",
                      param, ctx)
        return rv

    def _describe_range(self) -> str:
        return f"a power of two, {super()._describe_range()}"


def option_error(message: str) -> click.UsageError:
    """The error of an option's value (or of options given together) found after parsing.

    One line naming the option and what to give, exit 2 like a value refused while
    parsing -- never a file: a bad value is not the fault of the mesh read or the file
    written (:func:`naming` leaves it alone).  ``raise option_error("--k-range ...")``.
    """
    return click.UsageError(" ".join(str(message).split()))


@contextlib.contextmanager
def checking_options():
    """Library checks of option values in the block (e.g. ``FieldParameters.validate``)
    raise an :class:`~shtools.errors.InputError` without a file: refused as
    :func:`option_error` (an error naming a file is one about that file, and passes)."""
    from shtools.errors import InputError

    try:
        yield
    except InputError as exc:
        if exc.path is not None:
            raise
        raise option_error(exc.message) from None


#: The range of every numeric option that is not a runtime setting (those come from
#: the settings schema, :func:`setting_type`): one place, one finite check.
OPTION_TYPES: dict[str, click.ParamType] = {
    # exposure in stops: 2^60 ~ 1e18 keeps float32 radiance finite
    "exposure": FiniteRange(-60, 60),
    "elevation": FiniteRange(-90, 90),
    "azimuth": FiniteRange(-360, 360),
    # camera distance, scene units: within the scene's coordinate range (float32 runtime)
    "distance": FiniteRange(0, 1e18, min_open=True),
    "rotate_y": FiniteRange(-360, 360),
    "zoom": FiniteRange(0, 1000, min_open=True),
    "window_h": FiniteRange(0, 1000, min_open=True),
    "thickness": FiniteRange(0, None, min_open=True),
    # GIF frame delays are whole hundredths of a second: 100 fps at most
    "fps": FiniteRange(0.1, 100),
    "seed": click.IntRange(0, 2**32 - 1),
    "columns": click.IntRange(1, 1000),
    # an image's W H: sides >= 8, pixels limited (shtools.cli._limits.MAX_PIXELS)
    "size": ImageSize(),
    # sphere count: the fit itself says when N exceeds what the mesh's samples allow
    "count": click.IntRange(1, None),
    "level": click.IntRange(0, 64),
    # tables scaling: cone half-angle (only the cone uses it), sampled k, samples and
    # quadrature nodes
    "alpha_deg": FiniteRange(0, 90, min_open=True, max_open=True),
    "k": FiniteRange(0, 1e6),
    "scaling_order": click.IntRange(1, 16),
    "scaling_samples": click.IntRange(3, 10_000),
    "nodes": click.IntRange(8, 100_000),
    # tables log: cap radii
    "log_samples": click.IntRange(2, 100_000),
    # diff
    "tolerance": FiniteRange(0, None),
    "show": click.IntRange(0, 1000),
    # eval
    "grid": click.IntRange(2, 1024),
    "gap": FiniteRange(0, 100),
    "frame": click.IntRange(0, None),
    "n_dirs": click.IntRange(16, 100_000),
    # transfer: ray directions per vertex (rays and memory have their own limits,
    # shtools.cli._limits) and the visibility floor of the log
    "transfer_n_dirs": click.IntRange(16, 1_000_000),
    "floor": FiniteRange(0.0, 0.5),
    # spheres fit / tree / bind: round budget, starts, tree fan-out, skin weights
    "iterations": click.IntRange(1, 100_000),
    "restarts": click.IntRange(1, 1000),
    "branching": click.IntRange(2, 1000),
    "bones_per_sphere": click.IntRange(1, 64),
    "check_frames": click.IntRange(0, 10_000),
    # field sample (shtools.field_limits, which FieldParameters.validate checks too; --order and
    # --self-order are the runtime settings order and acc_order, setting_type)
    "shells": click.IntRange(*field_limits.SHELLS),
    "field_resolution": PowerOfTwo(*field_limits.RESOLUTION),
    "min_resolution": PowerOfTwo(1, field_limits.RESOLUTION[1]),
    "map_size": click.IntRange(*field_limits.MAP_SIZE),
    "threshold": FiniteRange(0, None, min_open=True),
    "bits": click.IntRange(*field_limits.BITS),
    # field sample --basis haar: fraction of the Haar coefficients kept
    "keep": FiniteRange(0, 1, min_open=True),
}


def option_type(name: str) -> click.ParamType:
    """The click type (range, finite) of the numeric option ``name`` (:data:`OPTION_TYPES`)."""
    return OPTION_TYPES[name]
