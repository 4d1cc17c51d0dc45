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

from conform.conformance.results import CheckResult, Grade, TargetRun
from conform.conformance.target import HarnessError, LinkSilent, Target
from conform.errors import LinkError
from conform.families.gve.conformance.checks import Check
from conform.families.gve.conformance.eta import Estimate, estimate_run
from conform.families.gve.conformance.expect import Reference, judge
from conform.families.gve.conformance.safety import SafetyRefusal, not_verified
from conform.families.gve.conformance.script import run_script, skip_reason
from conform.families.gve.conformance.state import StateKeeper

Progress = Callable[[CheckResult], None]
LINK_ERRORS_TO_ABORT = 3  # consecutive link failures on a real unit end the run (exit 2)
# the state machine's wall-time budget on a link, per profile (s): what fits the run targets
# (quick ≤ 5 min, full ≤ 20 min at 115 200 Bd) next to the directed checks
LINK_MACHINE_BUDGET = {"quick": 60.0, "full": 480.0}


@dataclass
class RunOptions:
    profile: str = "quick"
    seed: int = 0
    examples: int | None = None  # state-machine examples (None: the profile's)
    steps: int | None = None  # state-machine steps per example
    notes: list[str] = field(default_factory=list)
    machine_budget: float | None = None  # state machine wall time on a link (None: profile's)
    announce: Callable[[str], None] | None = None  # the estimate before, the ETA while running
    eta_every: float = 30.0  # seconds between ETA lines


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
        self.estimate: Estimate | None = None
        self.current: TargetRun | None = None
        if not target.emulated and target.keeper is None:
            target.keeper = StateKeeper(self.ref, target)

    def run(self, checks: Sequence[Check], progress: Progress | None = None) -> TargetRun:
        started = datetime.now(UTC).isoformat(timespec="seconds")
        run = TargetRun(self.target.name, self.variant.id, self.target.emulated,
                        self.options.profile, started, notes=list(self.options.notes))
        self.current = run
        t0 = time.perf_counter()
        next_eta = t0 + self.options.eta_every
        link_errors = 0
        try:
            if not self.target.emulated:
                run.machine_budget_s = self.machine_budget()
                if self.estimate is None:
                    self.estimate = estimate_run(self, checks)
                run.estimate_s = round(self.estimate.total, 1)
                self._say(f"{self.target.name} ({self.variant.id}): {len(checks)} checks, "
                          f"estimate {_mmss(self.estimate.total)} (state machine budget "
                          f"{_mmss(run.machine_budget_s or 0)})")
                t0 = next_eta = time.perf_counter()
                next_eta += self.options.eta_every
            for check in checks:
                result = self.run_check(check)
                run.checks.append(result)
                if self.estimate is not None:
                    now = time.perf_counter()
                    self.estimate.done(check.id, now - t0)
                    if now >= next_eta:
                        next_eta = now + self.options.eta_every
                        self._say(f"  {len(run.checks)}/{len(checks)} checks in "
                                  f"{_mmss(now - t0)}, ETA {_mmss(self.estimate.eta())}")
                if progress is not None:
                    progress(result)
                link_errors = link_errors + 1 if self._link_failed(result) else 0
                if link_errors >= LINK_ERRORS_TO_ABORT:
                    run.aborted = (f"link lost after {len(run.checks)} checks "
                                   f"({result.detail.split(';')[0]}); the run stopped")
                    break
        except KeyboardInterrupt:
            what = self.target.safe_stop()
            run.aborted = f"interrupted (Ctrl-C) after {len(run.checks)} checks; {what}"
            raise RunAborted(run) from None
        except Exception as exc:  # noqa: BLE001 - the report of what was done must survive
            tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
            what = "" if self.target.emulated else f"; {self.target.safe_stop()}"
            run.aborted = f"harness error after {len(run.checks)} checks: {tb}{what}"
        finally:
            run.duration = time.perf_counter() - t0
            keeper = self.target.keeper
            if keeper is not None:
                run.state = keeper.stats.to_json()
            run.not_verified = not_verified(run.checks)
        if (not self.target.emulated and self.target.guard.allow_motion
                and run.aborted is None):
            run.notes.append(f"end of run: {self.target.safe_stop()}")
        return run

    def _release_inputs(self, check: Check) -> None:
        """Inputs are physical and outlive J: on a link, whatever a check asserted is released
        (the checks release them themselves; this covers a check cut short)."""
        if self.target.emulated:
            return
        held = {s.input[:2] for s in check.script if s.input is not None and s.input[2]}
        for port, bit in sorted(held):
            self.target.set_input(port, bit, False)

    def _say(self, text: str) -> None:
        if self.options.announce is not None:
            self.options.announce(text)

    def machine_budget(self) -> float | None:
        """Wall-time budget of the state machine on a link (None: in-process, unbounded)."""
        if self.target.emulated:
            return None
        if self.options.machine_budget is not None:
            return self.options.machine_budget
        return LINK_MACHINE_BUDGET.get(self.options.profile, LINK_MACHINE_BUDGET["quick"])

    def _link_failed(self, result: CheckResult) -> bool:
        return (result.grade is Grade.ERROR and not self.target.emulated
                and result.detail.startswith(("HarnessError", "LinkSilent", "LinkError", "PortGone",
                                              "OSError")))

    def _result(self, check: Check, grade: Grade, **kw: Any) -> CheckResult:
        return CheckResult(id=check.id, grade=grade, clause=check.clause, level=check.level,
                           title=check.title, variant=self.variant.id, target=self.target.name,
                           replay=check.id, **kw)

    def run_check(self, check: Check) -> CheckResult:
        if check.na is not None:
            return self._result(check, Grade.NOT_APPLICABLE, detail=check.na)
        if check.kind != "machine":
            why = skip_reason(check.script, self.target.guard, self.target.drives_inputs)
            if why is not None:
                return self._result(check, Grade.SKIPPED, detail=why,
                                    sequence=[s.describe() for s in check.script])
        t0 = time.perf_counter()
        sequence = [s.describe() for s in check.script]
        keeper = self.target.keeper
        try:
            if check.kind == "machine":
                from conform.families.gve.conformance.machine import run_machine

                result = run_machine(self, check)
                if keeper is not None:
                    keeper.done(False)
                return result
            try:
                replies = run_script(self.target, check.script)
            finally:
                self._release_inputs(check)
        except (HarnessError, LinkError, SafetyRefusal, OSError) as exc:
            detail = f"{type(exc).__name__}: {exc}"
            if not self.target.emulated:  # after seconds of silence H needs no deaf-time retries
                bound = 1.0 if isinstance(exc, LinkSilent) else 7.0
                detail += f"; {self.target.safe_stop(h_bound=bound)}"
            if keeper is not None:
                keeper.done(False)
            return self._result(check, Grade.ERROR, detail=detail, sequence=sequence,
                                log=list(self.target.log),
                                duration=time.perf_counter() - t0)
        except Exception as exc:  # noqa: BLE001 - a harness bug must not end the run
            tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
            if keeper is not None:
                keeper.done(False)
            return self._result(check, Grade.ERROR, detail=f"harness: {tb}", sequence=sequence,
                                log=list(self.target.log), duration=time.perf_counter() - t0)
        verdict = judge(self.ref, check.script, replies, loose=self.loose,
                        questions=check.questions, max_rate=float(self.variant.max_rate))
        grade = Grade(verdict.grade)
        if keeper is not None:
            keeper.done(grade is Grade.PASS)
            if grade is not Grade.PASS and any(r is not None and r.silent for r in replies):
                lost = keeper.link_lost()
                if lost:  # the unit did not fall silent: the link did
                    return self._result(check, Grade.ERROR, detail=f"HarnessError: {lost}",
                                        expected=verdict.expected, actual=verdict.actual,
                                        sequence=sequence, log=list(self.target.log),
                                        duration=time.perf_counter() - t0)
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


def _mmss(seconds: float) -> str:
    m, s = divmod(int(round(seconds)), 60)
    return f"{m}:{s:02d}"


class RunAborted(Exception):
    """A run stopped by Ctrl-C; carries what was done (and what was sent to stop the unit)."""

    def __init__(self, run: TargetRun) -> None:
        super().__init__(run.aborted)
        self.run = run
