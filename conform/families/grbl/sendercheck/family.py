"""grbl's check-sender family (conform.sendercheck.family.Family): its scenarios and rules,
the grbl unit with the ground truth of every line its parser took, its fault injector (answers
lost or damaged, the cable pulled) and control requests (the machine's buttons), the restart
after an unplugged cable, and the capture analysed by the grbl analyser."""

from __future__ import annotations

import json
from typing import Any

from conform.families.grbl.sendercheck import rules, scenarios
from conform.families.grbl.sendercheck.session import GrblTruth, sender_run
from conform.sendercheck.family import MUST, SHOULD, Family, Rule, Scenario

CLAUSE_ONCE = "interface.md §Grbl Response Messages (one answer per line, no resend)"


def _variant(variant_id: str) -> tuple[Any, Any]:
    from conform.families.grbl.spec.load import load_grbl

    spec = load_grbl()
    return spec.variant(variant_id), spec


def _make_unit(variant: Any, spec: Any, t0: float, _scn: Scenario) -> Any:
    from conform.families.grbl.unit.model import GrblUnit

    return GrblUnit(variant, spec, t0=t0, settings=scenarios.MACHINE, truth=True)


def _injector(scn: Scenario, seed: int, t0: float) -> Any:
    from conform.families.grbl.unit.faults import GrblFaults
    from conform.link.faults import FaultConfig

    return GrblFaults(FaultConfig.parse(scn.faults) if scn.faults else None, seed, t0,
                      lose=scn.lose, garble=scn.params.get("garble", 0.0))


def _control(faults: Any) -> Any:
    from conform.families.grbl.unit.control import GrblControl

    return GrblControl(faults)


def _reopen(reopen: Any, unit: Any, faults: Any, truth: GrblTruth) -> Any:
    """After an unplugged cable the board restarts as the port comes back; the restart is
    noted with the number of lines taken before it."""
    from conform.families.grbl.serve import reopen_with_power_cycle

    power_cycled = reopen_with_power_cycle(reopen, unit, faults)

    def again() -> Any:
        n = len(unit.taken or ())
        was = faults.unplugged
        new = power_cycled()
        if was:
            truth.restarts.append(n)
        return new

    return again


def _settle(s: Any, unit: Any, truth: GrblTruth) -> None:
    s.truth = {"taken": list(unit.taken or ()), "bytes_lost": unit.lost,
               "restarts_after_line": list(truth.restarts), "events": s.events,
               "faults": s.faults}
    (s.directory / "truth.json").write_text(json.dumps(s.truth, indent=1), "utf-8")
    s.comparison = rules.compare(s.job_lines, s.truth["taken"])


def _analyze(capture: Any, variant_id: str) -> Any:
    from conform.families.grbl.analysis.analyze import analyze_capture

    return analyze_capture(str(capture), variant=variant_id, detected="recorded by check-sender")


def _truth_findings(s: Any) -> list[dict[str, Any]]:
    """Job lines the unit ran more often than the job has them (a second move), as facts."""
    c = s.comparison
    if c is None:
        return []
    return [{"kind": "line-executed-twice", "severity": "hazard", "clause": CLAUSE_ONCE,
             "scenario": s.scenario.name, "source": "ground-truth", "confirmed": True,
             "message": f"{line!r} executed more often than the job has it", "line": line}
            for line in c.doubles]


def _moves(lines: list[str]) -> int:
    """The lines of a job with a motion, axis or machine word (what a grbl job is made of)."""
    from conform.families.grbl.protocol.gcode import GcodeError, strip_line, words

    n = 0
    for line in lines:
        try:
            n += any(w[0] in "GMXYZ" for w in words(strip_line(line.encode("latin-1"))[0]))
        except (GcodeError, UnicodeEncodeError):
            continue
    return n


def _rule(rid: str, title: str, clause: str, level: str, check: Any) -> Rule:
    """A rule of rules.py: (grade, expected, actual) becomes (grade, detail, evidence,
    expected)."""
    def graded(r: Any) -> tuple[Any, ...]:
        grade, expected, actual = check(r)
        return grade, actual, [], expected

    return Rule(rid, title, clause, MUST if level == MUST else SHOULD, graded)


# recorded raw (lines are paired when analysed), each answer dated when the emulator wrote it:
# whether the sender "went on" after an answer is judged against the answer complete
GRBL = Family(
    name="grbl", default_variant="grbl-1.1f", scenarios=scenarios.SCENARIOS,
    rules=tuple(_rule(*row) for row in rules.RULES), job=scenarios.scenario_job_for,
    variant=_variant, make_unit=_make_unit, control=_control,
    observe=lambda unit, _t0: GrblTruth(unit), taken=lambda truth: len(truth.unit.taken or ()),
    settle=_settle, analyze=_analyze, truth_findings=_truth_findings, job_name="job.gcode",
    steps=scenarios.steps, injector=_injector, reopen=_reopen, facts=sender_run,
    end_counts=lambda unit: {"bytes_lost": unit.lost}, decode=False, backdate=False, linger=0.2,
    fast=("stream", "lost-answers"), moves=_moves,
)
