"""``conform run``'s loop over targets, the same for every family: the plan (targets,
``--matrix``, ``--replay``), what the run may do to a real unit, the variant identified, each
target's checks in the family's runner with a progress bar, ``--list`` and the mutant run.

A family gives what differs (``Family.open_target``, ``identify``, ``plan_checks``,
``runner``, ``run_mutants``); the command (conform/cli/run_cmd.py) writes the reports, the
summary and the exit code.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from conform.conformance.results import Grade, TargetRun
from conform.conformance.runner import Progress, RunAborted, RunOptions
from conform.conformance.suite import parse_replay
from conform.conformance.target import parse_target
from conform.errors import UserError


@dataclass(frozen=True)
class Permissions:
    """What a run may do to the unit: an emulator everything (inside ``max_steps`` when
    given, so it plans the checks a real unit would get), a real unit what was opted into."""

    emulated: bool
    allow_motion: bool
    max_steps: int | None
    allow_eeprom: bool

    @classmethod
    def of(cls, emulated: bool, allow_motion: bool, max_steps: int | None,
           allow_eeprom: bool) -> Permissions:
        if emulated:
            return cls(True, True, max_steps, True)
        return cls(False, allow_motion, max_steps, allow_eeprom)


def run_targets(fam: Any, targets: Sequence[str], variant: str | None, *, baud: int = 115200,
                profile: str = "quick", patterns: Sequence[str] = (), list_only: bool = False,
                matrix: bool = False, mutants: bool = False, replay: str | None = None,
                seed: int = 0, allow_motion: bool = False, max_steps: int | None = None,
                allow_eeprom: bool = False, no_machine: bool = False,
                inputs_control: str | None = None, quiet: bool = False, as_json: bool = False,
                echo: Callable[[str], None] = print,
                announce: Callable[[str], None] | None = None, **family_values: Any
                ) -> tuple[list[TargetRun], list[dict[str, Any]]] | None:
    """Run ``fam``'s checks on each target; (runs, mutant report), or None after ``--list``."""
    from conform.cli.params import echo_json
    from conform.cli.progress import progress as show_progress

    known = [v.id for v in fam.variants()]
    if variant is not None and variant not in known:
        from conform.families import unknown_variant

        raise UserError(unknown_variant(variant, fam.name))
    if allow_motion and max_steps is None and fam.needs_travel_bound:
        raise UserError("--allow-motion needs --max-steps N (the bound on every axis move)")
    if max_steps is not None and max_steps <= 0:
        raise UserError("--max-steps must be a positive number")
    exact = None
    if replay:
        exact, replay_seed = parse_replay(replay)
        if replay_seed is not None:
            seed = replay_seed
        if variant is None and "/" in exact and exact.split("/", 1)[0] in known:
            variant = exact.split("/", 1)[0]
    plan = list(targets) or ([f"emu:{v}" for v in known] if matrix else
                             [f"emu:{variant or fam.default_variant}"])
    if matrix and targets:
        plan += [f"emu:{v}" for v in known if f"emu:{v}" not in plan]
    machine = not no_machine

    if list_only:
        listed = []
        for t in plan:
            kind, what, _ = parse_target(t)
            vid = variant or (what if kind == "emu" and what else fam.default_variant)
            perms = Permissions.of(kind == "emu", allow_motion, max_steps, allow_eeprom)
            for c in fam.plan_checks(vid, permissions=perms, profile=profile, patterns=patterns,
                                     machine=machine, **family_values):
                listed.append({"id": c.id, "level": c.level, "clause": c.clause,
                               "title": c.title, "variant": vid})
                if not as_json:
                    echo(f"{c.id}\t{c.level}\t{c.clause}\t{c.title}")
        if as_json:
            echo_json({"checks": listed})
        return None

    runs: list[TargetRun] = []
    aborted = None
    mutant_report: list[dict[str, Any]] = []
    with show_progress("conform run", quiet=quiet) as bar:
        for t in plan:
            kind, what, _ = parse_target(t)
            if kind == "emu" and what and what not in known:
                raise UserError(f"target {t!r} is not a {fam.name} unit: run each family's "
                                "targets separately")
            perms = Permissions.of(kind == "emu", allow_motion, max_steps, allow_eeprom)
            target, implied = fam.open_target(t, baud=baud, permissions=perms,
                                              inputs_control=inputs_control, **family_values)
            notes: list[str] = []
            try:
                vid = variant or implied
                if vid is None:
                    vid, how = fam.identify(target)
                    notes.append(f"variant: {how}")
                checks = fam.plan_checks(vid, permissions=perms, profile=profile,
                                         patterns=patterns, machine=machine, **family_values)
                if exact is not None:  # ids hold glob characters (?, *S): match exactly
                    checks = [c for c in checks if c.id == exact]
                if not checks:
                    wanted = exact or " ".join(patterns) or "(all)"
                    raise UserError(f"no check of {vid} matches {wanted} (see --list)")
                if not target.emulated:
                    notes += fam.permission_notes(perms)
                options = RunOptions(profile=profile, seed=seed, notes=notes, announce=announce)
                runner = fam.runner(target, vid, options=options, permissions=perms,
                                    **family_values)
                step = _step(bar.task(f"{target.name} ({vid})", len(checks)), checks)
                try:
                    run = runner.run(checks, step)
                except RunAborted as exc:
                    run = exc.run
                runs.append(run)
                if run.aborted:
                    aborted = run.aborted
                    break
            finally:
                target.close()
        if mutants and aborted is None:
            variants = [r.variant for r in runs] or [fam.default_variant]
            task = bar.task("mutants", fam.mutant_count(variants))
            mutant_report = fam.run_mutants(variants, profile=profile, seed=seed,
                                            progress=lambda s: task.update(advance=1, step=s))
    return runs, mutant_report


def _step(task: Any, checks: Sequence[Any]) -> Progress:
    """The runner's per-check callback: advance, count FAILs, name the check now running."""
    fails = [0]

    def step(result: Any) -> None:
        fails[0] += result.grade is Grade.FAIL
        done = int(task.completed) + 1
        upcoming = checks[done].id if done < len(checks) else "writing the report"
        task.update(advance=1, step=(f"FAIL {fails[0]} · " if fails[0] else "") + upcoming)

    if checks:
        task.update(step=checks[0].id)
    return step
