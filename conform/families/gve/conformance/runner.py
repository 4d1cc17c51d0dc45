"""The GVE grading of a conformance run: scripts run on the target and judged against the GVE
reference unit, a link's unit kept in each check's starting state (StateKeeper), the state
machine within its budget, the estimate from the reference unit's virtual clock, and the halt
H, D, O0,FF. The loop itself (ETA, link-loss abort, Ctrl-C) is conform.conformance.runner's.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Sequence
from typing import Any

from conform.conformance.results import CheckResult, Grade, TargetRun
from conform.conformance.runner import Estimate, RunOptions
from conform.conformance.runner import Runner as BaseRunner
from conform.conformance.target import HarnessError, LinkSilent
from conform.errors import LinkError
from conform.families.gve.conformance.checks import Check
from conform.families.gve.conformance.expect import Reference, judge
from conform.families.gve.conformance.safety import SafetyRefusal, not_verified
from conform.families.gve.conformance.script import run_script, skip_reason
from conform.families.gve.conformance.state import StateKeeper
from conform.families.gve.conformance.target import GveTarget, could_not

# the state machine's wall-time budget on a link, per profile (s): what fits the run targets
# (quick ≤ 5 min, full ≤ 20 min at 115 200 Bd) next to the directed checks
LINK_MACHINE_BUDGET = {"quick": 60.0, "full": 480.0}


class Runner(BaseRunner):
    """Grades checks of one GVE variant on one target against the reference unit."""

    target: GveTarget

    def __init__(self, spec: Any, target: GveTarget, variant_id: str, *, dialect: Any = None,
                 options: RunOptions | None = None, unit_cls: Any = None) -> None:
        super().__init__(target, variant_id, options)
        self.spec = spec
        self.variant = spec.variant(variant_id)
        self.ref = Reference(spec, variant_id, dialect, unit_cls)
        self.loose = not target.emulated
        if not target.emulated and target.keeper is None:
            target.keeper = StateKeeper(self.ref, target)

    def halt(self, after_silence: bool = False) -> str:
        """H (after a silence no deaf-time retries), D, O0,FF."""
        return self.target.safe_stop(h_bound=1.0) if after_silence else self.target.safe_stop()

    def estimate_run(self, checks: Sequence[Any]) -> Estimate:
        from conform.families.gve.conformance.eta import estimate_run

        return estimate_run(self, checks)

    def machine_budget(self) -> float | None:
        """Wall-time budget of the state machine on a link (None: in-process, unbounded)."""
        if self.target.emulated:
            return None
        if self.options.machine_budget is not None:
            return self.options.machine_budget
        return LINK_MACHINE_BUDGET.get(self.options.profile, LINK_MACHINE_BUDGET["quick"])

    def finish(self, run: TargetRun) -> None:
        keeper = self.target.keeper
        if keeper is not None:
            run.state = keeper.stats.to_json()
        run.not_verified = not_verified(run.checks)

    def _release_inputs(self, check: Check) -> None:
        """Inputs are physical and outlive J: on a link, whatever a check asserted is released
        (the checks release them themselves; this covers a check cut short)."""
        if self.target.emulated:
            return
        held = {s.input[:2] for s in check.script if s.input is not None and s.input[2]}
        for port, bit in sorted(held):
            self.target.set_input(port, bit, False)

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
            detail = could_not(exc)
            if not self.target.emulated:  # after seconds of silence H needs no deaf-time retries
                detail += f"; {self.halt(after_silence=isinstance(exc, LinkSilent))}"
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
