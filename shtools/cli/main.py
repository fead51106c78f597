"""The ``shtools`` command: a click group whose subcommands load lazily.

Every command is thin: parse options, call the library, report.  Errors a user
can fix (:class:`shtools.errors.ShtoolsError`, click usage errors) become one
line ``error: <file>: <what to do>`` on stderr with exit status 2 (usage) or 1;
anything else is a bug and prints a traceback only with ``--debug``.

Ctrl-C (SIGINT), SIGTERM and SIGHUP stop a command the same way: the signal
becomes an exception, so atomic writers remove their temporary files and worker
processes are stopped, and the command prints one line and exits 128 + signal
(130, 143, 129).  A full disk, an exceeded quota or a read-only file system
(``ENOSPC``, ``EDQUOT``, ``EROFS``, ``EFBIG``) is a one-line error, exit 1, and so
is running out of memory (a request past its size limits with ``--force``).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import signal
import sys
import threading
import time
import warnings

import click

from shtools import __version__
from shtools.cli._common import one_blas_thread
from shtools.errors import ShtoolsError, disk_error_reason

#: command name -> "module:attribute" (module under shtools.cli).  Commands whose
#: module is not present are not listed.
COMMANDS = {
    "spheres": "shtools.cli.spheres:spheres",
    "tables": "shtools.cli.tables:tables",
    "transfer": "shtools.cli.transfer:transfer",
    "field": "shtools.cli.field:field",
    "light": "shtools.cli.light:light",
    "bake": "shtools.cli.bake:bake",
    "cache": "shtools.cli.cache:cache",
    "export": "shtools.cli.export:export",
    "relight": "shtools.cli.relight:relight",
    "view": "shtools.cli.view:view",
    "eval": "shtools.cli.eval:eval_cmd",
    "info": "shtools.cli.assets:info",
    "check": "shtools.cli.assets:check",
    "diff": "shtools.cli.assets:diff",
}


#: click >= 8.2 raises this for a bare group; older versions print the help and exit 0
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


class LazyGroup(click.Group):
    """A group that imports a subcommand's module only when it is used."""

    def list_commands(self, ctx):
        lazy = {
            name
            for name, target in COMMANDS.items()
            if importlib.util.find_spec(target.split(":")[0]) is not None
        }
        return sorted(lazy | set(super().list_commands(ctx)))

    def get_command(self, ctx, name):
        eager = super().get_command(ctx, name)
        if eager is not None:
            return eager
        target = COMMANDS.get(name)
        if target is None:
            return None
        module_name, attr = target.split(":")
        if importlib.util.find_spec(module_name) is None:
            return None
        return getattr(importlib.import_module(module_name), attr)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="shtools")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.option("-q", "--quiet", is_flag=True,
              help="No progress output (bars on a terminal, log lines every ~10 s otherwise).")
@click.pass_context
def cli(ctx, debug, quiet):
    """Soft shadows with spherical harmonics: preprocessing stages and baker.

    Each stage reads files and writes one HDF5 asset named by -o/--output.
    """
    from shtools.cli._common import set_quiet

    set_quiet(quiet)
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


class Terminated(BaseException):
    """Raised in the main thread when SIGTERM or SIGHUP arrives (see :func:`main`)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


#: The stop signal being handled (None when none is): while it is set, the signal
#: is sent again every RESEND_SECONDS, because Python runs a handler wherever the
#: main thread is, and an exception raised inside a finaliser or a weakref
#: callback is printed and dropped ("Exception ignored in ...") instead of
#: stopping the command.  Short, so a command cannot finish (and write its
#: output) between a dropped stop and the next one.
_STOPPING: int | None = None
RESEND_SECONDS = 0.2


def _raise_terminated(signum, _frame):
    global _STOPPING
    if _STOPPING is None:
        _STOPPING = signum

        def resend():
            while _STOPPING == signum:
                time.sleep(RESEND_SECONDS)
                if _STOPPING == signum:
                    os.kill(os.getpid(), signum)

        threading.Thread(target=resend, name="shtools-stop-resend", daemon=True).start()
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


def _quiet_dropped_stops(unraisable, _previous=sys.unraisablehook) -> None:
    """``sys.unraisablehook`` while a command runs: a stop dropped in a finaliser
    or weakref callback prints nothing (it is re-sent, see ``_STOPPING``), so the
    user still sees one line; anything else goes to the previous hook."""
    if isinstance(unraisable.exc_value, Terminated | KeyboardInterrupt):
        return
    _previous(unraisable)


def _default_termination_in_child() -> None:
    """After fork: SIGTERM/SIGHUP kill a worker again (the handlers above are inherited).

    A forked worker that kept them would turn SIGTERM into an exception, which a
    process pool's worker loop catches and survives -- pools stop their workers
    with SIGTERM.
    """
    for sig in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is _raise_terminated:
            signal.signal(sig, signal.SIG_DFL)
    if signal.getsignal(signal.SIGINT) is _raise_terminated:
        signal.signal(signal.SIGINT, signal.default_int_handler)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_default_termination_in_child)


def main(argv=None) -> int:
    """Entry point of the ``shtools`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGHUP):
            handlers[sig] = signal.signal(sig, _raise_terminated)
        # Ctrl-C the same way (re-sent while stopping), unless the caller ignores it
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            handlers[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_terminated)
    previous_hook, sys.unraisablehook = sys.unraisablehook, _quiet_dropped_stops
    try:
        with warnings.catch_warnings():
            if not debug:
                # numeric warnings of NumPy/SciPy are not messages for a user: a
                # real problem is checked and reported as one line where it matters
                warnings.simplefilter("ignore", RuntimeWarning)
            return _run(argv, debug)
    finally:
        sys.unraisablehook = previous_hook
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def _run(argv: list[str], debug: bool) -> int:
    try:
        # standalone_mode=False returns ctx.exit(n)'s code instead of raising it;
        # one BLAS thread unless the user set a count (see one_blas_thread)
        with one_blas_thread():
            rv = cli.main(args=argv, prog_name="shtools", standalone_mode=False)
    except Terminated as exc:
        global _STOPPING
        _STOPPING = None
        name = signal.Signals(exc.signum).name
        click.echo(f"error: stopped by {name}; no output was written", err=True)
        return 128 + exc.signum
    except _NO_ARGS_IS_HELP as exc:
        # a bare group (``shtools``, ``shtools spheres``) asks for its help
        click.echo(exc.ctx.get_help())
        return 0
    except ShtoolsError as exc:
        if debug:
            raise
        click.echo(f"error: {exc.one_line()}", err=True)
        return 1
    except click.exceptions.Abort:
        click.echo("error: interrupted; no output was written", err=True)
        return 130
    except click.ClickException as exc:
        if debug:
            raise
        click.echo(f"error: {' '.join(exc.format_message().split())}", err=True)
        return exc.exit_code
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except KeyboardInterrupt:
        _STOPPING = None
        click.echo("error: interrupted; no output was written", err=True)
        return 130
    except MemoryError:
        # past the size limits with --force, or a machine smaller than the limits assume
        if debug:
            raise
        command = " ".join(a for a in argv[:3] if not a.startswith("-")) or "shtools"
        click.echo(f"error: out of memory in '{command}'; lower the sizes given to it (the "
                   "size limits that --force goes past are in its --help)", err=True)
        return 1
    except Exception as exc:  # a bug: one line unless --debug
        if debug:
            raise
        reason = disk_error_reason(exc)
        if reason is not None:  # outside an atomic writer, which names its output itself
            where = getattr(exc, "filename", None)
            prefix = f"{where}: " if where else ""
            click.echo(f"error: {prefix}{reason}; free space or write elsewhere", err=True)
            return 1
        click.echo(
            f"error: internal error ({type(exc).__name__}: {exc}); rerun with --debug "
            "and report it",
            err=True,
        )
        return 3
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
