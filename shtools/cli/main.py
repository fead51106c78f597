"""The ``shtools`` command: a click group whose subcommands load lazily.

Every command is thin: parse options, call the library, report.  Errors a user
can fix (:class:`shtools.errors.ShtoolsError`, click usage errors) become one
line ``error: <file>: <what to do>`` on stderr with exit status 2 (usage) or 1;
anything else is a bug and prints a traceback only with ``--debug``.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys

import click

from shtools import __version__
from shtools.cli._common import one_blas_thread
from shtools.errors import ShtoolsError

#: command name -> "module:attribute" (module under shtools.cli).  Commands whose
#: module is not present are not listed.
COMMANDS = {
    "spheres": "shtools.cli.spheres:spheres",
    "tables": "shtools.cli.tables:tables",
    "transfer": "shtools.cli.transfer:transfer",
    "field": "shtools.cli.field:field",
    "light": "shtools.cli.light:light",
    "bake": "shtools.cli.bake:bake",
    "export": "shtools.cli.export:export",
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


def main(argv=None) -> int:
    """Entry point of the ``shtools`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    try:
        # standalone_mode=False returns ctx.exit(n)'s code instead of raising it;
        # one BLAS thread unless the user set a count (see one_blas_thread)
        with one_blas_thread():
            rv = cli.main(args=argv, prog_name="shtools", standalone_mode=False)
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
        click.echo("error: interrupted; no output was written", err=True)
        return 130
    except Exception as exc:  # a bug: one line unless --debug
        if debug:
            raise
        click.echo(
            f"error: internal error ({type(exc).__name__}: {exc}); rerun with --debug "
            "and report it",
            err=True,
        )
        return 3
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
