"""``conform spec``: list, show and compare the variants of the spec tables."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import click
from rich.console import Console
from rich.table import Table

from conform.cli.params import VARIANT, echo_json, json_option
from conform.jsondoc import JsonObject


def _console() -> Console:
    return Console(soft_wrap=False, width=None if sys.stdout.isatty() else 160)


_JSON = json_option("the table's rows")


def _emit(title: str, columns: Sequence[str], rows: Sequence[Sequence[Any]], as_json: bool,
          key: str, **extra: Any) -> None:
    """Print rows as a rich table, or as ``{key: [{column: value}], ...extra}`` JSON."""
    if as_json:
        echo_json({**extra, key: [dict(zip(columns, row, strict=True)) for row in rows]})
        return
    table = Table(title=title)
    for col in columns:
        table.add_column(col, overflow="fold")
    for row in rows:
        table.add_row(*(str(x) for x in row))
    _console().print(table)


@click.group()
def cli() -> None:
    """The protocol tables: variants, commands, ranges and differences.

    \b
    Examples:
      conform spec list
      conform spec diff gve64-v10 gve64-v19
    """


@cli.command("list")
@_JSON
def list_cmd(as_json: bool) -> None:
    """List the modelled variants of every family, one table per family.

    \b
    Example:
      conform spec list --json | jq -r '.variants[].variant'
    """
    from conform.families import families

    doc: JsonObject = {"variants": [], "families": {}}
    for fam in families():
        title, columns, rows = fam.variant_table(pretty=not as_json)
        if not as_json:
            _emit(title, columns, rows, False, "variants")
            continue
        records = [dict(zip(columns, row, strict=True)) for row in rows]
        doc["families"][fam.name] = {"title": fam.title or fam.name, "variants": records}
        doc["variants"] += [{"family": fam.name, **r} for r in records]
    if as_json:
        echo_json(doc)


@cli.command("show")
@click.argument("variant", type=VARIANT)
@click.argument("command", required=False)
@_JSON
def show_cmd(variant: str, command: str | None, as_json: bool) -> None:
    """Show a variant's commands (or one command) with ranges and the clauses they cite.

    \b
    Examples:
      conform spec show gve64-v19
      conform spec show gve124 V --json
    """
    from conform.families import family_for_variant

    family_for_variant(variant).show_spec(variant, command, console=_console(), as_json=as_json)


@cli.command("diff")
@click.argument("a", type=VARIANT)
@click.argument("b", type=VARIANT)
@_JSON
def diff_cmd(a: str, b: str, as_json: bool) -> None:
    """What differs from variant A to variant B (two variants of one family).

    \b
    Example:
      conform spec diff gve64-v19 gve124
    """
    from conform.errors import UserError
    from conform.families import family_for_variant

    fam = family_for_variant(a)
    other = family_for_variant(b)
    if other is not fam:
        raise UserError(f"{a} ({fam.name}) and {b} ({other.name}) are of different families: "
                        "a diff compares two variants of one family's tables")
    title, columns, rows = fam.diff_variants(a, b)
    _emit(title, columns, rows if as_json else [tuple(str(x) for x in r) for r in rows], as_json,
          "differences", a=a, b=b)


@cli.command("questions")
@click.option("--family", "family_name", default=None, metavar="NAME",
              help="Whose open questions (default: every family that has some).")
@_JSON
def questions_cmd(family_name: str | None, as_json: bool) -> None:
    """The open questions each family's sources leave, with the default assumed here.

    \b
    Example:
      conform spec questions
    """
    from conform.families import families, family

    chosen = [family(family_name)] if family_name else families()
    shown = 0
    for fam in chosen:
        table = fam.open_questions()
        if table is None:
            if family_name:
                raise fam.lacks("open questions")
            continue
        title, columns, rows = table
        _emit(title, columns, rows, as_json, "questions", family=fam.name)
        shown += 1
    if not shown and not as_json:
        click.echo("no family has open questions")


@cli.command("check")
@click.option("--specs", "root", type=click.Path(), default=None,
              help="A folder of one family's tables (a modified copy) to validate.")
def check_cmd(root: str | None) -> None:
    """Load and validate the tables; one line per problem, non-zero exit.

    \b
    Examples:
      conform spec check
      conform spec check --specs my-tables/   # a modified copy of one family's tables
    """
    from conform.families import families, family_of_tables

    if root is None:
        for fam in families():
            click.echo(fam.tables_summary())
        return
    click.echo(family_of_tables(root).tables_summary(root))
