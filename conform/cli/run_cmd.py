"""``conform run``: conformance checks against the emulator or a real unit, with reports."""

from __future__ import annotations

import sys
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import click

from conform.cli.family_options import family_options, split
from conform.cli.params import (
    BAUD,
    OUTPUT_DIR,
    POSITIVE_INT,
    TARGET,
    VARIANT,
    command_line,
    default_variant_text,
    echo_json,
    json_option,
    quiet_option,
    seed_option,
)
from conform.cli.progress import progress
from conform.conformance.plan import list_checks, run_targets
from conform.conformance.results import Grade
from conform.conformance.suite import PROFILE_NAMES, results_of
from conform.conformance.target import parse_target
from conform.errors import UserError, writable_folder
from conform.report.render import default_dir, link_latest, not_verified_lines, write_reports
from conform.stops import exit_status, shield

if TYPE_CHECKING:
    from conform.families import Family


@family_options("run")
@click.command(name="run")
@click.option("--target", "targets", multiple=True, metavar="T", type=TARGET,
              help="emu:VARIANT[:MUTANT], a device path, a pty or a pyserial URL "
                   f"(socket://, rfc2217://). Repeat for several. Default: emu:{default_variant_text()}.")
@click.option("--variant", type=VARIANT, default=None, help="The model expected (default: the emulator's, "
              f"else identify the unit, else {default_variant_text()}).")
@click.option("--baud", type=BAUD, default=115200, show_default=True)
@click.option("--profile", type=click.Choice(PROFILE_NAMES), default="quick", show_default=True)
@click.option("--report", "report_dir", type=OUTPUT_DIR, default=None,
              help="Report folder (default reports/<timestamp>/, linked as reports/latest).")
@click.option("--check", "patterns", multiple=True, metavar="GLOB",
              help="Only checks whose id matches (e.g. '*/C/*'); repeatable.")
@click.option("--list", "list_only", is_flag=True, help="List the check ids and exit.")
@click.option("--matrix", is_flag=True, help="Every variant on its emulator, side by side.")
@click.option("--mutants", is_flag=True,
              help="Also run the deviant units and report the kill rate.")
@click.option("--replay", default=None, metavar="ID[@SEED]",
              help="Re-run one check (a state-machine check with the seed that found it).")
@seed_option()
@click.option("--allow-motion", is_flag=True, help="Real units: allow checks that move axes, "
              "switch outputs or start the spindle (needs --max-steps).")
@click.option("--max-steps", type=POSITIVE_INT, default=None, help="Bound on every axis move (pulses).")
@click.option("--allow-eeprom", is_flag=True, help="Real units: allow EEPROM writes.")
@click.option("--no-machine", is_flag=True, help="Skip the random-sequence state machine.")
@click.option("--inputs-control", default=None, metavar="PATH",
              help="Drive the inputs of an emulator behind the link through its control socket "
                   "(`conform emulate serve` prints it), for the checks that need inputs.")
@quiet_option()
@json_option("the results in results.json's format, plus the report folder")
def cli(targets: tuple[str, ...], variant: str | None, baud: int, profile: str,
        report_dir: str | None, patterns: tuple[str, ...], list_only: bool, matrix: bool,
        mutants: bool, replay: str | None, seed: int,
        allow_motion: bool, max_steps: int | None, allow_eeprom: bool, no_machine: bool,
        inputs_control: str | None, quiet: bool, as_json: bool, **family_values: object) -> None:
    """Run the conformance checks; exit 0 when nothing FAILs, 1 when something does, 2 for a
    usage or link error, a check that could not be run (ERROR) or a run that stopped early.

    \b
    Examples:
      conform run                                   # the GVE64 v19 emulator, quick profile
      conform run --matrix --json > results.json    # all four variants, results on stdout
      conform run --target /dev/ttyUSB0 --allow-motion --max-steps 2000
      xdg-open reports/latest/index.html            # the last run's report
    """
    if report_dir:   # before the run: a folder that cannot be written is one line now
        writable_folder(report_dir, "--report")
    fam, variant = _family_of(targets, variant, baud, probe=not list_only, quiet=quiet)
    if matrix and len(fam.variants()) < 2:
        raise UserError(f"--matrix sets a family's variants side by side; {fam.name} has one "
                        f"({fam.default_variant}): leave --matrix out")
    if inputs_control and all(parse_target(t)[0] == "emu" for t in targets or ["emu"]):
        raise UserError(f"--inputs-control {inputs_control}: drives the inputs of an emulator "
                        "behind a port (--target PORT); an emu: target's inputs are driven "
                        "in-process: leave the option out")
    if mutants and not fam.mutants():
        raise fam.lacks("mutants (--mutants)")
    command = command_line()
    mine = split("run", fam.name, family_values)
    if list_only:
        listed = list_checks(fam, targets, variant, profile=profile, patterns=patterns,
                             matrix=matrix, replay=replay, allow_motion=allow_motion,
                             max_steps=max_steps, allow_eeprom=allow_eeprom,
                             no_machine=no_machine, **mine)
        if as_json:
            echo_json({"checks": listed})
        for c in [] if as_json else listed:
            click.echo(f"{c['id']}\t{c['level']}\t{c['clause']}\t{c['title']}")
        return
    with progress("conform run", quiet=quiet) as bar:
        runs, mutant_report = run_targets(
            fam, list(targets), variant, display=bar, baud=baud, profile=profile,
            patterns=patterns, matrix=matrix, mutants=mutants, replay=replay, seed=seed,
            allow_motion=allow_motion, max_steps=max_steps, allow_eeprom=allow_eeprom,
            no_machine=no_machine, inputs_control=inputs_control,
            announce=None if quiet else (lambda text: click.echo(text, err=True)), **mine)
    aborted = next((r.aborted for r in runs if r.aborted), None)
    results = results_of(runs, command, mutant_report)
    out = Path(report_dir) if report_dir else default_dir()
    with shield():   # a second signal must not cut the report of an interrupted run short
        write_reports(results, out)
        if not report_dir and not replay:   # a one-check replay leaves the last run's report
            link_latest(out)
    # a FAIL is about the unit (1); an ERROR says a check could not be run at all (2)
    code = exit_status(2 if aborted is not None else 1 if results.failed() else
                       2 if results.errored() else 0)   # a signal's 128 + N first
    if as_json:
        echo_json(results.to_json() | {"report": str(out), "exit": code})
    _print_summary(results, out, err=as_json)
    if aborted is not None:
        raise UserError(f"run aborted: {aborted}", exit_code=2)
    if code:
        sys.exit(code)


def _family_of(targets: tuple[str, ...], variant: str | None, baud: int = 115200, *,
               probe: bool = False, quiet: bool = False) -> tuple[Family, str | None]:
    """The family whose units this run addresses (conform.families), one per run, and the
    variant expected. ``probe``: a port given no ``--variant`` is asked `conform ports
    --probe`'s harmless questions, in the families' probe order (never one family's identify,
    which another family's unit may act on), and a port where nobody answers is refused."""
    from conform.families import Family, default_family, family, family_for_variant, unit_on_port

    wanted = [variant] + [parse_target(t)[1] for t in targets if parse_target(t)[0] == "emu"]
    named = {family_for_variant(v).name for v in wanted if v}
    ports = [t for t in targets if parse_target(t)[0] != "emu"]
    if probe and variant is None and ports:
        found = [unit_on_port(p, baud=baud) for p in ports]
        named |= {f.name for f, _ in found}
        for p, (_, vid) in zip(ports, found, strict=True):
            if not quiet:
                click.echo(f"{p}: {vid} answered", err=True)
        if len(targets) == 1 and type(found[0][0]).identify is Family.identify:
            # a family that does not ask its units itself takes the probe's variant; one that
            # does asks again (its own question, harmless to its own unit) and notes the answer
            variant = found[0][1]
    if len(named) > 1:
        raise UserError(f"this run names units of {' and '.join(sorted(named))}: run each "
                        "family's targets separately")
    return (family(named.pop()) if named else default_family()), variant


def _print_summary(results, out: Path, err: bool = False) -> None:  # noqa: ANN001
    from conform.report.view import causes, headline

    echo = partial(click.echo, err=err)
    grouped = causes(results)
    for r in results.runs:
        counts = r.counts()
        shown = ", ".join(f"{k} {v}" for k, v in counts.items() if v)
        echo(f"{r.target} ({r.variant}, {r.profile}): {shown} in {r.duration:.1f} s")
        for note in r.notes:
            if note.startswith("hint: "):
                echo(f"  {note}")
        told: set[int] = set()
        for cause in (g for g in grouped if g.checks[0].target == r.target):
            echo(f"  FAIL ×{len(cause.checks)} {cause.sentence()}")
            told.update(id(c) for c in cause.checks)
        for c in r.checks:
            if c.grade is Grade.FAIL and id(c) not in told:
                echo(f"  FAIL {c.id} [{c.clause}] expected {c.expected} / got {c.actual}")
            elif c.grade is Grade.ERROR:
                echo(f"  ERROR {c.id}: {c.detail.splitlines()[0] if c.detail else 'no detail'}")
        if r.aborted:
            echo(f"  INCOMPLETE: {r.aborted}")
    if results.mutants:
        killed = sum(1 for m in results.mutants if m["killed"])
        echo(f"mutants: {killed}/{len(results.mutants)} killed")
        for m in results.mutants:
            if not m["killed"]:
                echo(f"  SURVIVED {m['name']} ({m['fault']})")
    for line in not_verified_lines(results):
        echo(line)
    scope = headline(results).scope
    if scope:
        echo(scope)
    echo(f"report: {out / 'index.html'}")
