"""The family-agnostic shapes of check-sender: scenarios, rules, verdicts, a family.

A protocol family (GVE today, grbl next) supplies one :class:`Family` (``check_sender`` of
its ``conform.families`` entry): its scenarios (what is done to the link and the unit, and the
job the program streams), its rules (each citing its manual clause), how to set a unit up for
a scenario, and what it knows afterwards — the ground truth of what the unit accepted, the job
compared with it, the capture analysed. The session runner, the grading and the reports only
use these shapes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

MUST = "MUST"
SHOULD = "SHOULD"

PASS, FAIL, WARN, NA, ERROR = "PASS", "FAIL", "WARN", "NOT-APPLICABLE", "ERROR"
GRADES = (FAIL, ERROR, WARN, PASS, NA)


@dataclass(frozen=True)
class Action:
    """Something the scenario does during the run, once a share of the job's vectors has
    been accepted: ``stop`` (press the stop input, release it ``hold`` s later) or ``link``
    (the line is dead for ``hold`` s)."""

    kind: str
    at: float  # share of the job's vectors accepted, 0..1
    hold: float


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    faults: str = ""  # conform.link.faults spec applied by the emulator
    lose: float = 0.0  # probability that a whole answer is lost
    vectors: int = 60  # job length; ``over_queue`` makes it the queue size plus this
    over_queue: int | None = None
    pulses: int = 100
    head: int = 0  # pulses of one long first vector (the queue fills while it runs)
    speed: int = 20000
    timeout: float = 30.0
    actions: tuple[Action, ...] = ()
    tags: frozenset[str] = frozenset()  # what the rules look for: noise, stop, link, ...


@dataclass
class Verdict:
    rule: str
    scenario: str
    grade: str
    clause: str
    level: str
    title: str
    detail: str = ""
    evidence: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class Rule:
    """One graded rule: ``check(session)`` returns (grade, detail, evidence); ``applies`` says
    whether it is graded in a scenario (else NOT-APPLICABLE)."""

    id: str
    title: str
    clause: str
    level: str
    check: Callable[[Any], tuple[str, str, list[str]]]
    applies: Callable[[Scenario], bool] = lambda _s: True

    def grade(self, session: Any) -> Verdict:
        scn = session.scenario
        if not self.applies(scn):
            return Verdict(self.id, scn.name, NA, self.clause, self.level, self.title,
                           "not graded in this scenario")
        grade, detail, evidence = self.check(session)
        if grade == FAIL and self.level == SHOULD:
            grade = WARN
        return Verdict(self.id, scn.name, grade, self.clause, self.level, self.title, detail,
                       evidence)


@dataclass
class Family:
    name: str
    default_variant: str
    scenarios: dict[str, Scenario]
    rules: Sequence[Rule]
    job: Callable[[Scenario, Any], list[str]]  # (scenario, variant) -> job lines
    vectors: Callable[[list[str]], list[tuple[str, tuple[int, ...]]]]  # job lines -> vectors
    prepare: Callable[[Any, Scenario, float], None]  # (unit, scenario, t) before the run
    make_unit: Callable[[Any, Any, float], Any]  # (variant, dialect, t0) -> sans-I/O unit
    control_line: Callable[[str, bool, Any], str]  # (action kind, on, variant) -> control request
    commands: Callable[[Any, str, float], str]  # the emulator's control commands (emulator.control)
    variant: Callable[[str], tuple[Any, Any]]  # variant id -> (variant, dialect); UserError if unknown
    observe: Callable[[Any, float], Any]  # (unit, t0) -> its ground truth (``accepted``, ``to_dict()``)
    # (session, unit, ground truth) after the program: run the unit out, set ``truth`` (and
    # write truth.json) and ``comparison`` (the job against what the unit accepted)
    settle: Callable[[Any, Any, Any], None]
    analyze: Callable[[Any, str], Any]  # (capture path, variant id) -> the capture's analysis
    truth_findings: Callable[[Any], list[dict[str, Any]]]  # session -> ground-truth findings
    fast: tuple[str, ...] = ()  # scenarios for a quick run
