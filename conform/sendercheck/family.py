"""The family-agnostic shapes of check-sender: scenarios, rules, verdicts, a family's hooks.

A protocol family supplies one :class:`Family` (``check_sender`` of its ``conform.families``
entry): its scenarios (what is done to the link and the unit, and the job the program streams),
its rules (each citing its clause), how to build and set up its unit for a scenario, and what it
knows afterwards — the ground truth of what the unit took, the job compared with it, the capture
analysed. The supervisor (session.py), the grading (grade.py) and the reports (report.py) only
use these shapes; what a family's scenario needs beyond them goes in ``Scenario.params``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from conform.conformance.results import Grade

if TYPE_CHECKING:
    from pathlib import Path

    from conform.analysis.result import Finding
    from conform.emulator.control import ControlHandler
    from conform.emulator.serve import SansIOUnit
    from conform.jsondoc import JsonObject
    from conform.link.endpoint import Endpoint
    from conform.link.faults import FaultInjector
    from conform.sendercheck.session import Session

MUST = "MUST"
SHOULD = "SHOULD"

# the engine's grades (conform.conformance.results.Grade); a SHOULD rule not met is a DEVIATION
PASS, FAIL, WARN, NA, ERROR = (Grade.PASS, Grade.FAIL, Grade.DEVIATION, Grade.NOT_APPLICABLE,
                               Grade.ERROR)
GRADES = (FAIL, ERROR, WARN, PASS, NA)


@dataclass(frozen=True)
class Action:
    """Something the scenario does during the run, once a share ``at`` of the job's units
    (``Family.units``) has been taken by the unit; the family turns it into timed control
    requests (``Family.steps``). ``hold``: how long it lasts, in seconds."""

    kind: str
    at: float  # share of the job's units taken by the unit, 0..1
    hold: float


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    faults: str = ""  # conform.link.faults spec applied by the emulator
    lose: float = 0.0  # probability that a whole answer is lost
    timeout: float = 30.0
    actions: tuple[Action, ...] = ()
    tags: frozenset[str] = frozenset()  # what the rules look for
    params: Mapping[str, object] = field(default_factory=dict)  # the family's own knobs

    def __hash__(self) -> int:
        return hash(self.name)


@dataclass
class Verdict:
    rule: str
    scenario: str
    grade: Grade
    clause: str
    level: str
    title: str
    detail: str = ""
    evidence: list[str] = field(default_factory=list)
    expected: str = ""

    def to_json(self) -> dict[str, object]:
        d = dict(self.__dict__)
        d["grade"] = self.grade.value
        return d


@dataclass(frozen=True)
class Rule:
    """One graded rule: ``check(facts)`` returns (grade, detail, evidence) or (grade, detail,
    evidence, expected), the grade a :class:`Grade` or its text; ``applies`` says whether it is
    graded in a scenario (else NOT-APPLICABLE). ``facts`` is what ``Family.facts`` makes of a
    session (the session itself by default)."""

    id: str
    title: str
    clause: str
    level: str
    # facts -> (grade, detail, evidence[, expected]); the facts are the family's own (``facts``)
    check: Callable[[Any], tuple[Grade | str, str, Sequence[str]] | tuple[Grade | str, str, Sequence[str], str]]
    applies: Callable[[Scenario], bool] = lambda _s: True

    def grade(self, facts: object, scn: Scenario) -> Verdict:
        if not self.applies(scn):
            return Verdict(self.id, scn.name, NA, self.clause, self.level, self.title,
                           "not graded in this scenario")
        grade, detail, evidence, *expected = self.check(facts)
        grade = Grade(grade)
        if grade is FAIL and self.level == SHOULD:
            grade = WARN
        return Verdict(self.id, scn.name, grade, self.clause, self.level, self.title, detail,
                       list(evidence), expected[0] if expected else "")


def _no_steps(action: Action, variant: object) -> list[tuple[float, str]]:
    raise ValueError(f"action {action.kind!r}: this family has no such action")


def _nothing(*_args: object) -> None:
    return None


class Variant(Protocol):
    """What the engine reads of a family's variant: its id."""

    @property
    def id(self) -> str: ...


class Analysis(Protocol):
    """What the engine reads of the capture's analysis (``Family.analyze``): its findings and
    metrics (``finding_counts``), as a ``conform.analysis.result.ResultBase`` has them."""

    findings: list[Finding]
    metrics: JsonObject


class Comparison(Protocol):
    """A family's comparison of the job with what its unit took (``settle`` sets it): a line
    for the report; a dataclass's fields also go into results.json."""

    def summary(self) -> str: ...


VariantT = TypeVar("VariantT", bound=Variant)
ContextT = TypeVar("ContextT")   # what a family's hooks share about a variant (its tables)
TruthT = TypeVar("TruthT")       # the family's ground-truth recorder of what its unit took


@dataclass
class Family(Generic[VariantT, ContextT, TruthT]):
    """What a family hands check-sender. Hooks with a default are optional. Its type
    parameters are the family's own variant, context and ground-truth recorder types, which
    the engine carries from one hook to the next without reading them."""

    name: str
    default_variant: str
    scenarios: dict[str, Scenario]
    rules: Sequence[Rule]
    # (scenario, variant, the user's --job lines or None) -> the job's lines
    job: Callable[[Scenario, VariantT, list[str] | None], list[str]]
    variant: Callable[[str], tuple[VariantT, ContextT]]  # variant id -> (variant, family context)
    # (variant, context, t0, scn) -> unit
    make_unit: Callable[[VariantT, ContextT, float, Scenario], SansIOUnit]
    # the fault injector -> the emulator's control handler
    control: Callable[[FaultInjector], ControlHandler | None]
    observe: Callable[[SansIOUnit, float], TruthT]  # (unit, t0) -> its ground-truth recorder
    taken: Callable[[TruthT], int]  # ground-truth recorder -> job units the unit has taken so far
    # (session, unit, ground truth) after the program: run the unit out, set ``truth`` (and
    # write truth.json) and ``comparison`` (the job against what the unit took: ``summary()``)
    settle: Callable[[Session, SansIOUnit, TruthT], None]
    analyze: Callable[[Path, str], Analysis]  # (capture path, variant id) -> the capture's analysis
    truth_findings: Callable[[Session], list[dict[str, object]]]  # session -> ground-truth findings
    units: Callable[[list[str]], Sequence[object]] = list  # job lines -> the units actions count
    # job lines -> how many are moves its unit executes (a --job with none is another
    # family's: a usage error); None: every unit counts
    moves: Callable[[list[str]], int] | None = None
    job_name: str = "job.txt"  # the job file's name in each scenario's folder
    # (action, variant) -> [(seconds after it fires, control request)]; the engine itself
    # answers ``link dead SECONDS`` and ``link back`` (a dead line, both ways)
    steps: Callable[[Action, VariantT], list[tuple[float, str]]] = _no_steps
    # (scenario, seed, t0) -> the emulator's fault injector; None: the engine's ScriptedFaults
    injector: Callable[[Scenario, int, float], FaultInjector] | None = None
    # (reopen, unit, injector, ground truth) -> what the emulator calls to reopen the port
    reopen: Callable[[Callable[[], Endpoint], SansIOUnit, FaultInjector, TruthT],
                     Callable[[], Endpoint]] | None = None
    facts: Callable[[Session], object] = lambda s: s  # session -> what the rules read
    # the unit -> the capture's closing counts
    end_counts: Callable[[SansIOUnit], dict[str, object]] = lambda _unit: {}
    decode: bool = True  # decode frames while recording (the family's live decoder)
    # the recording dates an answer's first byte a wire time before the emulator wrote it (as
    # on a line); False: when it was written (what the family's analyser and rules expect)
    backdate: bool = True
    linger: float = 0.0  # s the emulator keeps serving (and recording) after the program ended
    baud: int = 115200  # the line's speed: the emulator's pacing, and CONFORM_BAUD for the program
    fast: tuple[str, ...] = ()  # scenarios for a quick run
    prepare: Callable[[SansIOUnit, Scenario, float], None] = _nothing  # (unit, scn, t0) before the run
