"""``conform characterize TARGET -o profile.toml``: what a unit does on each open question."""

from __future__ import annotations

import click

from conform.cli.outputs import force_option, fresh_output
from conform.cli.params import BAUD, OUTPUT_FILE, POSITIVE_INT, TARGET, VARIANT, quiet_option
from conform.conformance.target import parse_target


@click.command(name="characterize")
@click.argument("target", type=TARGET)
@click.option("-o", "--output", type=OUTPUT_FILE, required=True,
              help="Profile to write (TOML: [dialect] A-id = alternative, plus evidence).")
@force_option("the -o profile")
@click.option("--variant", type=VARIANT, default=None,
              help="The model (default: the emulator's, else the unit that answers "
                   "`conform ports --probe`'s harmless questions).")
@click.option("--baud", type=BAUD, default=115200, show_default=True)
@click.option("--allow-motion", is_flag=True, help="Real units: allow probes that move axes.")
@click.option("--max-steps", type=POSITIVE_INT, default=None, help="Bound on every axis move (pulses).")
@click.option("--allow-eeprom", is_flag=True, help="Real units: allow EEPROM write probes (A18).")
@quiet_option()
def cli(target: str, output: str, force: bool, variant: str | None, baud: int,
        allow_motion: bool, max_steps: int | None, allow_eeprom: bool, quiet: bool) -> None:
    """Probe the open questions A1–A29 and write what the unit actually does. Stopped by
    Ctrl-C, SIGTERM or SIGHUP, it halts the unit and writes the questions answered so far,
    marked partial (`conform profile diff` names the missing ones); exit 128 + N.

    \b
    Examples:
      conform characterize emu:gve64-v19 -o unit.toml
      conform characterize /dev/ttyUSB0 -o unit.toml --allow-motion --max-steps 2000
    """
    from conform.families import family_for_variant, unit_on_port

    fresh_output(output, force, "-o")
    kind, named, _ = parse_target(target)
    if kind != "emu" and variant is None:   # ask what every family's unit answers harmlessly
        _, variant = unit_on_port(target, baud=baud)
        if not quiet:
            click.echo(f"variant: {variant} answered on {target}", err=True)
    family_for_variant(variant or named or "").characterize(
        target, output, variant, baud=baud, allow_motion=allow_motion, max_steps=max_steps,
        allow_eeprom=allow_eeprom, quiet=quiet, echo=click.echo)
