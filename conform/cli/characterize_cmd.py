"""``conform characterize TARGET -o profile.toml``: what a unit does where its builds (or its
documents) leave a choice. Each family says what it asks of its units
(``Family.characterize_about``); the help lists them."""

from __future__ import annotations

import click

from conform.cli.outputs import force_option, fresh_output
from conform.cli.params import BAUD, OUTPUT_FILE, POSITIVE_INT, TARGET, VARIANT, quiet_option
from conform.conformance.target import parse_target


class _Characterize(click.Command):
    """The command's help, followed by what each family's characterisation asks."""

    def format_help_text(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        super().format_help_text(ctx, formatter)
        from conform.errors import UserError
        from conform.families import families

        try:
            rows = [(f.name, f.characterize_about) for f in families() if f.characterize_about]
        except UserError:
            return
        if rows:
            with formatter.section("What each family asks"):
                formatter.write_dl(rows)


@click.command(name="characterize", cls=_Characterize)
@click.argument("target", type=TARGET)
@click.option("-o", "--output", type=OUTPUT_FILE, required=True,
              help="Profile to write (TOML: what the unit does on each item probed, with the "
                   "evidence).")
@force_option("the -o profile")
@click.option("--variant", type=VARIANT, default=None,
              help="The model (default: the emulator's, else the unit that answers "
                   "`conform ports --probe`'s harmless questions).")
@click.option("--baud", type=BAUD, default=115200, show_default=True)
@click.option("--allow-motion", is_flag=True, help="Real units: allow probes that move axes.")
@click.option("--max-steps", type=POSITIVE_INT, default=None, help="Bound on every axis move (pulses).")
@click.option("--allow-eeprom", is_flag=True,
              help="Real units: allow probes that write the EEPROM (where a family has them).")
@quiet_option()
def cli(target: str, output: str, force: bool, variant: str | None, baud: int,
        allow_motion: bool, max_steps: int | None, allow_eeprom: bool, quiet: bool) -> None:
    """Probe what the unit does where its builds or documents leave a choice, and write it
    as a profile (what each family asks is listed below). Stopped by Ctrl-C, SIGTERM or
    SIGHUP, it halts the unit and writes what it found so far, marked partial (`conform
    profile diff` names what is missing); exit 128 + N.

    \b
    Examples:
      conform characterize emu:gve64-v19 -o unit.toml
      conform characterize emu:grbl-1.1f -o grbl.toml
      conform characterize /dev/ttyUSB0 -o unit.toml --variant marlin-2.1
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
