"""Sessions in, verdicts and results out; the families check-sender knows.

``check(command, ...)`` runs every chosen scenario once, grades every rule on each, and
returns :class:`CheckResults` (``exit_code``: 0 no MUST rule failed, 1 one did, 2 the
harness failed).
"""

from __future__ import annotations

import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.errors import UserError
from conform.families import default_family as registered_default
from conform.families import family_for_variant
from conform.sendercheck.family import ERROR, FAIL, MUST, Family, Verdict
from conform.sendercheck.options import require_program
from conform.sendercheck.session import Session, run_session
from conform.stops import interrupted_by


def default_family() -> Family:
    """check-sender's shapes when no variant is given: the default family's."""
    return registered_default().check_sender


def family_for(variant_id: str) -> Family:
    """The check-sender scenarios and rules of the family serving ``variant_id``."""
    fam = family_for_variant(variant_id)
    shapes = getattr(fam, "check_sender", None)
    if shapes is None:
        raise UserError(f"check-sender has no scenarios for {variant_id} ({fam.name})")
    return shapes


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
    interrupted: str | None = None   # why the scenarios stopped early (a signal), and what is missing

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
                "interrupted": self.interrupted,
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
    if s.error:
        return [Verdict(r.id, s.scenario.name, ERROR, r.clause, r.level, r.title,
                        f"harness error: {s.error}") for r in family.rules]
    return [r.grade(s) for r in family.rules]


def check(command: list[str], *, variant: str | None = None, names: list[str] | None = None,
          directory: Path, timeout: float | None = None, seed: int = 1,
          job_lines: list[str] | None = None,
          progress: Callable[[str], None] | None = None) -> CheckResults:
    require_program(command)
    shapes = family_for(variant) if variant else default_family()
    var, dialect = shapes.variant(variant or shapes.default_variant)
    family = shapes
    chosen = [n.strip() for x in (names or list(family.scenarios)) for n in x.split(",")
              if n.strip()]
    unknown = [n for n in chosen if n not in family.scenarios]
    if unknown:
        raise UserError(f"--scenario {unknown[0]!r}: unknown; choose from "
                        f"{', '.join(family.scenarios)}")
    say = progress or (lambda _m: None)
    start = time.monotonic()
    results: list[ScenarioResult] = []
    interrupted = None
    for name in chosen:
        scn = family.scenarios[name]
        say(f"{name}: {scn.title} ...")
        try:
            s = run_session(family, scn, var, dialect, command, directory / name,
                            timeout=timeout, seed=seed, job_lines=job_lines)
        except KeyboardInterrupt as exc:   # Ctrl-C, SIGTERM, SIGHUP: report what finished
            interrupted = (f"interrupted ({interrupted_by(exc)}) during {name}; not run: "
                           f"{', '.join(chosen[len(results):])}")
            say(interrupted)
            break
        verdicts = grade_session(family, s)
        results.append(ScenarioResult(name, scn.title, verdicts, s, session_findings(s)))
        bad = [v.rule for v in verdicts if v.grade in (FAIL, ERROR)]
        say(f"{name}: {s.duration:.1f} s, exit {s.exit_code}"
            + (" (timed out)" if s.hung else "")
            + (f"; failed: {', '.join(bad)}" if bad else "; no failure"))
    return CheckResults(list(command), var.id, family.name, results,
                        time.monotonic() - start, interrupted)
