"""``conform run``: conformance checks against the emulator or a real unit, with reports."""

from __future__ import annotations

import sys
from functools import partial
from pathlib import Path

import click

from conform.cli.params import (
    BAUD,
    INPUT_FILE,
    NON_NEGATIVE_INT,
    OUTPUT_DIR,
    POSITIVE_INT,
    TARGET,
    VARIANT,
    command_line,
    echo_json,
    json_option,
)
from conform.cli.progress import progress as show_progress
from conform.conformance.results import Grade, TargetRun
from conform.conformance.runner import RunAborted, RunOptions
from conform.conformance.suite import PROFILE_NAMES, parse_replay, results_of
from conform.conformance.target import parse_target
from conform.errors import UserError
from conform.families.gve.conformance.profile import load_profile_dialect
from conform.families.gve.conformance.safety import run_guard
from conform.families.gve.conformance.suite import run_mutants, run_one, suite
from conform.families.gve.conformance.target import DEFAULT_VARIANT, identify, open_target
from conform.families.gve.spec import load_spec
from conform.report.render import default_dir, link_latest, not_verified_lines, write_reports


@click.command(name="run")
@click.option("--target", "targets", multiple=True, metavar="T", type=TARGET,
              help="emu:VARIANT[:MUTANT], a device path, a pty or a pyserial URL "
                   "(socket://, rfc2217://). Repeat for several. Default: emu:gve64-v19.")
@click.option("--variant", type=VARIANT, default=None, help="The model expected (default: the emulator's, "
              "else ask '?' and map the firmware string, else gve64-v19).")
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
@click.option("--seed", type=NON_NEGATIVE_INT, default=0, show_default=True, help="State-machine seed.")
@click.option("--dialect", "dialect_file", type=INPUT_FILE, default=None,
              help="Expect this characterised profile's dialect instead of the defaults.")
@click.option("--allow-motion", is_flag=True, help="Real units: allow checks that move axes, "
              "switch outputs or start the spindle (needs --max-steps).")
@click.option("--max-steps", type=POSITIVE_INT, default=None, help="Bound on every axis move (pulses).")
@click.option("--allow-eeprom", is_flag=True, help="Real units: allow EEPROM writes.")
@click.option("--no-machine", is_flag=True, help="Skip the random-sequence state machine.")
@click.option("--inputs-control", default=None, metavar="PATH",
              help="Drive the inputs of an emulator behind the link through its control socket "
                   "(`conform emulate serve` prints it), for the checks that need inputs.")
@click.option("-q", "--quiet", is_flag=True, help="No progress display.")
@json_option("the results in results.json's format, plus the report folder")
def cli(targets: tuple[str, ...], variant: str | None, baud: int, profile: str,
        report_dir: str | None, patterns: tuple[str, ...], list_only: bool, matrix: bool,
        mutants: bool, replay: str | None, seed: int, dialect_file: str | None,
        allow_motion: bool, max_steps: int | None, allow_eeprom: bool, no_machine: bool,
        inputs_control: str | None, quiet: bool, as_json: bool) -> None:
    """Run the conformance checks; exit 0 when nothing FAILs, 1 when something does, 2 for a
    usage or link error (or a run that stopped early).

    \b
    Examples:
      conform run                                   # the GVE64 v19 emulator, quick profile
      conform run --matrix --json > results.json    # all four variants, results on stdout
      conform run --target /dev/ttyUSB0 --allow-motion --max-steps 2000
      xdg-open reports/latest/index.html            # the last run's report
    """
    if _other_family(targets, variant):
        if mutants or matrix or replay or dialect_file:
            raise UserError("--mutants, --matrix, --replay and --dialect apply to GVE units only")
        _run_family(targets, variant, baud, profile, report_dir, patterns, list_only,
                    allow_motion, allow_eeprom)
        return
    spec = load_spec()
    if variant is not None:
        spec.variant(variant)
    if allow_motion and max_steps is None:
        raise UserError("--allow-motion needs --max-steps N (the bound on every axis move)")
    if max_steps is not None and max_steps <= 0:
        raise UserError("--max-steps must be a positive number of pulses")
    command = command_line()
    exact = None
    if replay:
        check_id, replay_seed = parse_replay(replay)
        exact = check_id
        if replay_seed is not None:
            seed = replay_seed
        if variant is None and "/" in check_id:
            variant = check_id.split("/", 1)[0]
            spec.variant(variant)
    plan = list(targets) or ([f"emu:{v}" for v in spec.variants] if matrix else ["emu"])
    if matrix and targets:
        plan += [f"emu:{v}" for v in spec.variants if f"emu:{v}" not in plan]
    dialect = load_profile_dialect(spec, dialect_file) if dialect_file else None

    if list_only:
        listed = []
        for t in plan:
            kind, what, _ = parse_target(t)
            vid = variant or (what if kind == "emu" and what else DEFAULT_VARIANT)
            for c in suite(spec, vid, patterns=patterns, machine=not no_machine,
                           profile=profile):
                listed.append({"id": c.id, "level": c.level, "clause": c.clause,
                               "title": c.title})
                if not as_json:
                    click.echo(f"{c.id}\t{c.level}\t{c.clause}\t{c.title}")
        if as_json:
            echo_json({"checks": listed})
        return

    runs: list[TargetRun] = []
    aborted = None
    with show_progress("conform run", quiet=quiet) as bar:
        for t in plan:
            kind, what, _ = parse_target(t)
            guard = run_guard(kind == "emu", allow_motion, max_steps, allow_eeprom)
            target, implied = open_target(t, spec, baud=baud, guard=guard)
            if inputs_control and not target.emulated:
                target.inputs = inputs_control  # type: ignore[attr-defined]
            notes = []
            try:
                vid = variant or implied
                if vid is None:
                    vid, how = identify(target, spec)
                    notes.append(f"variant: {how}")
                checks = suite(spec, vid, patterns=patterns, guard=guard,
                               machine=not no_machine, profile=profile)
                if exact is not None:  # ids hold glob characters (?, *S): match exactly
                    checks = [c for c in checks if c.id == exact]
                if not checks:
                    wanted = exact or " ".join(patterns) or "(all)"
                    raise UserError(f"no check of {vid} matches {wanted} (see --list)")
                if not target.emulated and not allow_motion:
                    notes.append("motion-bearing checks SKIPPED (no --allow-motion)")
                options = RunOptions(profile=profile, seed=seed, notes=notes,
                                     announce=None if quiet else
                                     (lambda text: click.echo(text, err=True)))
                progress = _step(bar.task(f"{target.name} ({vid})", len(checks)), checks)
                try:
                    run = run_one(spec, target, vid, checks, options=options, dialect=dialect,
                                  progress=progress)
                    runs.append(run)
                    if run.aborted:
                        aborted = run.aborted
                        break
                except RunAborted as exc:
                    runs.append(exc.run)
                    aborted = exc.run.aborted
                    break
            finally:
                target.close()
        mutant_report = []
        if mutants and aborted is None:
            from conform.families.gve.conformance.mutants import mutant_targets

            variants = [r.variant for r in runs] or [DEFAULT_VARIANT]
            task = bar.task("mutants", len(list(mutant_targets(variants))))
            mutant_report, _ = run_mutants(
                spec, variants, profile=profile, seed=seed,
                progress=lambda s: task.update(advance=1, step=s))
    results = results_of(runs, command, mutant_report)
    out = Path(report_dir) if report_dir else default_dir()
    write_reports(results, out)
    if not report_dir:
        link_latest(out)
    code = 2 if aborted is not None else 1 if results.failed() else 0
    if as_json:
        echo_json(results.to_json() | {"report": str(out), "exit": code})
    _print_summary(results, out, err=as_json)
    if aborted is not None:
        raise UserError(f"run aborted: {aborted}", exit_code=2)
    if code:
        sys.exit(code)


def _step(task, checks):  # noqa: ANN001, ANN202 - a progress Task, the checks in run order
    """The runner's per-check callback: advance, count FAILs, name the check now running."""
    fails = [0]

    def step(result):  # noqa: ANN001, ANN202
        fails[0] += result.grade is Grade.FAIL
        done = int(task.completed) + 1
        upcoming = checks[done].id if done < len(checks) else "writing the report"
        task.update(advance=1, step=(f"FAIL {fails[0]} · " if fails[0] else "") + upcoming)

    if checks:
        task.update(step=checks[0].id)
    return step


def _other_family(targets: tuple[str, ...], variant: str | None) -> bool:
    """Does this run address a non-GVE protocol family (conform.families)?"""
    from conform.families import is_family_variant

    wanted = [variant] + [parse_target(t)[1] for t in targets if parse_target(t)[0] == "emu"]
    return any(is_family_variant(v, "grbl") for v in wanted)


def _run_family(targets: tuple[str, ...], variant: str | None, baud: int, profile: str,
                report_dir: str | None, patterns: tuple[str, ...], list_only: bool,
                allow_motion: bool, allow_eeprom: bool) -> None:
    """grbl targets: the family's checks, the engine's results, reports and exit codes."""
    from conform.families.grbl.checks import run_targets

    runs = run_targets(list(targets) or [f"emu:{variant}"], variant, baud=baud,
                       patterns=patterns, profile=profile, allow_motion=allow_motion,
                       allow_eeprom=allow_eeprom, list_only=list_only, echo=click.echo,
                       announce=lambda text: click.echo(text, err=True))
    if list_only:
        return
    results = results_of(runs, command_line())
    out = Path(report_dir) if report_dir else default_dir()
    write_reports(results, out)
    _print_summary(results, out)
    aborted = next((r.aborted for r in runs if r.aborted), None)
    if aborted is not None:
        raise UserError(f"run aborted: {aborted}", exit_code=2)
    if results.failed():
        sys.exit(1)


def _print_summary(results, out: Path, err: bool = False) -> None:  # noqa: ANN001
    echo = partial(click.echo, err=err)
    for r in results.runs:
        counts = r.counts()
        shown = ", ".join(f"{k} {v}" for k, v in counts.items() if v)
        echo(f"{r.target} ({r.variant}, {r.profile}): {shown} in {r.duration:.1f} s")
        for c in r.checks:
            if c.grade is Grade.FAIL:
                echo(f"  FAIL {c.id} [{c.clause}] expected {c.expected} / got {c.actual}")
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
    echo(f"report: {out / 'index.html'}")
