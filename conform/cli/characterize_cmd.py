"""``conform characterize TARGET -o profile.toml``: what a unit does on each open question."""

from __future__ import annotations

import click

from conform.cli.params import BAUD, OUTPUT_FILE, POSITIVE_INT, TARGET, VARIANT
from conform.cli.progress import progress
from conform.conformance.target import parse_target
from conform.errors import UserError
from conform.families.gve.conformance.characterize import characterize, to_profile
from conform.families.gve.conformance.profile import write_profile
from conform.families.gve.conformance.safety import Guard
from conform.families.gve.conformance.target import identify, open_target
from conform.families.gve.spec import load_spec


@click.command(name="characterize")
@click.argument("target", type=TARGET)
@click.option("-o", "--output", type=OUTPUT_FILE, required=True,
              help="Profile to write (TOML: [dialect] A-id = alternative, plus evidence).")
@click.option("--variant", type=VARIANT, default=None, help="The model (default: the emulator's or ask '?').")
@click.option("--baud", type=BAUD, default=115200, show_default=True)
@click.option("--allow-motion", is_flag=True, help="Real units: allow probes that move axes.")
@click.option("--max-steps", type=POSITIVE_INT, default=None, help="Bound on every axis move (pulses).")
@click.option("--allow-eeprom", is_flag=True, help="Real units: allow EEPROM write probes (A18).")
def cli(target: str, output: str, variant: str | None, baud: int, allow_motion: bool,
        max_steps: int | None, allow_eeprom: bool) -> None:
    """Probe the open questions A1–A29 and write what the unit actually does.

    \b
    Examples:
      conform characterize emu:gve64-v19 -o unit.toml
      conform characterize /dev/ttyUSB0 -o unit.toml --allow-motion --max-steps 2000
    """
    from conform.families import is_family_variant

    if is_family_variant(variant or parse_target(target)[1], "grbl"):
        from conform.families.grbl.characterize import run

        run(target, output, variant, baud, echo=click.echo)
        return
    spec = load_spec()
    if allow_motion and max_steps is None:
        raise UserError("--allow-motion needs --max-steps N (the bound on every axis move)")
    kind, _, _ = parse_target(target)
    guard = Guard.emulated() if kind == "emu" else Guard(allow_motion, max_steps, allow_eeprom)
    tgt, implied = open_target(target, spec, baud=baud, guard=guard)
    try:
        vid = variant or implied
        if vid is None:
            vid, how = identify(tgt, spec)
            click.echo(f"variant: {how}", err=True)
        spec.variant(vid)

        def show(f):  # noqa: ANN001, ANN202
            mark = {"determined": "=", "ambiguous": "~", "no-match": "!", "not-probed": "-"}
            click.echo(f"{f.question:>4} {mark[f.status]} {f.choice:<28} {f.status}"
                       + (f" ({', '.join(f.matches)})" if f.status == "ambiguous" else "")
                       + (f" — {f.note}" if f.status == "not-probed" else ""))

        with progress("conform characterize") as bar:
            task = bar.task(f"{target} ({vid})", len(spec.questions))

            def step(f):  # noqa: ANN001, ANN202
                task.update(advance=1, step=f.question)
                show(f)

            dialect, findings = characterize(spec, tgt, vid, progress=step)
        if not tgt.emulated and allow_motion:
            click.echo(tgt.safe_stop(), err=True)
    finally:
        tgt.close()
    write_profile(to_profile(spec, dialect, findings, target=target, variant=vid), output)
    changed = dialect.changed()
    click.echo(f"{output}: {len(changed)} answer(s) differ from the defaults"
               + (": " + ", ".join(f"{k}={v}" for k, v in changed.items()) if changed else ""))
