"""``conform run`` for GVE units: the plan (targets, ``--matrix``, ``--replay``), the guard,
the variant identified by ``?``, the suite of each target in the engine's runner with a
progress bar, and the mutant run. The command (conform/cli/run_cmd.py) reaches it through
``Family.run_targets`` and writes the reports, the summary and the exit code."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from conform.cli.params import echo_json
from conform.cli.progress import progress as show_progress
from conform.conformance.results import Grade, TargetRun
from conform.conformance.runner import RunAborted, RunOptions
from conform.conformance.suite import parse_replay
from conform.conformance.target import parse_target
from conform.errors import UserError
from conform.families.gve.conformance.profile import load_profile_dialect
from conform.families.gve.conformance.safety import run_guard
from conform.families.gve.conformance.suite import run_mutants, run_one, suite
from conform.families.gve.conformance.target import DEFAULT_VARIANT, identify, open_target
from conform.families.gve.spec import load_spec


def run_targets(targets: list[str], variant: str | None, *, baud: int = 115200,
                profile: str = "quick", patterns: tuple[str, ...] = (), list_only: bool = False,
                matrix: bool = False, mutants: bool = False, replay: str | None = None,
                seed: int = 0, dialect_file: str | None = None, allow_motion: bool = False,
                max_steps: int | None = None, allow_eeprom: bool = False,
                no_machine: bool = False, inputs_control: str | None = None,
                quiet: bool = False, as_json: bool = False,
                echo: Callable[[str], None] = print,
                announce: Callable[[str], None] | None = None, **_unused: Any
                ) -> tuple[list[TargetRun], list[dict[str, Any]]] | None:
    """Run the suite on each target; (runs, mutant report), or None after ``--list``."""
    spec = load_spec()
    if variant is not None:
        spec.variant(variant)
    if allow_motion and max_steps is None:
        raise UserError("--allow-motion needs --max-steps N (the bound on every axis move)")
    if max_steps is not None and max_steps <= 0:
        raise UserError("--max-steps must be a positive number of pulses")
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
                    echo(f"{c.id}\t{c.level}\t{c.clause}\t{c.title}")
        if as_json:
            echo_json({"checks": listed})
        return None

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
                else:
                    notes += _other_variant(target, spec, vid, implied)
                checks = suite(spec, vid, patterns=patterns, guard=guard,
                               machine=not no_machine, profile=profile)
                if exact is not None:  # ids hold glob characters (?, *S): match exactly
                    checks = [c for c in checks if c.id == exact]
                if not checks:
                    wanted = exact or " ".join(patterns) or "(all)"
                    raise UserError(f"no check of {vid} matches {wanted} (see --list)")
                if not target.emulated and not allow_motion:
                    notes.append("motion-bearing checks SKIPPED (no --allow-motion)")
                options = RunOptions(profile=profile, seed=seed, notes=notes, announce=announce)
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
    return runs, mutant_report


def _other_variant(target, spec, vid: str, implied: str | None) -> list[str]:  # noqa: ANN001
    """A hint, said first, when the unit is another variant than the one asked for: then most
    FAILs are the variants' differences, not faults of the unit."""
    if implied is not None:
        found, how = implied, f"the target is {target.name}"
    else:
        found, how = identify(target, spec)
        if "assumed" in how:   # no firmware string the tables know: nothing to say
            return []
    if found == vid:
        return []
    return [f"hint: {how}, not {vid}: try --variant {found}"]


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


