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
from typing import TYPE_CHECKING

from conform.conformance.results import Grade, TargetRun
from conform.conformance.runner import Progress, RunAborted, RunOptions
from conform.conformance.suite import parse_replay
from conform.conformance.target import parse_target
from conform.errors import UserError

if TYPE_CHECKING:
    from conform.cli.progress import Task, Tracker
    from conform.conformance.results import CheckResult
    from conform.conformance.runner import Check
    from conform.conformance.target import Target
    from conform.families import Family


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


class _Plan:
    """The targets of a run and what it may do, from the command's options."""

    def __init__(self, fam: Family, targets: Sequence[str], variant: str | None, *,
                 matrix: bool, replay: str | None, seed: int, allow_motion: bool,
                 max_steps: int | None, allow_eeprom: bool) -> None:
        known = [v.id for v in fam.variants()]
        if variant is not None and variant not in known:
            raise UserError(f"{variant!r} is not a {fam.name} variant (known: {', '.join(known)})")
        if allow_motion and max_steps is None and fam.needs_travel_bound:
            raise UserError("--allow-motion needs --max-steps N (the bound on every axis move)")
        if max_steps is not None and max_steps <= 0:
            raise UserError("--max-steps must be a positive number")
        self.exact: str | None = None
        if replay:
            self.exact, replay_seed = parse_replay(replay)
            if replay_seed is not None:
                seed = replay_seed
            if variant is None and "/" in self.exact and self.exact.split("/", 1)[0] in known:
                variant = self.exact.split("/", 1)[0]
        self.targets = list(targets) or ([f"emu:{v}" for v in known] if matrix else
                                         [f"emu:{variant or fam.default_variant}"])
        if matrix and targets:
            self.targets += [f"emu:{v}" for v in known if f"emu:{v}" not in self.targets]
        self.fam, self.known, self.variant, self.seed = fam, known, variant, seed
        self.allow = (allow_motion, max_steps, allow_eeprom)

    def permissions(self, target: str) -> Permissions:
        return Permissions.of(parse_target(target)[0] == "emu", *self.allow)


def list_checks(fam: Family, targets: Sequence[str], variant: str | None, *,
                profile: str = "quick", patterns: Sequence[str] = (), matrix: bool = False,
                replay: str | None = None, allow_motion: bool = False,
                max_steps: int | None = None, allow_eeprom: bool = False,
                no_machine: bool = False, **family_values: object) -> list[dict[str, object]]:
    """``conform run --list``: the checks each target would get, without running them."""
    plan = _Plan(fam, targets, variant, matrix=matrix, replay=replay, seed=0,
                 allow_motion=allow_motion, max_steps=max_steps, allow_eeprom=allow_eeprom)
    listed: list[dict[str, object]] = []
    for t in plan.targets:
        kind, what, _ = parse_target(t)
        vid = plan.variant or (what if kind == "emu" and what else fam.default_variant)
        for c in fam.plan_checks(vid, permissions=plan.permissions(t), profile=profile,
                                 patterns=patterns, machine=not no_machine, **family_values):
            listed.append({"id": c.id, "level": c.level, "clause": c.clause, "title": c.title,
                           "variant": vid})
    if not listed and patterns:   # an empty list is no answer to a glob that matches nothing
        raise UserError(f"no check matches {' '.join(patterns)} (`conform run --list` lists "
                        "them all)")
    return listed


def run_targets(fam: Family, targets: Sequence[str], variant: str | None, *, display: Tracker,
                baud: int = 115200, profile: str = "quick", patterns: Sequence[str] = (),
                matrix: bool = False, mutants: bool = False, replay: str | None = None,
                seed: int = 0, allow_motion: bool = False, max_steps: int | None = None,
                allow_eeprom: bool = False, no_machine: bool = False,
                inputs_control: str | None = None,
                announce: Callable[[str], None] | None = None, **family_values: object
                ) -> tuple[list[TargetRun], list[dict[str, object]]]:
    """Run ``fam``'s checks on each target; (runs, mutant report). ``display`` shows progress:
    ``display.task(name, total)`` gives a task with ``update(advance=, step=)`` and
    ``completed`` (conform.cli.progress)."""
    plan = _Plan(fam, targets, variant, matrix=matrix, replay=replay, seed=seed,
                 allow_motion=allow_motion, max_steps=max_steps, allow_eeprom=allow_eeprom)
    runs: list[TargetRun] = []
    aborted = None
    for t in plan.targets:
        kind, what, _ = parse_target(t)
        if kind == "emu" and what and what not in plan.known:
            raise UserError(f"target {t!r} is not a {fam.name} unit: run each family's "
                            "targets separately")
        perms = plan.permissions(t)
        target, implied = fam.open_target(t, baud=baud, permissions=perms,
                                          inputs_control=inputs_control, **family_values)
        notes: list[str] = []
        try:
            vid = plan.variant or implied
            if vid is None:
                vid, how = fam.identify(target)
                notes.append(f"variant: {how}")
            else:
                notes += _other_variant(fam, target, vid, implied)
            checks = fam.plan_checks(vid, permissions=perms, profile=profile, patterns=patterns,
                                     machine=not no_machine, **family_values)
            if plan.exact is not None:  # ids hold glob characters (?, *S): match exactly
                checks = [c for c in checks if c.id == plan.exact]
            if not checks:
                wanted = plan.exact or " ".join(patterns) or "(all)"
                raise UserError(f"no check of {vid} matches {wanted} (see --list)")
            if not target.emulated:
                notes += fam.permission_notes(perms)
            options = RunOptions(profile=profile, seed=plan.seed, notes=notes, announce=announce)
            runner = fam.runner(target, vid, options=options, permissions=perms, **family_values)
            step = _step(display.task(f"{target.name} ({vid})", len(checks)), checks)
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
    mutant_report: list[dict[str, object]] = []
    if mutants and aborted is None:
        variants = [r.variant for r in runs] or [fam.default_variant]
        task = display.task("mutants", fam.mutant_count(variants))
        mutant_report = fam.run_mutants(variants, profile=profile, seed=plan.seed,
                                        progress=lambda s: task.update(advance=1, step=s))
    return runs, mutant_report


def _other_variant(fam: Family, target: Target, vid: str, implied: str | None) -> list[str]:
    """A hint, said first, when the unit is another variant than the one asked for: then most
    FAILs are the variants' differences, not faults of the unit."""
    if implied is not None:
        found, how = implied, f"the target is {target.name}"
    else:
        found, how = fam.identify(target)
        if "assumed" in how:   # no answer the tables know: nothing to say
            return []
    if found == vid:
        return []
    return [f"hint: {how}, not {vid}: try --variant {found}"]


def _step(task: Task, checks: Sequence[Check]) -> Progress:
    """The runner's per-check callback: advance, count FAILs, name the check now running."""
    fails = [0]

    def step(result: CheckResult) -> None:
        fails[0] += result.grade is Grade.FAIL
        done = int(task.completed) + 1
        upcoming = checks[done].id if done < len(checks) else "writing the report"
        task.update(advance=1, step=(f"FAIL {fails[0]} · " if fails[0] else "") + upcoming)

    if checks:
        task.update(step=checks[0].id)
    return step
