"""Entry point of the ``conform`` command.

Subcommand groups live in their own modules (``conform.cli.<name>``) and expose a click
command or group called ``cli``; they are registered here so that a failing import of one
group never takes the others down silently: it is reported as one line.
"""

from __future__ import annotations

import importlib
import sys

import click

from conform import __version__
from conform.errors import UserError

# module name -> attribute; each module defines a click command/group named in the value
SUBCOMMANDS: tuple[str, ...] = (
    "spec",
    "emulate",
    "run",
    "report",
    "characterize",
    "profile",
    "proxy",
    "sniff",
    "capture",
    "analyze",
    "diagnose",
    "bundle",
    "send",
    "check-sender",
    "ports",
)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="conform")
def cli() -> None:
    """Conformance, emulation, capture and analysis for Gravos GVE64/GVE124 interpolators.

    Exit status: 0 done, 1 something failed (a FAIL, a failed send, a damaged capture), 2 a
    usage or input mistake, a link that cannot be opened, or a run that stopped early; 130
    interrupted.

    \b
    Examples:
      conform run                                   # conformance against the emulator
      conform ports --probe                         # which serial port has a unit
      conform analyze captures/careless-noisy.mcap  # what went wrong in a session
      conform COMMAND --help                        # each command, with examples
    """


def _register() -> None:
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"conform.cli.{name.replace('-', '_')}_cmd")
        except ModuleNotFoundError as exc:
            if exc.name == f"conform.cli.{name.replace('-', '_')}_cmd":
                continue  # not built yet
            raise
        cli.add_command(module.cli, name=name)


_register()


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else list(argv)
    try:  # obj["argv"]: the command line as given, for the reports' "how to run it again"
        cli.main(args=args, prog_name="conform", standalone_mode=False, obj={"argv": args})
    except click.exceptions.Abort:
        click.echo("conform: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        click.echo(f"conform: {exc.format_message()}", err=True)
        sys.exit(exc.exit_code)
    except UserError as exc:
        click.echo(f"conform: {exc}", err=True)
        sys.exit(exc.exit_code)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    sys.exit(0)
