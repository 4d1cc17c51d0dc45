"""Marlin's check-sender family (conform.sendercheck.family.Family): its scenarios and rules,
the Marlin unit with the ground truth of every command it ran, its fault injector (ok lines
lost, the cable pulled) and control requests (reset, busy), the restart after an unplugged
cable, and the capture analysed by the Marlin analyser."""

from __future__ import annotations

import json
from collections import Counter
from functools import partial
from typing import Any

from conform.families.marlin.sendercheck import rules, scenarios
from conform.families.marlin.sendercheck.session import MarlinTruth, sender_run
from conform.sendercheck.family import Family, Rule, Scenario

CLAUSE_ONCE = "queue.cpp get_serial_commands (a line is taken once per number)"


def _variant(variant_id: str) -> tuple[Any, Any]:
    from conform.families.marlin.spec import load_marlin

    spec = load_marlin()
    return spec.variant(variant_id), spec


def _make_unit(variant: Any, _spec: Any, t0: float, _scn: Scenario) -> Any:
    from conform.families.marlin.unit.serve import build

    return build(variant.id, t0=t0, baud=None, faults=None, seed=None)[0]


def _injector(scn: Scenario, seed: int, t0: float) -> Any:
    from conform.families.marlin.unit.faults import MarlinFaults
    from conform.link.faults import FaultConfig

    return MarlinFaults(FaultConfig.parse(scn.faults) if scn.faults else None, seed, t0,
                        lose=scn.lose)


def _control(faults: Any) -> Any:
    from conform.families.marlin.unit.control import MarlinControl

    return MarlinControl(faults)


def _reopen(reopen: Any, unit: Any, faults: Any, _truth: MarlinTruth) -> Any:
    """After an unplugged cable the board has restarted when the port is back (the unit
    notes the restart in its ground truth)."""
    from conform.families.marlin.unit.serve import reopen_with_reset

    return reopen_with_reset(reopen, unit, faults)


def _settle(s: Any, unit: Any, truth: MarlinTruth) -> None:
    """The ground truth: ``s.truth`` on the unit's clock (what the rules compare), truth.json
    with the log's times from the start of the session."""
    s.truth = {**unit.truth.to_dict(), "log": list(unit.truth.log), "events": s.events,
               "faults": s.faults, "returncode": s.exit_code, "hung": s.hung, "t0": truth.t0}
    written = {**s.truth, "log": [[round(t - truth.t0, 6), n, x] for t, n, x in s.truth["log"]]}
    del written["t0"]
    (s.directory / "truth.json").write_text(json.dumps(written, indent=1), "utf-8")


def _analyze(capture: Any, variant_id: str) -> Any:
    from conform.families.marlin.analysis.analyze import analyze_capture

    return analyze_capture(str(capture), variant=variant_id, detected="recorded by check-sender",
                           keep_lines=True)


def _truth_findings(s: Any) -> list[dict[str, Any]]:
    """Job lines the unit ran more often than the job has them (a second move), as facts."""
    from conform.families.marlin.unit.unit import _after_number

    if not isinstance(s.truth, dict) or "log" not in s.truth:
        return []
    job = Counter(s.job_lines)
    ran = Counter(t for t in (_after_number(x) for _, _, x in s.truth["log"]) if t in job)
    return [{"kind": "line-executed-twice", "severity": "hazard", "clause": CLAUSE_ONCE,
             "scenario": s.scenario.name, "source": "ground-truth", "confirmed": True,
             "message": f"{line!r} ran {n} times, the job has it {job[line]}", "line": line}
            for line, n in ran.items() if n > job[line]]


def _graded(check: Any, r: Any) -> tuple[Any, ...]:
    """A rule of rules.py: its (grade, expected, actual) as (grade, detail, evidence,
    expected)."""
    grade, expected, actual = check(r)
    return grade, actual, [], expected


RULES = tuple(Rule(rid, title, clause, level, partial(_graded, check))
              for rid, title, clause, level, check in rules.RULES)


# recorded raw (lines are paired when analysed), each answer dated when the emulator wrote it;
# served at 250 000 Bd, every variant's speed (variants.toml baud: Configuration.h BAUDRATE)
MARLIN = Family(
    name="marlin", default_variant="marlin-2.1", scenarios=scenarios.SCENARIOS,
    rules=RULES, job=scenarios.job_for,
    units=scenarios.moves, variant=_variant, make_unit=_make_unit, control=_control,
    observe=MarlinTruth, taken=MarlinTruth.moves_run, settle=_settle, analyze=_analyze,
    truth_findings=_truth_findings, job_name="job.gcode", steps=scenarios.steps,
    injector=_injector, reopen=_reopen, facts=sender_run,
    end_counts=lambda unit: {"bytes_lost": unit.lost}, decode=False, backdate=False,
    linger=0.2, fast=("clean", "noisy"), baud=250000,
    moves=lambda lines: len(scenarios.moves(lines)),
)
