"""Shared click parameter types: every command checks variants, bauds, probabilities, counts
and targets the same way, so a mistake is the same one line (exit 2) everywhere."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click
from click.shell_completion import CompletionItem

if TYPE_CHECKING:
    from collections.abc import Callable

    from click.decorators import FC

MAX_BAUD = 10_000_000  # above any RS232 converter; a typo guard, not a hardware limit


def variant_ids() -> list[str]:
    """Every family's variants, in the registry's order (conform.families)."""
    from conform.families import families

    ids: list[str] = []
    for fam in families():
        ids += [v.id for v in fam.variants() if v.id not in ids]
    return ids


def default_variant_text() -> str:
    """The variant commands address when given none, for help texts (never an error here: a
    bad ``$CONFORM_VARIANT`` is reported when a command runs)."""
    from conform.errors import UserError
    from conform.families import default_variant

    try:
        return default_variant()
    except UserError:
        return "the default family's first variant"


class VariantType(click.ParamType):
    """A variant id of the tables (``gve64-v19``)."""

    name = "variant"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        text = str(value).strip()
        known = variant_ids()
        if text not in known:
            self.fail(f"{text!r} is not a variant (known: {', '.join(known)})", param, ctx)
        return text

    def shell_complete(self, ctx: click.Context, param: click.Parameter,
                       incomplete: str) -> list[CompletionItem]:
        return [CompletionItem(v) for v in variant_ids() if v.startswith(incomplete)]


class TargetType(click.ParamType):
    """``emu``, ``emu:VARIANT[:MUTANT]``, a device path, a pty or a pyserial URL. The emulator
    forms are checked here; a port is checked when it is opened."""

    name = "target"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        text = str(value).strip()
        if not text:
            self.fail("empty target", param, ctx)
        if text != "emu" and not text.startswith("emu:"):
            return text
        parts = text.split(":")
        if len(parts) > 3:
            self.fail(f"{text!r}: expected emu:VARIANT[:MUTANT]", param, ctx)
        known = variant_ids()
        if len(parts) > 1 and not parts[1]:
            self.fail(f"{text!r} names no variant: emu:VARIANT (one of {', '.join(known)}), "
                      "or emu alone for the default", param, ctx)
        if len(parts) > 1 and parts[1] and parts[1] not in known:
            self.fail(f"{text!r}: {parts[1]!r} is not a variant (known: {', '.join(known)})",
                      param, ctx)
        if len(parts) > 2 and parts[2]:
            from conform.families import family_for_variant

            mutants = family_for_variant(parts[1]).mutants()
            if mutants and parts[2] not in mutants:  # a family without any says so itself
                self.fail(f"{text!r}: no mutant {parts[2]!r} (see conform run --mutants)",
                          param, ctx)
        return text

    def shell_complete(self, ctx: click.Context, param: click.Parameter,
                       incomplete: str) -> list[CompletionItem]:
        if incomplete.startswith("emu"):
            return [CompletionItem(f"emu:{v}") for v in variant_ids()
                    if f"emu:{v}".startswith(incomplete)]
        return [CompletionItem(incomplete, type="file")]


class BaudType(click.ParamType):
    """A positive baud rate (int, or float where a measured rate is allowed)."""

    name = "baud"

    def __init__(self, fractional: bool = False) -> None:
        self.fractional = fractional

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> int | float:
        try:
            rate = float(value) if self.fractional else int(str(value).strip())
        except ValueError:
            self.fail(f"{value!r} is not a baud rate (e.g. 115200)", param, ctx)
        if not 0 < rate <= MAX_BAUD:
            self.fail(f"{value} is not a baud rate (a number from 1 to {MAX_BAUD:,})", param, ctx)
        return rate


class ProbabilityType(click.ParamType):
    """A probability, 0 to 1."""

    name = "probability"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> float:
        try:
            p = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not 0.0 <= p <= 1.0:
            self.fail(f"{value} is not a probability (0 to 1)", param, ctx)
        return p


class InputPathType(click.Path):
    """An existing file (or folder, where allowed) the user named; missing or of the wrong kind
    is the project's one line (``PATH: no such file``), as the readers say it."""

    def __init__(self, dir_okay: bool = False) -> None:
        super().__init__(exists=True, dir_okay=dir_okay, path_type=str)

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> Any:
        import os

        from conform.errors import UserError

        path = os.fspath(value)
        if not os.path.exists(path):
            raise UserError(f"{path}: no such file")
        if not self.dir_okay and os.path.isdir(path):
            raise UserError(f"{path}: is a directory, not a file")
        return super().convert(value, param, ctx)


VARIANT = VariantType()
TARGET = TargetType()
BAUD = BaudType()
FRACTIONAL_BAUD = BaudType(fractional=True)
PROBABILITY = ProbabilityType()
class WholeNumber(click.IntRange):
    """An integer with a lower bound; anything else is said as what is expected."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> Any:
        try:
            int(str(value).strip())
        except ValueError:
            self.fail(f"{value!r} is not a whole number (e.g. {self.min or 0})", param, ctx)
        return super().convert(value, param, ctx)


POSITIVE_INT = WholeNumber(min=1)
NON_NEGATIVE_INT = WholeNumber(min=0)
NON_NEGATIVE = click.FloatRange(min=0.0)
POSITIVE = click.FloatRange(min=0.0, min_open=True)
PORT_NUMBER = click.IntRange(0, 65535)
#: an existing input file (a directory is refused by click with one line)
INPUT_FILE = InputPathType()
#: an existing capture (a file, or a folder of a split capture)
INPUT_PATH = InputPathType(dir_okay=True)
OUTPUT_DIR = click.Path(file_okay=False, path_type=str)
OUTPUT_FILE = click.Path(dir_okay=False, path_type=str)

def json_option(what: str = "") -> Callable[[FC], FC]:
    """``--json`` (``as_json``): one JSON document on stdout; human messages go to stderr."""
    return click.option("--json", "as_json", is_flag=True,
                        help=f"One JSON document on stdout{': ' + what if what else ''}; "
                             "messages go to stderr.")


def echo_json(doc: object) -> None:
    """The one JSON document of a ``--json`` command."""
    import json

    click.echo(json.dumps(doc, indent=1, default=str, ensure_ascii=False))


def quiet_option() -> Callable[[FC], FC]:
    """``-q/--quiet``: the same on every long-running command (README, "Options that mean the
    same everywhere")."""
    return click.option("-q", "--quiet", is_flag=True,
                        help="No progress display (by default: bars on a terminal, a line "
                             "every few seconds off one).")


#: what ``--seed`` is when not given, on every command that has one
DEFAULT_SEED = 1


def seed_option() -> Callable[[FC], FC]:
    """``--seed N``: one default and one meaning wherever it appears."""
    return click.option("--seed", type=NON_NEGATIVE_INT, default=DEFAULT_SEED,
                        show_default=True,
                        help="Seed of everything random this command does (state-machine "
                             "sequences, injected faults): the same seed repeats the run.")


#: exit statuses every command shares (README "Exit status")
EXIT_OK, EXIT_FINDING, EXIT_USAGE = 0, 1, 2


def command_line() -> str:
    """``conform ARGS`` as the user typed it (the root context's argv, else sys.argv): the
    reports' "how to run it again"."""
    import shlex
    import sys

    ctx = click.get_current_context(silent=True)
    argv = ((ctx.find_root().obj if ctx else None) or {}).get("argv", sys.argv[1:])
    return "conform " + " ".join(shlex.quote(a) for a in argv)
