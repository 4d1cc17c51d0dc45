"""Run checks on a target and grade them: the conformance runner.

The runner owns the order of things and the safety net: checks a run may not do are SKIPPED
before anything is sent; a harness or link failure is an ERROR (and, on a real unit, followed by
H, D, O0,FF); Ctrl-C stops the run the same way and the results say so.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from conform.conformance.checks import Check
from conform.conformance.expect import Reference, judge
from conform.conformance.results import CheckResult, Grade, TargetRun
from conform.conformance.safety import SafetyRefusal
from conform.conformance.script import run_script, skip_reason
from conform.conformance.target import HarnessError, Target
from conform.errors import LinkError

Progress = Callable[[CheckResult], None]
LINK_ERRORS_TO_ABORT = 3  # consecutive link failures on a real unit end the run (exit 2)


@dataclass
class RunOptions:
    profile: str = "quick"
    seed: int = 0
    examples: int | None = None  # state-machine examples (None: the profile's)
    steps: int | None = None  # state-machine steps per example
    notes: list[str] = field(default_factory=list)


class Runner:
    """Grades checks of one variant on one target against the reference unit."""

    def __init__(self, spec: Any, target: Target, variant_id: str, *, dialect: Any = None,
                 options: RunOptions | None = None, unit_cls: Any = None) -> None:
        self.spec = spec
        self.target = target
        self.variant = spec.variant(variant_id)
        self.ref = Reference(spec, variant_id, dialect, unit_cls)
        self.options = options or RunOptions()
        self.loose = not target.emulated

    def run(self, checks: Sequence[Check], progress: Progress | None = None) -> TargetRun:
        started = datetime.now(UTC).isoformat(timespec="seconds")
        run = TargetRun(self.target.name, self.variant.id, self.target.emulated,
                        self.options.profile, started, notes=list(self.options.notes))
        t0 = time.perf_counter()
        link_errors = 0
        try:
            for check in checks:
                result = self.run_check(check)
                run.checks.append(result)
                if progress is not None:
                    progress(result)
                link_errors = link_errors + 1 if self._link_failed(result) else 0
                if link_errors >= LINK_ERRORS_TO_ABORT:
                    run.aborted = (f"link lost after {len(run.checks)} checks "
                                   f"({result.detail.split(';')[0]})")
                    break
        except KeyboardInterrupt:
            what = self.target.safe_stop()
            run.aborted = f"interrupted (Ctrl-C) after {len(run.checks)} checks; {what}"
            raise RunAborted(run) from None
        finally:
            run.duration = time.perf_counter() - t0
        if not self.target.emulated and self.target.guard.allow_motion:
            run.notes.append(f"end of run: {self.target.safe_stop()}")
        return run

    def _link_failed(self, result: CheckResult) -> bool:
        return (result.grade is Grade.ERROR and not self.target.emulated
                and result.detail.startswith(("HarnessError", "LinkError", "PortGone", "OSError")))

    def _result(self, check: Check, grade: Grade, **kw: Any) -> CheckResult:
        return CheckResult(id=check.id, grade=grade, clause=check.clause, level=check.level,
                           title=check.title, variant=self.variant.id, target=self.target.name,
                           replay=check.id, **kw)

    def run_check(self, check: Check) -> CheckResult:
        if check.kind == "machine":
            from conform.conformance.machine import run_machine

            return run_machine(self, check)
        if check.na is not None:
            return self._result(check, Grade.NOT_APPLICABLE, detail=check.na)
        why = skip_reason(check.script, self.target.guard, self.target.emulated)
        if why is not None:
            return self._result(check, Grade.SKIPPED, detail=why,
                                sequence=[s.describe() for s in check.script])
        t0 = time.perf_counter()
        sequence = [s.describe() for s in check.script]
        try:
            replies = run_script(self.target, check.script)
        except (HarnessError, LinkError, SafetyRefusal, OSError) as exc:
            detail = f"{type(exc).__name__}: {exc}"
            if not self.target.emulated:
                detail += f"; {self.target.safe_stop()}"
            return self._result(check, Grade.ERROR, detail=detail, sequence=sequence,
                                log=list(self.target.log),
                                duration=time.perf_counter() - t0)
        except Exception as exc:  # noqa: BLE001 - a harness bug must not end the run
            tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
            return self._result(check, Grade.ERROR, detail=f"harness: {tb}", sequence=sequence,
                                log=list(self.target.log), duration=time.perf_counter() - t0)
        verdict = judge(self.ref, check.script, replies, loose=self.loose,
                        questions=check.questions, max_rate=float(self.variant.max_rate))
        grade = Grade(verdict.grade)
        if grade is Grade.PASS:
            exp = ""
            subject = [i for i, s in enumerate(check.script) if s.subject]
            if subject and replies[subject[-1]] is not None:
                step = check.script[subject[-1]]
                reply = replies[subject[-1]]
                assert reply is not None
                exp = f"{step.describe()} → {reply.text()}"
            return self._result(check, grade, expected=exp, actual=exp, sequence=sequence,
                                log=list(self.target.log), duration=time.perf_counter() - t0,
                                question=check.questions[0] if check.questions else None)
        return self._result(check, grade, expected=verdict.expected, actual=verdict.actual,
                            detail=verdict.detail, question=verdict.question,
                            alternative=verdict.alternative, sequence=sequence,
                            log=list(self.target.log), duration=time.perf_counter() - t0)


class RunAborted(Exception):
    """A run stopped by Ctrl-C; carries what was done (and what was sent to stop the unit)."""

    def __init__(self, run: TargetRun) -> None:
        super().__init__(run.aborted)
        self.run = run
