"""``conform spec``: list, show and compare the variants of the spec tables."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import click
from rich.console import Console
from rich.table import Table

from conform.cli.params import VARIANT, echo_json, json_option
from conform.errors import UserError
from conform.families.gve.spec import load_spec
from conform.families.gve.spec.diff import diff_variants
from conform.families.gve.spec.model import CommandSpec, Variant


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


def _params(cmd: CommandSpec, variant: Variant) -> str:
    out = []
    for p in cmd.params:
        if p.kind == "sign":
            rng = "|".join(p.choices)
        elif p.kind == "axis":
            rng = "/".join(variant.axes)
        elif p.kind == "hex":
            rng = f"{p.lo:02X}..{p.hi:02X}h"
        else:
            rng = f"{p.lo}..{p.hi}"
        name = f"{p.name}×{len(variant.axes)}" if p.per_axis else p.name
        if p.per_axis and p.min_count and p.min_count < len(variant.axes):
            name = f"{p.name}×{p.min_count}-{len(variant.axes)}"
        out.append(f"{name} {p.kind} {rng}")
    return "; ".join(out) or "-"


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
    spec = load_spec()
    rows = [(v.id, v.title, v.firmware, "".join(v.axes), v.queue, v.max_rate, len(v.commands),
             v.base or "-") for v in spec.variants.values()]
    if not as_json:
        rows = [(*r[:5], f"{r[5]:,}", *r[6:]) for r in rows]
    others = {}
    if as_json:
        from conform.families import families

        others = {f.name: [{"variant": v.id, "title": v.title, "firmware": v.firmware,
                            "axes": v.axes, "buffers": v.buffer, "notes": v.notes}
                           for v in f.variants()] for f in families() if f.name != "gve"}
    _emit("GVE variants", ("variant", "title", "firmware", "axes", "queue", "max rate",
                           "commands", "base"), rows, as_json, "variants", other_families=others)
    if not as_json:
        _other_families()


def _other_families() -> None:
    """Variants of the other protocol families (conform.families), one table each."""
    from conform.families import families

    for fam in families():
        if fam.name == "gve":
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

    if family_for_variant(variant).name == "grbl":
        from conform.families.grbl.show import show

        show(variant, command, _console())
        return
    spec = load_spec()
    v = spec.variant(variant)
    console = _console()
    if command is not None:
        cmd = v.command(command)
        if cmd is None:
            known = spec.commands.get(command)
            if known is None:
                raise UserError(f"no command {command!r} in the tables")
            raise UserError(f"{v.id} has no command {command!r} (absent in this version)")
        rows = [
            ("mnemonic", cmd.mnemonic), ("addresses", ",".join(map(str, cmd.addresses))),
            ("family", cmd.family), ("parameters", _params(cmd, v)),
            ("answer", ", ".join(f"{f.name}:{f.radix}" for f in cmd.answer) or "code only"),
            ("modal", "yes" if cmd.modal else "no"),
            ("while running", "yes" if cmd.while_running else "no (7)"),
            ("moves the machine", "yes" if cmd.motion else "no"),
            ("effect", cmd.effect), ("clause", cmd.clause_for(v.manual)),
            ("all clauses", ", ".join(cmd.clauses)),
            ("open questions", ", ".join(cmd.questions) or "-"),
            ("variants", ", ".join(x.id for x in spec.variants.values() if x.has(cmd.id))),
        ]
        if as_json:
            echo_json({"variant": v.id, "command": cmd.id, **dict(rows)})
            return
        table = Table(title=f"{v.id}: {cmd.id}", show_header=False)
        table.add_column("field")
        table.add_column("value")
        for k, val in rows:
            table.add_row(k, val)
        console.print(table)
        return
    rows = [(cmd.id, ",".join(map(str, cmd.addresses)), _params(cmd, v),
             ",".join(f.name for f in cmd.answer) or "-", "yes" if cmd.modal else "",
             "" if cmd.while_running else "7", cmd.clause_for(v.manual))
            for cmd in v.commands.values()]
    _emit(f"{v.title} ({v.id}): axes {''.join(v.axes)}, queue {v.queue}, "
          f"max {v.max_rate:,} pulses/s",
          ("command", "addr", "parameters", "answer", "modal", "running", "clause"), rows,
          as_json, "commands", variant=v.id, axes="".join(v.axes), queue=v.queue,
          max_rate=v.max_rate)


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
      conform spec check --specs specs/gve
    """
    spec = load_spec(root)
    n = sum(len(v.commands) for v in spec.variants.values())
    click.echo(f"ok: {len(spec.commands)} commands, {len(spec.variants)} variants "
               f"({n} variant commands), {len(spec.questions)} open questions, {len(spec.examples)} examples")
    if root is None:
        from conform.families.grbl.tables import load_grbl

        g = load_grbl()
        click.echo(f"ok: grbl: {len(g.variants)} variant, {len(g.errors)} error codes, "
                   f"{len(g.alarms)} alarm codes, {len(g.settings)} settings, "
                   f"{len(g.commands)} $ commands, {len(g.examples)} examples")
