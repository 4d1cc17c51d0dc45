"""Sessions in, verdicts and results out; the families check-sender knows.

``check(command, ...)`` runs every chosen scenario once, grades every rule on each, and
returns :class:`CheckResults` (``exit_code``: 0 no MUST rule failed, 1 one did, 2 the
harness failed).
"""

from __future__ import annotations

import shlex
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.errors import UserError
from conform.families.gve.sendercheck import rules, scenarios
from conform.families.gve.unit.control import run_control
from conform.sendercheck.family import ERROR, FAIL, MUST, Family, Verdict
from conform.sendercheck.session import Session, run_session

GVE = Family(
    name="gve", default_variant="gve64-v19", scenarios=scenarios.SCENARIOS, rules=rules.RULES,
    job=scenarios.make_job, vectors=scenarios.job_vectors, prepare=scenarios.prepare_unit,
    make_unit=scenarios.make_unit, control_line=scenarios.control_line,
    commands=run_control, fast=scenarios.FAST,
)
FAMILIES = {"gve": GVE}


def family_for(variant_id: str) -> Family:
    """The family of a variant (every variant modelled today is GVE)."""
    return GVE


@dataclass
class ScenarioResult:
    name: str
    title: str
    verdicts: list[Verdict]
    session: Session
    findings: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        s = self.session
        return {
            "scenario": self.name, "title": self.title, "exit_code": s.exit_code,
            "hung": s.hung, "duration_s": round(s.duration, 3), "timeout_s": s.timeout,
            "capture": str(s.capture), "truth": str(s.directory / "truth.json"),
            "events": [{k: v for k, v in e.items() if k != "t_abs"} for e in s.events],
            "faults": s.faults, "harness_error": s.error, "analysis_error": s.analysis_error,
            "comparison": None if s.comparison is None else {
                "summary": s.comparison.summary(), "doubles": s.comparison.doubles,
                "extras": s.comparison.extras, "lost": s.comparison.lost,
                "altered": s.comparison.altered},
            "verdicts": [v.to_json() for v in self.verdicts],
        }


@dataclass
class CheckResults:
    command: list[str]
    variant: str
    family: str
    scenarios: list[ScenarioResult]
    duration: float = 0.0

    @property
    def verdicts(self) -> list[Verdict]:
        return [v for s in self.scenarios for v in s.verdicts]

    @property
    def findings(self) -> list[dict[str, Any]]:
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
            out[v.grade] = out.get(v.grade, 0) + 1
        return out

    def to_json(self) -> dict[str, Any]:
        return {"command": shlex.join(self.command), "variant": self.variant,
                "family": self.family, "duration_s": round(self.duration, 3),
                "exit_code": self.exit_code, "counts": self.counts(),
                "scenarios": [s.to_json() for s in self.scenarios],
                "verdicts": [v.to_json() for v in self.verdicts],
                "findings": self.findings}


def session_findings(s: Session) -> list[dict[str, Any]]:
    """Every finding of a scenario: the analyser's (the wire) and the ground truth's."""
    out = []
    for f in s.findings:
        d = f.to_dict()
        d.update(scenario=s.scenario.name, source="capture")
        out.append(d)
    c = s.comparison
    if c is not None:
        for kind, items, clause in (
                ("double-move", c.doubles, "GVE64 §13.5.2 (relative vectors: executed twice "
                                           "moves twice)"),
                ("extra-vector", c.extras, "GVE64 §13.5.2"),
                ("lost-vector", c.lost, "GVE64 §13.5.2, §13.7 (a vector not accepted is not "
                                        "executed)"),
                ("altered-vector", c.altered, "GVE64 §13.3.2 (a damaged line is executed "
                                              "unless checksums are on)")):
            for it in items:
                out.append({"kind": kind, "severity": "hazard", "clause": clause,
                            "scenario": s.scenario.name, "source": "ground-truth",
                            "confirmed": True, "message": f"{kind}: {it}", **it})
    if s.hung:
        out.append({"kind": "timeout", "severity": "error", "scenario": s.scenario.name,
                    "clause": "none (harness rule: a run must end)", "source": "harness",
                    "message": f"the program was stopped after {s.timeout:g} s"})
    if s.error:
        out.append({"kind": "harness-error", "severity": "error", "scenario": s.scenario.name,
                    "clause": "", "source": "harness", "message": s.error})
    return out


def grade_session(family: Family, s: Session) -> list[Verdict]:
    if s.error:
        return [Verdict(r.id, s.scenario.name, ERROR, r.clause, r.level, r.title,
                        f"harness error: {s.error}") for r in family.rules]
    return [r.grade(s) for r in family.rules]


def check(command: list[str], *, variant: str | None = None, names: list[str] | None = None,
          directory: Path, timeout: float | None = None, seed: int = 1,
          job_lines: list[str] | None = None,
          progress: Callable[[str], None] | None = None) -> CheckResults:
    from conform.families.gve.spec import load_spec

    if not command:
        raise UserError("no program given: conform check-sender [OPTIONS] -- COMMAND ARGS...")
    if shutil.which(command[0]) is None:
        raise UserError(f"{command[0]}: no such program (not found or not executable)")
    spec = load_spec()
    var = spec.variant(variant or GVE.default_variant)
    family = family_for(var.id)
    chosen = [n.strip() for x in (names or list(family.scenarios)) for n in x.split(",")
              if n.strip()]
    unknown = [n for n in chosen if n not in family.scenarios]
    if unknown:
        raise UserError(f"--scenario {unknown[0]!r}: unknown; choose from "
                        f"{', '.join(family.scenarios)}")
    say = progress or (lambda _m: None)
    start = time.monotonic()
    results = []
    for name in chosen:
        scn = family.scenarios[name]
        say(f"{name}: {scn.title} ...")
        s = run_session(family, scn, var, spec.dialect(), command, directory / name,
                        timeout=timeout, seed=seed, job_lines=job_lines)
        verdicts = grade_session(family, s)
        results.append(ScenarioResult(name, scn.title, verdicts, s, session_findings(s)))
        bad = [v.rule for v in verdicts if v.grade in (FAIL, ERROR)]
        say(f"{name}: {s.duration:.1f} s, exit {s.exit_code}"
            + (" (timed out)" if s.hung else "")
            + (f"; failed: {', '.join(bad)}" if bad else "; no failure"))
    return CheckResults(list(command), var.id, family.name, results,
                        time.monotonic() - start)
