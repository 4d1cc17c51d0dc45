"""GVE's side of the command line: what ``conform characterize`` probes and writes, what
``conform spec show|diff|questions`` print for GVE variants, the family's own subcommand
(``profile``, the dialect profiles of ``characterize``) and its
options on the engine's commands (``--dialect`` on ``run``; the A-register, reference switches
and ground truth on ``emulate serve``). The engine reaches these through the family registry
(conform.families, conform.cli.family_options)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import click
from rich.table import Table

from conform.cli.params import INPUT_FILE
from conform.cli.progress import progress
from conform.conformance.target import parse_target
from conform.errors import UserError
from conform.families.gve.conformance.characterize import characterize as probe
from conform.families.gve.conformance.profile import write_profile
from conform.families.gve.conformance.safety import Guard
from conform.families.gve.conformance.target import identify, open_target
from conform.families.gve.spec import load_spec
from conform.families.gve.spec.model import CommandSpec, Variant
from conform.stops import halting


def characterize(target: str, output: str, variant: str | None, *, baud: int = 115200,
                 allow_motion: bool = False, max_steps: int | None = None,
                 allow_eeprom: bool = False, quiet: bool = False,
                 echo: Callable[..., None] = click.echo) -> None:
    """Probe the open questions A1–A29 on ``target`` and write the profile to ``output``; an
    interrupted characterisation writes the questions answered so far, marked partial."""
    from conform.families.gve.conformance.characterize import to_profile

    spec = load_spec()
    if allow_motion and max_steps is None:
        raise UserError("--allow-motion needs --max-steps N (the bound on every axis move)")
    kind, _, _ = parse_target(target)
    guard = Guard.emulated() if kind == "emu" else Guard(allow_motion, max_steps, allow_eeprom)
    tgt, implied = open_target(target, spec, baud=baud, guard=guard)
    try:
        vid = variant or implied
        if not tgt.emulated:   # a dead port must not read as a unit that matches the manual
            _answers(tgt, target)
        if vid is None:
            vid, how = identify(tgt, spec)
            echo(f"variant: {how}", err=True)
        spec.variant(vid)

        def show(f):  # noqa: ANN001, ANN202
            mark = {"determined": "=", "ambiguous": "~", "no-match": "!", "not-probed": "-"}
            echo(f"{f.question:>4} {mark[f.status]} {f.choice:<28} {f.status}"
                 + (f" ({', '.join(f.matches)})" if f.status == "ambiguous" else "")
                 + (f" — {f.note}" if f.status == "not-probed" else ""))

        findings: dict[str, Any] = {}

        def partial(how: str) -> str:
            """The questions answered before the stop, marked partial (the rest listed): a
            question counts once the unit answered its probe, not when it was skipped."""
            answered = {q: f for q, f in findings.items() if f.answers}
            n = len(answered)
            write_profile(to_profile(spec, None, answered, target=target, variant=vid,
                                     interrupted=f"{how} after {n} of "
                                                 f"{len(spec.questions)} questions"), output)
            return f"partial profile {output}: {n} of {len(spec.questions)} questions answered"

        with progress("conform characterize", quiet=quiet) as bar:
            task = bar.task(f"{target} ({vid})", len(spec.questions))

            def step(f):  # noqa: ANN001, ANN202
                show(f)

            with halting(None if tgt.emulated else tgt.safe_stop, partial):
                dialect, findings = probe(
                    spec, tgt, vid, progress=step, findings=findings,
                    probing=lambda q: task.update(completed=len(findings), step=q))
                task.update(completed=len(spec.questions), step="")
        if not tgt.emulated and allow_motion:
            echo(tgt.safe_stop(), err=True)
    finally:
        tgt.close()
    write_profile(to_profile(spec, dialect, findings, target=target, variant=vid), output)
    changed = dialect.changed()
    echo(f"{output}: {len(changed)} answer(s) differ from the defaults"
         + (": " + ", ".join(f"{k}={v}" for k, v in changed.items()) if changed else ""))


def _answers(tgt: Any, target: str) -> None:
    """The unit on ``tgt`` answers ``?`` (it only reads the firmware string, GVE64 §13.5.1),
    in either checksum framing; else one line, before any probe and before a profile of
    defaults could be written."""
    from conform.conformance.target import HarnessError

    for checksum in (False, True):
        try:
            reply = tgt.exchange(tgt.frame("!0?", checksum=checksum), timeout=1.0)
        except HarnessError:
            continue
        if reply.lines:
            return
    raise UserError(f"{target}: no answer to '?' within 1 s: is the unit on, on this port and "
                    "at this baud rate (--baud)? Nothing was written")


def show_spec(variant: str, command: str | None, *, console: Any, as_json: bool) -> None:
    """A variant's commands with ranges and clauses, or one command in detail."""
    from conform.cli.params import echo_json
    from conform.cli.spec_cmd import _emit

    spec = load_spec()
    v = spec.variant(variant)
    if command is not None:
        cmd = v.command(command)
        if cmd is None:
            known = spec.commands.get(command)
            if known is None:
                raise UserError(f"no command {command!r} in {v.id}'s tables (`conform spec "
                                f"show {v.id}` lists them)")
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


def variant_table(pretty: bool) -> tuple[str, tuple[str, ...], list[Sequence[Any]]]:
    """``conform spec list``'s GVE table: title, columns, rows (``pretty``: for a terminal)."""
    spec = load_spec()
    rows: list[Sequence[Any]] = [
        (v.id, v.title, v.firmware, "".join(v.axes), v.queue, v.max_rate, len(v.commands),
         v.base or "-") for v in spec.variants.values()]
    if pretty:
        rows = [(*r[:5], f"{r[5]:,}", *r[6:]) for r in rows]
    return "GVE variants", ("variant", "title", "firmware", "axes", "queue", "max rate",
                            "commands", "base"), rows


def tables_summary(root: str | None = None) -> str:
    """``conform spec check``'s line: the tables loaded and validated."""
    spec = load_spec(root)
    n = sum(len(v.commands) for v in spec.variants.values())
    return (f"ok: gve: {len(spec.commands)} commands, {len(spec.variants)} variants "
            f"({n} variant commands), {len(spec.questions)} open questions, "
            f"{len(spec.examples)} examples")


def diff_table(a: str, b: str) -> tuple[str, list[str], list[tuple[Any, ...]]]:
    """``conform spec diff``: what differs from variant ``a`` to ``b`` in the GVE tables."""
    from conform.families.gve.spec.diff import diff_variants

    spec = load_spec()
    va, vb = spec.variant(a), spec.variant(b)
    diffs = diff_variants(va, vb)
    return (f"{va.id} → {vb.id}: {len(diffs)} differences", ["kind", "what", a, b, "clause"],
            [(d.kind, d.what, d.a, d.b, d.clause) for d in diffs])


def questions_table() -> tuple[str, list[str], list[tuple[Any, ...]]]:
    """``conform spec questions``: the A-register, each question with its default."""
    spec = load_spec()
    return ("Open questions (A-register)", ["id", "question", "default", "alternatives", "settled"],
            [(q.id, q.question, q.default, ", ".join(q.alternatives), q.settled or "")
             for q in spec.questions.values()])

def commands() -> Sequence[click.Command]:
    return ()


def command_options(command: str) -> Sequence[click.Option]:
    if command == "send":
        from conform.families.gve.sender.command import send_options

        return send_options()
    if command == "run":
        return (click.Option(["--dialect", "dialect_file"], type=INPUT_FILE, default=None,
                             help="GVE: expect this characterised profile's dialect instead of "
                                  "the defaults."),)
    if command == "emulate serve":
        return (
            click.Option(["--dialect", "dialect_pairs"], multiple=True, metavar="A<n>=ALT",
                         help="GVE: choose an open-question alternative (repeatable)."),
            click.Option(["--profile"], type=INPUT_FILE, default=None,
                         help="GVE: a TOML file whose [dialect] table chooses alternatives."),
            click.Option(["--switch", "switch_pairs"], multiple=True, metavar="AXIS=PULSES",
                         help="GVE: distance from a W's start to that axis's reference switch "
                              "(default 3000)."),
            click.Option(["--truth", "truth_path"], default=None, metavar="FILE.json",
                         help="GVE: on exit, write what the unit accepted and executed (every "
                              "vector, D/K/R/H/G/J, final position) as JSON: the ground truth "
                              "beside a recording."),
        )
    return ()
