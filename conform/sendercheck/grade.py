"""Sessions in, verdicts and results out, for every family.

``check(command, ...)`` runs every chosen scenario once through the supervisor (session.py),
grades every rule of the family on each (the engine's :class:`Grade`), and returns
:class:`CheckResults` (``exit_code``: 0 no MUST rule failed, 1 one did, 2 the harness failed).
Ctrl-C (or SIGTERM, SIGHUP) stops the scenario running, and the results hold those finished.
"""

from __future__ import annotations

import dataclasses
import shlex
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from conform.conformance.results import CheckResult, TargetRun
from conform.errors import UserError
from conform.families import default_family as registered_default
from conform.families import family_for_variant
from conform.sendercheck.family import ERROR, FAIL, MUST, Comparison, Family, Verdict
from conform.sendercheck.options import require_program
from conform.sendercheck.session import Session, run_session
from conform.stops import current, interrupted_by

if TYPE_CHECKING:
    from conform.families import Family as RegisteredFamily


def default_family() -> Family:
    """check-sender's shapes when no variant is given: the default family's."""
    return _shapes(registered_default())


def family_for(variant_id: str) -> Family:
    """The check-sender scenarios and rules of the family serving ``variant_id``."""
    return _shapes(family_for_variant(variant_id))


def _shapes(fam: RegisteredFamily) -> Family[Any, Any, Any]:
    shapes = getattr(fam, "check_sender", None)
    if shapes is None:
        raise fam.lacks("check-sender scenarios")
    return shapes


def comparison_json(c: Comparison | None) -> dict[str, object] | None:
    """A family's comparison of the job with the truth, for results.json."""
    if c is None:
        return None
    facts: dict[str, object] = dataclasses.asdict(c) if dataclasses.is_dataclass(c) and not isinstance(c, type) else {}
    return {"summary": c.summary(), **facts}


@dataclass
class ScenarioResult:
    name: str
    title: str
    verdicts: list[Verdict]
    session: Session
    findings: list[dict[str, object]] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        s = self.session
        return {
            "scenario": self.name, "title": self.title, "exit_code": s.exit_code,
            "hung": s.hung, "duration_s": round(s.duration, 3), "timeout_s": s.timeout,
            "capture": str(s.capture), "truth": str(s.directory / "truth.json"),
            "events": s.events,
            "faults": s.faults, "harness_error": s.error, "analysis_error": s.analysis_error,
            "port": s.port, "comparison": comparison_json(s.comparison),
            "verdicts": [v.to_json() for v in self.verdicts],
        }


@dataclass
class CheckResults:
    command: list[str]
    variant: str
    family: str
    scenarios: list[ScenarioResult]
    duration: float = 0.0
    interrupted: str = ""  # why the run stopped before every scenario had run
    started: str = ""

    @property
    def verdicts(self) -> list[Verdict]:
        return [v for s in self.scenarios for v in s.verdicts]

    @property
    def findings(self) -> list[dict[str, object]]:
        return [f for s in self.scenarios for f in s.findings]

    @property
    def exit_code(self) -> int:
        vs = self.verdicts
        if any(v.grade == FAIL and v.level == MUST for v in vs):
            return 1
        if any(v.grade == ERROR for v in vs):
            return 2
        return 0

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for v in self.verdicts:
            out[v.grade.value] = out.get(v.grade.value, 0) + 1
        return out

    def checks(self) -> list[CheckResult]:
        """Every verdict as the engine's check result (id ``VARIANT/check-sender/SCENARIO/RULE``),
        what ``conform run``'s reports and results read."""
        return [CheckResult(f"{self.variant}/check-sender/{v.scenario}/{v.rule}", v.grade,
                            v.clause, level=v.level, title=v.title, expected=v.expected,
                            actual=v.detail, detail="\n".join(v.evidence),
                            duration=round(s.session.duration, 3), variant=self.variant,
                            target=f"sender:{v.scenario}")
                for s in self.scenarios for v in s.verdicts]

    def target_run(self) -> TargetRun:
        """The run as one column of ``conform run``'s results."""
        return TargetRun(shlex.join(self.command), self.variant, True, "check-sender",
                         self.started, self.duration, self.checks(),
                         aborted=self.interrupted or None)

    def to_json(self) -> dict[str, object]:
        return {"command": shlex.join(self.command), "variant": self.variant,
                "family": self.family, "duration_s": round(self.duration, 3),
                "exit_code": self.exit_code, "counts": self.counts(),
                "interrupted": self.interrupted,
                "scenarios": [s.to_json() for s in self.scenarios],
                "verdicts": [v.to_json() for v in self.verdicts],
                "findings": self.findings,
                "checks": [c.to_json() for c in self.checks()]}


def session_findings(s: Session) -> list[dict[str, object]]:
    """Every finding of a scenario: the analyser's (the wire) and the ground truth's."""
    out = []
    for f in s.findings:
        d = f.to_dict() if hasattr(f, "to_dict") else dataclasses.asdict(f)
        d.update(scenario=s.scenario.name, source="capture")
        out.append(d)
    out += s.family.truth_findings(s)
    if s.hung:
        out.append({"kind": "timeout", "severity": "error", "scenario": s.scenario.name,
                    "clause": "none (harness rule: a run must end)", "source": "harness",
                    "message": f"the program was stopped after {s.timeout:g} s"})
    if s.error:
        out.append({"kind": "harness-error", "severity": "error", "scenario": s.scenario.name,
                    "clause": "", "source": "harness", "message": s.error})
    return out


def grade_session(family: Family, s: Session) -> list[Verdict]:
    """Every rule on one session; every rule ERROR when the harness failed."""
    if s.error:
        return [Verdict(r.id, s.scenario.name, ERROR, r.clause, r.level, r.title,
                        f"harness error: {s.error}") for r in family.rules]
    try:
        facts = family.facts(s)
        return [r.grade(facts, s.scenario) for r in family.rules]
    except Exception as exc:  # noqa: BLE001 - a rule that cannot be graded is the harness's
        s.error = f"grading failed: {type(exc).__name__}: {exc}"
        return grade_session(family, s)


@contextmanager
def _interruptible() -> Iterator[None]:
    """SIGTERM and SIGHUP end the run as Ctrl-C does (the finished scenarios are kept).
    Under ``conform`` (conform.stops.stop_signals installed) its handlers already do, and
    record which signal came so the command exits 128 + N: they are left in place."""
    if threading.current_thread() is not threading.main_thread() or current() is not None:
        yield
        return

    def stop(signum: int, _frame: FrameType | None) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    old = {sig: signal.signal(sig, stop) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


def check(command: list[str], *, variant: str | None = None, names: list[str] | None = None,
          directory: Path, timeout: float | None = None, seed: int = 1,
          job_lines: list[str] | None = None,
          progress: Callable[[str], None] | None = None) -> CheckResults:
    require_program(command)
    shapes = family_for(variant) if variant else default_family()
    var, context = shapes.variant(variant or shapes.default_variant)
    family = shapes
    chosen = [n.strip() for x in (names or list(family.scenarios)) for n in x.split(",")
              if n.strip()]
    unknown = [n for n in chosen if n not in family.scenarios]
    if unknown:
        raise UserError(f"--scenario {unknown[0]!r}: unknown; choose from "
                        f"{', '.join(family.scenarios)}")
    say = progress or (lambda _m: None)
    start = time.monotonic()
    out = CheckResults(list(command), var.id, family.name, [],
                       started=datetime.now(UTC).isoformat(timespec="seconds"))
    with _interruptible():
        for name in chosen:
            scn = family.scenarios[name]
            say(f"{name}: {scn.title} ...")
            try:
                s = run_session(family, scn, var, context, command, directory / name,
                                timeout=timeout, seed=seed, job_lines=job_lines)
                verdicts = grade_session(family, s)
                done = ScenarioResult(name, scn.title, verdicts, s, session_findings(s))
            except KeyboardInterrupt as exc:
                why = interrupted_by(exc)
                out.interrupted = (f"interrupted ({why}) during {name}; "
                                   f"{len(out.scenarios)} of {len(chosen)} scenario(s) finished")
                say(out.interrupted)
                break
            out.scenarios.append(done)
            bad = [v.rule for v in verdicts if v.grade in (FAIL, ERROR)]
            say(f"{name}: {s.duration:.1f} s, exit {s.exit_code}"
                + (" (timed out)" if s.hung else "")
                + (f"; failed: {', '.join(bad)}" if bad else "; no failure"))
    out.duration = time.monotonic() - start
    return out
