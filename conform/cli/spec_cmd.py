"""``conform spec``: list, show and compare the variants of the spec tables."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import click
from rich.console import Console
from rich.table import Table

from conform.cli.params import VARIANT, echo_json, json_option


def _console() -> Console:
    return Console(soft_wrap=False, width=None if sys.stdout.isatty() else 160)


_JSON = json_option("the table's rows")


def _emit(title: str, columns: Sequence[str], rows: list[Sequence[Any]], as_json: bool,
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
    """List the modelled variants.

    \b
    Example:
      conform spec list --json | jq -r '.variants[].variant'
    """
    from conform.families import DEFAULT_FAMILY, families, family

    title, columns, rows = family(DEFAULT_FAMILY).variant_table(pretty=not as_json)
    others = {}
    if as_json:
        others = {f.name: [{"variant": v.id, "title": v.title, "firmware": v.firmware,
                            "axes": v.axes, "buffers": v.buffer, "notes": v.notes}
                           for v in f.variants()] for f in families() if f.name != DEFAULT_FAMILY}
    _emit(title, columns, rows, as_json, "variants", other_families=others)
    if not as_json:
        _other_families()


def _other_families() -> None:
    """Variants of the other protocol families (conform.families), one table each."""
    from conform.families import DEFAULT_FAMILY, families

    for fam in families():
        if fam.name == DEFAULT_FAMILY:
            continue
        table = Table(title=f"{fam.name} variants")
        for col in ("variant", "title", "firmware", "axes", "buffers", "notes"):
            table.add_column(col)
        for v in fam.variants():
            table.add_row(v.id, v.title, v.firmware, v.axes, v.buffer, v.notes)
        _console().print(table)


@cli.command("show")
@click.argument("variant", type=VARIANT)
@click.argument("command", required=False)
@_JSON
def show_cmd(variant: str, command: str | None, as_json: bool) -> None:
    """Show a variant's commands (or one command) with ranges and manual clauses.

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
    """What differs from variant A to variant B.

    \b
    Example:
      conform spec diff gve64-v19 gve124
    """
    from conform.families.gve.spec import load_spec  # GVE-only: the variant diff of its tables
    from conform.families.gve.spec.diff import diff_variants

    spec = load_spec()
    va, vb = spec.variant(a), spec.variant(b)
    diffs = diff_variants(va, vb)
    rows = [(d.kind, d.what, d.a, d.b, d.clause) for d in diffs]
    _emit(f"{va.id} → {vb.id}: {len(diffs)} differences", ("kind", "what", a, b, "clause"),
          rows if as_json else [(*r[:2], str(r[2]), str(r[3]), r[4]) for r in rows], as_json,
          "differences", a=a, b=b)


@cli.command("questions")
def questions_cmd() -> None:
    """The open questions the manuals leave, with the assumed default.

    \b
    Example:
      conform spec questions
    """
    from conform.families.gve.spec import load_spec  # GVE-only: its A-register

    spec = load_spec()
    table = Table(title="Open questions (A-register)")
    for col in ("id", "question", "default", "alternatives", "settled"):
        table.add_column(col, overflow="fold")
    for q in spec.questions.values():
        table.add_row(q.id, q.question, q.default, ", ".join(q.alternatives), q.settled or "")
    _console().print(table)


@cli.command("check")
@click.option("--specs", "root", type=click.Path(), default=None, help="A spec folder to validate.")
def check_cmd(root: str | None) -> None:
    """Load and validate the tables; one line per problem, non-zero exit.

    \b
    Example:
      conform spec check --specs gve/spec/tables
    """
    from conform.families import DEFAULT_FAMILY, families, family

    click.echo(family(DEFAULT_FAMILY).tables_summary(root))
    if root is None:   # a folder given is checked as the default family's tables
        for fam in families():
            if fam.name != DEFAULT_FAMILY:
                click.echo(fam.tables_summary())
