"""A toy protocol family, written against conform's family contract only (conform.families),
registered through the ``conform.families`` entry point group by its own dist-info
(tests/toyfamily/toyline-0.1.dist-info): the proof that a new family is one new package and no
engine edit. Its protocol (tables/variants.toml): PING, SET n, GET, HALT, one CR-ended line each.
Its check-sender (``check_sender``): a clean line and one losing answers, and two rules graded
from what the unit executed.
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.conformance.results import MUST, CheckResult, Grade
from conform.conformance.runner import Runner
from conform.errors import UserError
from conform.families import Detection, Family, VariantInfo, table_folder
from conform.sendercheck import family as sender

ANSWER_TIME = 0.002  # s from a line's CR to its answer


def _tables(root: str | None = None) -> dict[str, dict[str, Any]]:
    folder = Path(root) if root else table_folder("toy", __name__)
    try:
        return tomllib.loads((folder / "variants.toml").read_text())["variant"]
    except (OSError, KeyError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"{folder / 'variants.toml'}: {exc}") from None


class ToyUnit:
    """The sans-I/O reference unit: bytes and a time in, answers with their due times out."""

    def __init__(self, top: int, t0: float = 0.0, mutant: str | None = None) -> None:
        self.top, self.now, self.mutant = top, t0, mutant
        self.value, self.line, self.out = 0, b"", []
        self.executed: list[str] = []

    def receive(self, data: bytes, t: float) -> None:
        self.now = t
        for b in data:
            if b != 0x0D:
                self.line += bytes([b])
                continue
            self.out.append((t + ANSWER_TIME, self._answer(self.line.decode("latin-1").strip()) + b"\r"))
            self.line = b""

    def _answer(self, text: str) -> bytes:
        word, _, arg = text.partition(" ")
        if word == "PING":
            return b"PANG" if self.mutant == "no-pong" else b"PONG"
        if word == "GET":
            return b"VAL %d" % self.value
        if word == "HALT":
            return b"OK"
        if word == "SET" and arg.isdigit():
            top = self.top + 1 if self.mutant == "range-plus-one" else self.top
            if int(arg) > top:
                return b"ERR range"
            self.value = int(arg)
            self.executed.append(text)
            return b"OK"
        return b"ERR unknown"

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        self.now = max(self.now, t)
        due = [o for o in self.out if o[0] <= t]
        self.out = [o for o in self.out if o[0] > t]
        return due

    def next_deadline(self) -> float | None:
        return min((o[0] for o in self.out), default=None)


@dataclass(frozen=True)
class ToyCheck:
    id: str
    title: str
    send: bytes
    expect: bytes
    clause: str = "variants.toml"
    level: str = MUST

    @property
    def subject(self) -> str:
        return self.send.split()[0].decode()


class ToyRunner(Runner):
    def run_check(self, check: ToyCheck) -> CheckResult:
        if not self.target.emulated:
            self.target.resync()
        reply = self.target.exchange(check.send + b"\r", timeout=0.5)
        got = reply.lines[0] if reply.lines else b""
        grade = Grade.PASS if got == check.expect else Grade.FAIL
        return CheckResult(check.id, grade, check.clause, check.level, check.title,
                           expected=check.expect.decode(), actual=reply.text(),
                           log=list(self.target.log), variant=self.variant_id,
                           target=self.target.name)

    def halt(self, after_silence: bool = False) -> str:
        reply = self.target.exchange(b"HALT\r", timeout=0.5)
        return f"HALT answered {reply.text()}"


@dataclass
class ToyAnalysis:
    path: str
    lines: int
    answered: int
    errors: int
    duration: float
    findings: list[Any] = field(default_factory=list)   # what check-sender lists (none here)

    def summary_lines(self) -> list[str]:
        return [f"toy: {self.lines} lines, {self.answered} answered, {self.errors} errors "
                f"in {self.duration:.3f} s"]

    def write_report(self, directory: str) -> dict[str, Path]:
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.md").write_text("\n".join(["# toy session", "", *self.summary_lines()]) + "\n")
        (out / "findings.json").write_text(json.dumps({"findings": [], "errors": self.errors}))
        return {"summary": out / "summary.md", "findings": out / "findings.json"}

    def write_tables(self, directory: str) -> dict[str, Path]:
        import pandas as pd

        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        path = out / "toy_lines.parquet"
        pd.DataFrame({"lines": [self.lines], "errors": [self.errors]}).to_parquet(path)
        return {"lines": path}

    def fleet_row(self) -> dict[str, Any]:
        return {"family": "toy", "state": "clean", "exchanges": self.lines,
                "errors": self.errors, "duration_s": round(self.duration, 3)}


# -- check-sender: scenarios, rules graded from the unit's ground truth, the hooks -------------

SENDER_CLAUSE = "variants.toml (SET n -> OK: the register takes n; one answer a line)"


@dataclass(frozen=True)
class ToyVariant:
    id: str
    top: int


def _sets(lines: list[str]) -> list[str]:
    """The job's SET lines as the unit keeps them (words single-spaced)."""
    return [" ".join(x.split()) for x in lines if x.split()[:1] == ["SET"]]


def _none_skipped(s: Any) -> tuple[Any, ...]:
    """Every SET line of the job executed (as often as the job has it)."""
    left = list(s.truth["executed"])
    missing = []
    for line in _sets(s.job_lines):
        if line in left:
            left.remove(line)
        else:
            missing.append(line)
    grade = sender.FAIL if missing else sender.PASS
    detail = f"{len(missing)} SET lines never executed" + (f", first {missing[0]!r}" if missing else "")
    return grade, detail, missing[:5], "every SET line of the job executed"


def _once_in_order(s: Any) -> tuple[Any, ...]:
    """What the unit executed is the job's SET lines in the job's order, none twice (lines may
    be missing: that is the other rule's)."""
    job, executed = _sets(s.job_lines), s.truth["executed"]
    at = 0
    for k, line in enumerate(executed):
        try:
            at = job.index(line, at) + 1
        except ValueError:
            why = "again or out of order" if line in job else "not a line of the job"
            return (sender.FAIL, f"execution {k + 1}: {line!r} {why}", executed[max(0, k - 2):k + 1],
                    "the job's SET lines in order, each once")
    return sender.PASS, f"{len(executed)} SET lines executed in the job's order", []


def _settle(s: Any, unit: ToyUnit, _truth: Any) -> None:
    s.truth = {"executed": list(unit.executed), "value": unit.value}
    (s.directory / "truth.json").write_text(json.dumps(s.truth, indent=1), "utf-8")


def _sender_variant(variant_id: str) -> tuple[ToyVariant, None]:
    rows = _tables()
    if variant_id not in rows:
        raise UserError(f"{variant_id!r}: not a toy variant ({', '.join(rows)})")
    return ToyVariant(variant_id, rows[variant_id]["max"]), None


def _analyze(capture: Any, _variant_id: str) -> ToyAnalysis:
    return FAMILY.analyze(str(capture))


SENDER_SHAPES = sender.Family(
    name="toy", default_variant="toy-1",
    scenarios={sc.name: sc for sc in (
        sender.Scenario("clean", "a clean job of SET lines", timeout=20.0),
        sender.Scenario("lost-answers", "one answer in ten never arrives", lose=0.1,
                        timeout=20.0))},
    rules=(sender.Rule("none-skipped", "every SET line executed", SENDER_CLAUSE, sender.MUST,
                       _none_skipped),
           sender.Rule("once-in-order", "SET lines executed once, in the job's order",
                       SENDER_CLAUSE, sender.MUST, _once_in_order)),
    job=lambda _scn, _v, given: list(given or [f"SET {i}" for i in range(1, 41)]),
    units=_sets, variant=_sender_variant,
    make_unit=lambda v, _ctx, t0, _scn: ToyUnit(v.top, t0),
    control=lambda _faults: None, observe=lambda unit, _t0: unit,
    taken=lambda unit: len(unit.executed), settle=_settle, analyze=_analyze,
    truth_findings=lambda _s: [], decode=False,
)


class ToyFamily(Family):
    name = "toy"
    title = "the toy line protocol (tests)"
    table_files = ("variants",)
    check_sender = SENDER_SHAPES

    def load_tables(self, root: str | None = None) -> Any:
        return _tables(root)

    def variants(self) -> Sequence[VariantInfo]:
        return [VariantInfo(vid, self.name, row["title"], "toy", "-", f"register 0..{row['max']}")
                for vid, row in _tables().items()]

    def mutants(self) -> Sequence[str]:
        return ("range-plus-one", "no-pong")

    def make_unit(self, variant: str, *, t0: float = 0.0, mutant: str | None = None,
                  **_: Any) -> ToyUnit:
        return ToyUnit(_tables()[variant]["max"], t0, mutant)

    def plan_checks(self, variant: str, *, permissions: Any, profile: str = "quick",
                    patterns: Sequence[str] = (), machine: bool = True, **_: Any) -> list[ToyCheck]:
        import fnmatch

        top = _tables()[variant]["max"]
        checks = [ToyCheck(f"{variant}/ping", "PING answers PONG", b"PING", b"PONG"),
                  ToyCheck(f"{variant}/set-max", "SET at the top of the range", b"SET %d" % top, b"OK"),
                  ToyCheck(f"{variant}/set-over", "SET past the range is refused", b"SET %d" % (top + 1),
                           b"ERR range"),
                  ToyCheck(f"{variant}/unknown", "an unknown word", b"JUMP", b"ERR unknown")]
        return [c for c in checks if not patterns or any(fnmatch.fnmatchcase(c.id, p) for p in patterns)]

    def runner(self, target: Any, variant: str, *, options: Any = None, permissions: Any = None,
               **_: Any) -> ToyRunner:
        return ToyRunner(target, variant, options)

    def serve(self, variant: str, **options: Any) -> None:
        from conform.emulator.launch import ServedUnit, serve_unit

        top = _tables()[variant]["max"]
        serve_unit(self.name, variant, lambda t0: ServedUnit(ToyUnit(top, t0), decode=False),
                   **options)

    def detect(self, host: bytes, unit: bytes, metadata: dict[str, Any]) -> Detection:
        words = [ln.split(b" ")[0] for ln in host[:65536].split(b"\r") if ln]
        known = sum(w in (b"PING", b"SET", b"GET", b"HALT") for w in words)
        score = known / len(words) if words else 0.0
        return Detection(self.name, score, f"{known} of {len(words)} host lines are toy commands")

    def analyze(self, path: str, **options: Any) -> ToyAnalysis:
        from conform.analysis.stream import read_raw

        raw = read_raw(path)
        host = raw.host.data.tobytes()
        unit = raw.unit.data.tobytes()
        answers = [a for a in unit.split(b"\r") if a]
        times = list(raw.host.t_first.tolist()) + list(raw.unit.t_read.tolist())
        return ToyAnalysis(path, sum(1 for ln in host.split(b"\r") if ln), len(answers),
                           sum(a.startswith(b"ERR") for a in answers),
                           (max(times) - min(times)) if times else 0.0)


FAMILY = ToyFamily()
