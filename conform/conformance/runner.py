"""Run checks on a target and grade them: the conformance runner, the same for every family.

The runner owns the order of things and the safety net: a harness or link failure is an ERROR
(and, on a real unit, followed by the family's halt); consecutive link failures end the run;
Ctrl-C, SIGTERM and SIGHUP (one exception, :mod:`conform.stops`) halt the unit and the
results say what was sent; on a link the estimate is announced
before the run and the ETA while it runs. What a check is and how it is graded, which state the
unit is kept in and how it is halted belong to the family: a subclass of :class:`Runner`
(``Family.runner``) provides ``run_check``, ``halt`` and optionally ``estimate``,
``machine_budget`` and ``finish``. A check object's ``subject`` (what it is about, named alike
in every variant: a command, a setting) becomes its result's, the row of the report's matrix.
"""

from __future__ import annotations

import time
import traceback
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Generic, Protocol, TypeVar

from conform.conformance.results import CheckResult, Grade, TargetRun
from conform.conformance.target import Target
from conform.stops import interrupted_by


class Check(Protocol):
    """What the engine reads of any family's check (``Family.plan_checks``); the rest (its
    script, what it moves, how it is graded) is the family's, read by its own runner. A check
    may also name its ``subject`` (see the module docstring)."""

    @property
    def id(self) -> str:
        """``VARIANT/GROUP/...``: unique in a run, what ``--replay`` and the report name."""

    @property
    def level(self) -> str:
        """MUST, SHOULD or MAY: how a failure counts."""

    @property
    def clause(self) -> str:
        """The source the check holds the unit to (manual clause, source function)."""

    @property
    def title(self) -> str:
        """What is checked, in a line."""


CheckT = TypeVar("CheckT", bound=Check)
"""A family's own check type: its Runner subclass is ``Runner[ItsCheck]``."""

Progress = Callable[[CheckResult], None]
LINK_ERRORS_TO_ABORT = 3  # consecutive link failures on a real unit end the run (exit 2)
# what an ERROR's detail starts with when the link, not the harness's logic, failed
LINK_FAILURES = ("HarnessError", "LinkSilent", "LinkError", "PortGone", "OSError")


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


@dataclass
class Estimate:
    """How long a run will take: seconds per check id, and the ETA scaled by the pace so far."""

    per_check: dict[str, float] = field(default_factory=dict)
    total: float = 0.0
    _done_est: float = 0.0
    _done_wall: float = 0.0

    def done(self, check_id: str, elapsed: float) -> None:
        self._done_est += self.per_check.get(check_id, 0.0)
        self._done_wall = elapsed

    def eta(self) -> float:
        """Seconds left, scaled by the pace so far."""
        left = max(0.0, self.total - self._done_est)
        if self._done_est > 5.0:
            left *= self._done_wall / self._done_est
        return left


class Runner(ABC, Generic[CheckT]):
    """Runs the checks of one variant on one target; a family grades them (subclasses)."""

    def __init__(self, target: Target, variant_id: str, options: RunOptions | None = None
                 ) -> None:
        self.target = target
        self.variant_id = variant_id
        self.options = options or RunOptions()
        self.estimate: Estimate | None = None
        self.current: TargetRun | None = None

    # -- what a family provides ---------------------------------------------------------------
    @abstractmethod
    def run_check(self, check: CheckT) -> CheckResult:
        """Run and grade one check; failures of the link are ERRORs whose detail starts with
        the exception's class name (``LINK_FAILURES``)."""

    @abstractmethod
    def halt(self, after_silence: bool = False) -> str:
        """Stop the unit (retried until acknowledged); what was sent and answered.
        ``after_silence``: the link was silent for a while, so no deaf time is waited out."""

    def estimate_run(self, checks: Sequence[CheckT]) -> Estimate:
        """The estimate of ``checks`` on a link (announced before, the ETA while running)."""
        return Estimate()

    def machine_budget(self) -> float | None:
        """Wall-time budget of a family's open-ended checks on a link (None: none)."""
        return None

    def stop_at_end(self) -> bool:
        """Halt the unit after a complete run (a real unit allowed to move)."""
        return not self.target.emulated and self.target.guard.allow_motion

    def finish(self, run: TargetRun) -> None:  # noqa: B027 - nothing to add by default
        """Add the family's summary to a run that ended (state statistics, what was not
        verified)."""

    # -- the loop ---------------------------------------------------------------------------
    def run(self, checks: Sequence[CheckT], progress: Progress | None = None) -> TargetRun:
        started = datetime.now(UTC).isoformat(timespec="seconds")
        run = TargetRun(self.target.name, self.variant_id, self.target.emulated,
                        self.options.profile, started, notes=list(self.options.notes))
        self.current = run
        t0 = time.perf_counter()
        next_eta = t0 + self.options.eta_every
        link_errors = 0
        try:
            if not self.target.emulated:
                run.machine_budget_s = self.machine_budget()
                if self.estimate is None:
                    self.estimate = self.estimate_run(checks)
                run.estimate_s = round(self.estimate.total, 1)
                budget = ("" if run.machine_budget_s is None else
                          f" (state machine budget {_mmss(run.machine_budget_s)})")
                self._say(f"{self.target.name} ({self.variant_id}): {len(checks)} checks, "
                          f"estimate {_mmss(self.estimate.total)}{budget}")
                t0 = next_eta = time.perf_counter()
                next_eta += self.options.eta_every
            for check in checks:
                result = self.run_check(check)
                if not result.subject:
                    result.subject = str(getattr(check, "subject", "") or "")
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
        except KeyboardInterrupt as exc:   # Ctrl-C, SIGTERM, SIGHUP (conform.stops)
            what = self.halt()
            run.aborted = (f"interrupted ({interrupted_by(exc)}) after {len(run.checks)} "
                           f"checks; {what}")
            raise RunAborted(run) from None
        except Exception as exc:  # noqa: BLE001 - the report of what was done must survive
            tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
            what = "" if self.target.emulated else f"; {self.halt()}"
            run.aborted = f"harness error after {len(run.checks)} checks: {tb}{what}"
        finally:
            run.duration = time.perf_counter() - t0
            self.finish(run)
        if self.stop_at_end() and run.aborted is None:
            run.notes.append(f"end of run: {self.halt()}")
        return run

    def _say(self, text: str) -> None:
        if self.options.announce is not None:
            self.options.announce(text)

    def _link_failed(self, result: CheckResult) -> bool:
        return (result.grade is Grade.ERROR and not self.target.emulated
                and result.detail.startswith(LINK_FAILURES))


def _mmss(seconds: float) -> str:
    m, s = divmod(int(round(seconds)), 60)
    return f"{m}:{s:02d}"


class RunAborted(Exception):
    """A run stopped by Ctrl-C; carries what was done (and what was sent to stop the unit)."""

    def __init__(self, run: TargetRun) -> None:
        super().__init__(run.aborted)
        self.run = run
