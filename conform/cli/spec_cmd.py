"""``conform spec``: list, show and compare the variants of the spec tables."""

from __future__ import annotations

import click
from rich.console import Console
from rich.table import Table

from conform.spec import load_spec
from conform.spec.diff import diff_variants
from conform.spec.model import CommandSpec, Variant


def _console() -> Console:
    return Console(soft_wrap=False, width=None if click.get_text_stream("stdout").isatty() else 160)


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
    """The protocol tables: variants, commands, ranges and differences."""


@cli.command("list")
def list_cmd() -> None:
    """List the modelled variants."""
    spec = load_spec()
    table = Table(title="GVE variants")
    for col in ("variant", "title", "firmware", "axes", "queue", "max rate", "commands", "base"):
        table.add_column(col)
    for v in spec.variants.values():
        table.add_row(v.id, v.title, v.firmware, "".join(v.axes), str(v.queue), f"{v.max_rate:,}",
                      str(len(v.commands)), v.base or "-")
    _console().print(table)
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
@click.argument("variant")
@click.argument("command", required=False)
def show_cmd(variant: str, command: str | None) -> None:
    """Show a variant's commands (or one command) with ranges and manual clauses."""
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
                raise click.ClickException(f"no command {command!r} in the tables")
            raise click.ClickException(f"{v.id} has no command {command!r} (absent in this version)")
        table = Table(title=f"{v.id}: {cmd.id}", show_header=False)
        table.add_column("field")
        table.add_column("value")
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
        for k, val in rows:
            table.add_row(k, val)
        console.print(table)
        return
    table = Table(title=f"{v.title} ({v.id}): axes {''.join(v.axes)}, queue {v.queue}, "
                        f"max {v.max_rate:,} pulses/s")
    for col in ("command", "addr", "parameters", "answer", "modal", "running", "clause"):
        table.add_column(col, overflow="fold")
    for cmd in v.commands.values():
        table.add_row(cmd.id, ",".join(map(str, cmd.addresses)), _params(cmd, v),
                      ",".join(f.name for f in cmd.answer) or "-", "yes" if cmd.modal else "",
                      "" if cmd.while_running else "7", cmd.clause_for(v.manual))
    console.print(table)


@cli.command("diff")
@click.argument("a")
@click.argument("b")
def diff_cmd(a: str, b: str) -> None:
    """What differs from variant A to variant B."""
    spec = load_spec()
    va, vb = spec.variant(a), spec.variant(b)
    diffs = diff_variants(va, vb)
    table = Table(title=f"{va.id} → {vb.id}: {len(diffs)} differences")
    for col in ("kind", "what", a, b, "clause"):
        table.add_column(col, overflow="fold")
    for d in diffs:
        table.add_row(d.kind, d.what, str(d.a), str(d.b), d.clause)
    _console().print(table)


@cli.command("questions")
def questions_cmd() -> None:
    """The open questions the manuals leave, with the assumed default."""
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
    """Load and validate the tables; one line per problem, non-zero exit."""
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
