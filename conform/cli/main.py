"""Entry point of the ``conform`` command.

Subcommand groups live in their own modules (``conform.cli.<name>``) and expose a click
command or group called ``cli``; they are registered here so that a failing import of one
group never takes the others down silently: it is reported as one line.
"""

from __future__ import annotations

import importlib
import os
import sys
import traceback

import click

from conform import __version__
from conform.cli.family_options import add_family_commands
from conform.errors import UserError

# module name -> attribute; each module defines a click command/group named in the value
SUBCOMMANDS: tuple[str, ...] = (
    "spec",
    "emulate",
    "run",
    "send",
    "report",
    "characterize",
    "profile",
    "proxy",
    "sniff",
    "capture",
    "analyze",
    "diagnose",
    "bundle",
    "check-sender",
    "ports",
    "samples",
)


class _Conform(click.Group):
    """The top-level group: its help names every registered family and its variants (read
    when the help is shown, so no other command pays for loading the tables). A subcommand's
    module is imported when that command is asked for (a command line pays only for its own
    command's imports); listing, the help or a family's own command loads them all."""

    _all_loaded = False

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        from conform.stops import Stopped, current, shield

        if cmd_name not in self.commands:
            # a stop signal while the modules load is kept and acted on once they are in: one
            # raised inside an extension module's import (orjson's) crashed the interpreter
            with shield():
                if cmd_name in SUBCOMMANDS:
                    _add_subcommand(cmd_name)
                else:
                    _register()
            state = current()
            if state is not None and state.signum is not None:
                raise Stopped(state.signum)
        return super().get_command(ctx, cmd_name)

    def list_commands(self, ctx: click.Context) -> list[str]:
        _register()
        return super().list_commands(ctx)

    def format_help_text(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        import inspect

        _register()
        try:
            from conform.families import families

            rows = [f"{fam.name} ({', '.join(v.id for v in fam.variants())})"
                    for fam in families()]
        except Exception:  # noqa: BLE001 - the help must always show
            rows = []
        if rows and self.help and "Protocol families" not in self.help:
            head, _, rest = inspect.cleandoc(self.help).partition("\n\n")
            self.help = f"{head}\n\nProtocol families: {'; '.join(rows)}.\n\n{rest}"
        super().format_help_text(ctx, formatter)


@click.group(cls=_Conform, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="conform")
def cli() -> None:
    """Conformance, emulation, capture and analysis for serial CNC motion controllers.

    Exit status: 0 done, 1 something failed (a FAIL, a failed send, a damaged capture), 2 a
    usage or input mistake, a link that cannot be opened, or a run that stopped early; 128 + N
    stopped by signal N (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP), after halting the unit and
    writing the report.

    \b
    Examples:
      conform run                                   # conformance against the emulator
      conform ports --probe                         # which serial port has a unit
      conform analyze captures/careless-noisy.mcap  # what went wrong in a session
      conform COMMAND --help                        # each command, with examples
    """


def _add_subcommand(name: str) -> None:
    try:
        module = importlib.import_module(f"conform.cli.{name.replace('-', '_')}_cmd")
    except ModuleNotFoundError as exc:
        if exc.name == f"conform.cli.{name.replace('-', '_')}_cmd":
            return  # not built yet
        raise
    cli.add_command(module.cli, name=name)


def _register() -> None:
    """Every subcommand, then every family's own commands (once)."""
    if _Conform._all_loaded:
        return
    _Conform._all_loaded = True
    for name in SUBCOMMANDS:
        if name not in cli.commands:
            _add_subcommand(name)
    add_family_commands(cli)
    _name_the_families()


def _name_the_families() -> None:
    """The first line of ``conform --help`` names every registered family."""
    from conform.families import families

    try:
        titles = [f.title or f.name for f in families()]
    except UserError:
        return
    first, rest = (cli.help or "").split("\n", 1)
    cli.help = f"{first.rstrip('.')}: {'; '.join(titles)}.\n{rest}"


def main(argv: list[str] | None = None) -> None:
    from conform.stops import Stopped, early_stop, exit_status, stop_signals

    args = sys.argv[1:] if argv is None else list(argv)
    with stop_signals() as state:   # SIGINT, SIGTERM, SIGHUP: the same safe stop everywhere
        try:  # obj["argv"]: the command line as given, for the reports' "how to run it again"
            early = early_stop()
            if early is not None:   # stopped while loading: nothing was started
                state.signum = early
                raise Stopped(early)
            cli.main(args=args, prog_name="conform", standalone_mode=False, obj={"argv": args})
            code = 0
        except click.exceptions.Abort as exc:   # click's wrapper of a KeyboardInterrupt
            cause = exc.__cause__
            how = cause.name if isinstance(cause, Stopped) else "Ctrl-C"
            click.echo(f"conform: interrupted ({how})", err=True)
            code = 130
        except Stopped as exc:   # raised outside click's invoke (cannot happen often)
            click.echo(f"conform: interrupted ({exc.name})", err=True)
            code = exc.exit_code
        except click.MissingParameter as exc:   # what is missing, and where it goes
            usage = exc.ctx.get_usage().replace("Usage: ", "", 1) if exc.ctx else ""
            path = exc.ctx.command_path if exc.ctx else "conform"
            click.echo(f"conform: {exc.format_message().rstrip('.')}"
                       + (f": {usage} ({path} --help has examples)" if usage else ""), err=True)
            code = exc.exit_code
        except click.ClickException as exc:
            click.echo(f"conform: {exc.format_message()}", err=True)
            code = exc.exit_code
        except UserError as exc:
            click.echo(f"conform: {exc}", err=True)
            code = exc.exit_code
        except click.exceptions.Exit as exc:
            code = exc.exit_code
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 1
            if not isinstance(exc.code, int | None):
                click.echo(str(exc.code), err=True)
        except Exception as exc:   # a bug (conform's or a family plugin's): one line, not a traceback
            if os.environ.get("CONFORM_DEBUG"):
                raise
            where = traceback.extract_tb(exc.__traceback__)[-1]
            click.echo(f"conform: internal error: {type(exc).__name__}: {exc} (at "
                       f"{'/'.join(where.filename.split(os.sep)[-2:])}:{where.lineno}; CONFORM_DEBUG=1 shows "
                       "the traceback)", err=True)
            code = 70
        code = exit_status(code)
    sys.exit(code)
