"""The whole GVE suite of one variant (directed, examples, state machine) and the mutant run —
what ``conform run`` and the pytest plugin share for GVE units."""

from __future__ import annotations

import time
from collections.abc import Callable, Collection, Sequence
from typing import Any

from conform.conformance.results import Grade, TargetRun
from conform.conformance.runner import Progress, RunOptions
from conform.families.gve.conformance.checks import Check, generate, select
from conform.families.gve.conformance.machine import machine_check
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.safety import Guard
from conform.families.gve.conformance.target import GveEmuTarget, emulator_factory


def suite(spec: Any, variant_id: str, *, patterns: Sequence[str] = (),
          guard: Guard | None = None, machine: bool = True, profile: str = "quick"
          ) -> list[Check]:
    """Every check of a variant for a profile (filtered by globs)."""
    travel = 100000
    if guard is not None and guard.max_steps is not None:
        travel = min(travel, guard.max_steps)
    motion = guard is None or guard.allow_motion
    checks = generate(spec, variant_id, travel=travel, deep=profile == "full", motion=motion)
    if machine:
        checks.append(machine_check(spec, variant_id))
    return select(checks, patterns)


def run_mutants(spec: Any, variant_ids: Sequence[str], *, profile: str = "quick", seed: int = 0,
                machine: bool = False, progress: Callable[[str], None] | None = None,
                names: Collection[str] | None = None
                ) -> tuple[list[dict[str, Any]], list[TargetRun]]:
    """Run the suite against every mutant (or those in ``names``); which checks caught each
    (FAIL) and the runs."""
    from conform.families.gve.conformance.mutants import mutant_targets

    report, runs = [], []
    for m, vid in mutant_targets(variant_ids):
        if names is not None and m.name not in names:
            continue
        t0 = time.perf_counter()
        target = GveEmuTarget(emulator_factory(spec, vid, None, m.name), f"emu:{vid}:{m.name}")
        runner = Runner(spec, target, vid, options=RunOptions(profile=profile, seed=seed))
        run = runner.run(suite(spec, vid, machine=machine, profile=profile))
        failed = [c for c in run.checks if c.grade is Grade.FAIL]
        caught_by = [c.id for c in failed]
        expected_hit = [c.id for c in failed if c.key in m.catches]
        report.append({"name": m.name, "variant": vid, "fault": m.fault,
                       "catches": list(m.catches), "caught_by": caught_by,
                       "expected_hit": expected_hit, "killed": bool(failed),
                       "seconds": round(time.perf_counter() - t0, 3)})
        runs.append(run)
        if progress is not None:
            progress(f"mutant {m.name} on {vid}: "
                     f"{'killed by ' + str(len(caught_by)) + ' checks' if failed else 'SURVIVED'}")
    return report, runs


def run_one(spec: Any, target: Any, variant_id: str, checks: Sequence[Check], *,
            options: RunOptions, dialect: Any = None, progress: Progress | None = None
            ) -> TargetRun:
    return Runner(spec, target, variant_id, dialect=dialect, options=options).run(checks, progress)
