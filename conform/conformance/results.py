"""What a conformance run produces: grades, findings, per-check results, the run as a whole.

Plain dataclasses that round-trip through JSON (``results.json``), so a report can be re-rendered
from a file without the unit or the tables.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from pathlib import Path

from conform.errors import UserError, read_user_text
from conform.jsondoc import JsonObject


class Grade(StrEnum):
    """Per-check verdicts (docs/conformance.md)."""

    PASS = "PASS"
    FAIL = "FAIL"
    DEVIATION = "DEVIATION"
    NOT_APPLICABLE = "NOT-APPLICABLE"
    SKIPPED = "SKIPPED"
    ERROR = "ERROR"


GRADE_ORDER = [Grade.FAIL, Grade.ERROR, Grade.DEVIATION, Grade.PASS, Grade.SKIPPED,
               Grade.NOT_APPLICABLE]

MUST = "MUST"
INFO = "INFO"


@dataclass
class LogEntry:
    """One chunk on the wire: seconds since the check began, direction (tx|rx|note), bytes."""

    t: float
    dir: str
    data: bytes

    def to_json(self) -> dict[str, object]:
        return {"t": round(self.t, 6), "dir": self.dir, "data": self.data.decode("latin-1")}

    @staticmethod
    def from_json(d: JsonObject) -> LogEntry:
        return LogEntry(float(d["t"]), str(d["dir"]), str(d["data"]).encode("latin-1"))


@dataclass
class CheckResult:
    """The verdict of one check on one target."""

    id: str
    grade: Grade
    clause: str
    level: str = MUST
    title: str = ""
    expected: str = ""
    actual: str = ""
    detail: str = ""
    question: str | None = None       # the open question a DEVIATION (or INFO check) is about
    alternative: str | None = None    # the alternative the target matched (DEVIATION)
    sequence: list[str] = field(default_factory=list)  # the (shrunk) lines that show it
    seed: int | None = None
    replay: str = ""                  # argument for `conform run --replay`
    log: list[LogEntry] = field(default_factory=list)
    duration: float = 0.0
    variant: str = ""
    target: str = ""
    # what the check is about (a command, a setting, an open question), named alike in every
    # variant of a family, so the variants × subjects matrix lines up a command whatever clause
    # each variant's manual gives it; the family's check object says it (its ``subject``)
    subject: str = ""

    @property
    def row(self) -> str:
        """The subject, or for results written before subjects the first part of the key."""
        return self.subject or self.key.split("/", 1)[0]

    @property
    def key(self) -> str:
        """The id without variant and clause: the row of the variants × checks matrix."""
        parts = self.id.split("/")
        return "/".join(parts[2:]) if len(parts) > 2 else self.id

    def to_json(self) -> dict[str, object]:
        d = asdict(self)
        d["grade"] = self.grade.value
        d["log"] = [e.to_json() for e in self.log]
        return d

    @staticmethod
    def from_json(d: JsonObject) -> CheckResult:
        d = dict(d)
        d["grade"] = Grade(d["grade"])
        d["log"] = [LogEntry.from_json(e) for e in d.get("log", [])]
        known = set(CheckResult.__dataclass_fields__)
        return CheckResult(**{k: v for k, v in d.items() if k in known})


@dataclass
class TargetRun:
    """All results of one target (one column of the matrix)."""

    target: str
    variant: str
    emulated: bool
    profile: str
    started: str
    duration: float = 0.0
    checks: list[CheckResult] = field(default_factory=list)
    aborted: str | None = None        # why the run stopped early (and what was sent to stop it)
    notes: list[str] = field(default_factory=list)
    # a link's costs: how the checks' states were reached (the family's state keeping, set by
    # its Runner.finish), the estimate printed before starting and the budget of the family's
    # open-ended checks (the GVE state machine) in s
    state: dict[str, object] = field(default_factory=dict)
    estimate_s: float | None = None
    machine_budget_s: float | None = None
    # what this run did not verify and how to enable it (the family's Runner.finish)
    not_verified: list[dict[str, object]] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.aborted is None

    def counts(self) -> dict[str, int]:
        out = {g.value: 0 for g in GRADE_ORDER}
        for c in self.checks:
            out[c.grade.value] += 1
        return out


@dataclass
class RunResults:
    """A whole ``conform run``: one or more targets."""

    runs: list[TargetRun]
    command: str = ""
    created: str = ""
    mutants: list[JsonObject] = field(default_factory=list)

    @property
    def checks(self) -> list[CheckResult]:
        return [c for r in self.runs for c in r.checks]

    def failed(self) -> bool:
        return any(c.grade is Grade.FAIL for c in self.checks)

    def errored(self) -> bool:
        """Some check could not be run (the harness or the link failed): not a pass."""
        return any(c.grade is Grade.ERROR for c in self.checks)

    def to_json(self) -> dict[str, object]:
        return {
            "format": "conform-results/1",
            "command": self.command,
            "created": self.created,
            "checks": [c.to_json() for c in self.checks],
            "runs": [
                {k: v for k, v in asdict(r).items() if k != "checks"}
                | {"counts": r.counts(), "complete": r.complete}
                for r in self.runs
            ],
            "mutants": self.mutants,
        }

    def dump(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1), encoding="utf-8")

    @staticmethod
    def from_json(d: JsonObject) -> RunResults:
        checks = [CheckResult.from_json(c) for c in d.get("checks", [])]
        runs = []
        for r in d.get("runs", []):
            run = TargetRun(
                target=r["target"], variant=r["variant"], emulated=bool(r.get("emulated")),
                profile=r.get("profile", ""), started=r.get("started", ""),
                duration=float(r.get("duration", 0.0)), aborted=r.get("aborted"),
                notes=list(r.get("notes", [])), state=dict(r.get("state") or {}),
                estimate_s=r.get("estimate_s"), machine_budget_s=r.get("machine_budget_s"),
                not_verified=list(r.get("not_verified") or []),
            )
            run.checks = [c for c in checks if c.target == run.target and c.variant == run.variant]
            runs.append(run)
        return RunResults(runs, d.get("command", ""), d.get("created", ""), d.get("mutants", []))

    @staticmethod
    def load(path: str | Path) -> RunResults:
        p = Path(path)
        try:
            data = json.loads(read_user_text(p))
        except json.JSONDecodeError as exc:
            raise UserError(f"{p}: line {exc.lineno} column {exc.colno}: {exc.msg}") from None
        if not isinstance(data, dict) or not isinstance(data.get("checks"), list):
            raise UserError(f"{p}: not a conform results file (no 'checks' list)")
        try:
            return RunResults.from_json(data)
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{p}: malformed results: {exc}") from None
