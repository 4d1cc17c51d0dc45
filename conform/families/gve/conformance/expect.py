"""What the spec allows: the reference unit's transcript of a script, per dialect, and the
comparison that grades a target's transcript against it.

A check passes when the target answers every step as the reference unit does under the expected
dialect. When it does not, the same script is run on references that differ in one open question
(A-register); if one of them reproduces the target's whole transcript the check is a DEVIATION on
that question, otherwise a FAIL at the first step that differs.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from conform.conformance.target import Reply
from conform.families.gve.conformance.script import ENVIRONMENT, POSITION, Script, Step, run_script
from conform.families.gve.conformance.target import GveEmuTarget
from conform.families.gve.protocol.checksum import verify

# open questions that bear on any script, whatever its commands
GLOBAL_QUESTIONS = ("A24", "A10", "A11", "A22", "A21", "A14", "A20", "A25", "A26", "A23", "A9")

_CACHE: dict[tuple[Any, ...], list[Reply | None]] = {}
_CACHE_MAX = 60000


def dialect_key(dialect: Any) -> tuple[tuple[str, str], ...]:
    return tuple(sorted(dialect.changed().items()))


class Reference:
    """The reference unit of one variant; transcripts of scripts per dialect, cached."""

    def __init__(self, spec: Any, variant_id: str, dialect: Any = None,
                 unit_cls: Any = None) -> None:
        self.spec = spec
        self.variant = spec.variant(variant_id)
        self.dialect = dialect if dialect is not None else spec.dialect()
        if unit_cls is None:
            from conform.families.gve.unit.model import Unit as unit_cls
        self.unit_cls = unit_cls
        self._parser: dict[Any, Any] = {}

    def with_choice(self, question: str, alternative: str) -> Any:
        return self.spec.dialect(self.dialect.changed() | {question: alternative})

    def transcript(self, script: Script, dialect: Any = None) -> list[Reply | None]:
        d = self.dialect if dialect is None else dialect
        key = (self.variant.id, self.unit_cls, dialect_key(d), script)
        hit = _CACHE.get(key)
        if hit is not None:
            return hit
        variant, cls = self.variant, self.unit_cls
        target = GveEmuTarget(lambda: cls(variant, d), "reference")
        replies = run_script(target, script)
        if len(_CACHE) >= _CACHE_MAX:
            _CACHE.clear()
        _CACHE[key] = replies
        return replies

    def command_ids(self, script: Iterable[Step]) -> list[str]:
        """The spec row ids a script's lines name (for the open questions they bear on)."""
        from conform.families.gve.protocol import Command, CommandParser

        parser = self._parser.get("p")
        if parser is None:
            parser = self._parser["p"] = CommandParser(self.variant, self.spec.dialect())
        out = []
        for step in script:
            if not step.line:
                continue
            line = step.line.rstrip(b"\r\n")
            parsed = parser.parse(line, verify(line))
            name = parsed.name if isinstance(parsed, Command) else getattr(parsed, "name", None)
            if name:
                out.append(name)
        return out

    def candidate_questions(self, script: Iterable[Step], first: Sequence[str] = (),
                            include_global: bool = True) -> list[str]:
        seen: list[str] = []
        for q in first:
            if q not in seen:
                seen.append(q)
        for cid in self.command_ids(script):
            cmd = self.spec.commands.get(cid)
            for q in cmd.questions if cmd else ():
                if q not in seen:
                    seen.append(q)
        for q in GLOBAL_QUESTIONS if include_global else ():
            if q not in seen:
                seen.append(q)
        return [q for q in seen if q in self.spec.questions]


# --- comparing answers --------------------------------------------------------------------------

def _split(line: bytes) -> tuple[bytes, bool]:
    """(line without a valid checksum tail, had one)."""
    if verify(line):
        return line[:-3], True
    return line, False


_FLOAT = r"-?(?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?|-?inf|nan"
_RADIX = {"dec": r"-?\d+", "float": _FLOAT, "hex": r"[0-9A-F]{%d}", "text": r".{%d}"}


def _field_shape_ok(expected: str, actual: str, shape: tuple[str, int | None] | None = None
                    ) -> bool:
    """Does ``actual`` have the shape of the table's answer field (radix, width; upper-case
    hex), or without a table entry the shape of ``expected``?"""
    if shape is not None:
        radix, width = shape
        pattern = _RADIX.get(radix, r".+")
        if "%d" in pattern:
            pattern = pattern % width if width else pattern.replace("{%d}", "+")
        return re.fullmatch(pattern, actual) is not None
    if re.fullmatch(r"-?\d+", expected):
        return re.fullmatch(r"-?\d+", actual) is not None
    if re.fullmatch(r"[0-9A-F]+", expected):
        return re.fullmatch(r"[0-9A-F]{%d}" % len(expected), actual) is not None
    return bool(actual) or not expected


def line_mismatch(step: Step, expected: bytes, actual: bytes, loose: bool,
                  tol: float) -> str | None:
    if expected == actual:
        return None
    if not loose or step.kind not in (POSITION, ENVIRONMENT):
        return "answer differs"
    e_body, e_sum = _split(expected)
    a_body, a_sum = _split(actual)
    if e_sum != a_sum:
        return "checksum missing or wrong" if e_sum else "unexpected checksum"
    e_f, a_f = e_body.decode("latin-1").split(","), a_body.decode("latin-1").split(",")
    if e_f[0] != a_f[0]:
        return "answer code differs"
    if len(e_f) != len(a_f):
        return f"{len(a_f) - 1} fields where {len(e_f) - 1} were expected"
    for i, (e, a) in enumerate(zip(e_f[1:], a_f[1:], strict=True)):
        if step.kind == POSITION:
            if re.fullmatch(r"-?\d+", a) is None:  # no sign +, spaces or LF (§13.7)
                return f"position field {a!r} is not an integer"
            if abs(int(e) - int(a)) > tol:
                return f"position {a} is not within {tol:g} of {e}"
        elif not _field_shape_ok(e, a, step.shape[i] if i < len(step.shape) else None):
            return f"field {a!r} does not have the shape of {e!r}"
    return None


def _trailing(reply: Reply) -> bytes:
    return getattr(reply, "trailing", b"")


def _shown(data: bytes) -> str:
    return repr(data.decode("latin-1"))


def _trailing_mismatch(expected: bytes, actual: bytes, loose: bool) -> str | None:
    """The answer judged whole (GVE64 §13.7: the code, its fields, Enter 0Dh): bytes after its
    CR before the line went quiet are part of it. On a link, lines the reference also sends
    unasked there (MPG reports) may differ in content, never in framing."""
    if actual == expected:
        return None
    if loose and expected and (not actual or actual.endswith(b"\r") and b"\n" not in actual):
        return None
    return f"bytes after the answer's CR: {_shown(actual)}"


def moving_tolerance(max_rate: float, expected: Reply, actual: Reply) -> float:
    """How far an axis under way may read from the reference's position: the max rate over the
    time the two readings may lie apart. A unit takes its position between the moment the line
    is written and the moment its answer is back, so the readings may differ by the gap between
    the two writes, plus the time the target's answer took beyond the reference's (a unit that
    is slow to answer read its position later), plus 50 ms for the link's timing."""
    late = 0.0
    if expected.t_rx is not None and actual.t_rx is not None:
        late = max(0.0, (actual.t_rx - actual.t_tx) - (expected.t_rx - expected.t_tx))
    return max_rate * (abs(expected.t_tx - actual.t_tx) + late + 0.05)


def tolerance_of(max_rate: float, loose: bool) -> Callable[[Reply | None, Reply | None], float]:
    """The position tolerance for each (expected, actual) pair of answers: ``moving_tolerance``
    on a link, none in-process (where the two run on one clock)."""

    def tol(expected: Reply | None, actual: Reply | None) -> float:
        if not loose or expected is None or actual is None:
            return 0.0
        return moving_tolerance(max_rate, expected, actual)

    return tol


def reply_mismatch(step: Step, expected: Reply | None, actual: Reply | None, loose: bool,
                   tol: float) -> str | None:
    """Why ``actual`` is not an answer the reference allows for ``step`` (None if it is)."""
    if expected is None or actual is None:
        return None if expected is actual else "step not run"
    if not loose and expected.stray != actual.stray:
        return "unexpected bytes before the command" if actual.stray else "bytes missing"
    if loose and b"\n" in actual.stray and b"\n" not in expected.stray:
        # late bytes of the previous answer: an answer ends with its CR (GVE64 §13.7)
        return f"an LF after the previous answer's CR ({_shown(actual.stray)})"
    if actual.partial and not expected.partial:
        return "answer not terminated by CR"
    if len(expected.lines) != len(actual.lines):
        if not actual.lines and not actual.partial:
            return "no answer"
        return f"{len(actual.lines)} answer line(s) where {len(expected.lines)} were expected"
    if expected.partial != actual.partial and not loose:
        return "unterminated bytes differ"
    for e, a in zip(expected.lines, actual.lines, strict=True):
        why = line_mismatch(step, e, a, loose, tol if expected.moving else 0.0)
        if why:
            return why
    why = _trailing_mismatch(_trailing(expected), _trailing(actual), loose)
    if why:
        return why
    if step.tolerance is not None and expected.t_rx is not None and actual.t_rx is not None:
        d_e, d_a = expected.t_rx - expected.t_tx, actual.t_rx - actual.t_tx
        if abs(d_a - d_e) > step.tolerance:
            return (f"answered after {d_a * 1000:.0f} ms where the reference answers after "
                    f"{d_e * 1000:.0f} ms (tolerance ±{step.tolerance * 1000:.0f} ms)")
    return None


def answers_differ(step: Step, default: Reply | None, other: Reply | None) -> bool:
    """Does an open question's alternative change the answer to ``step`` at all? Only then may
    it explain a target's different answer there: an alternative excuses the behaviour its
    question is about, never a value it leaves as the default has it."""
    if default is None or other is None:
        return default is not other
    if (default.lines, default.partial, default.stray, _trailing(default)) != (
            other.lines, other.partial, other.stray, _trailing(other)):
        return True
    if default.moving != other.moving:
        return True
    if step.tolerance is not None and None not in (default.t_rx, other.t_rx):
        d_e = default.t_rx - default.t_tx  # type: ignore[operator]
        d_o = other.t_rx - other.t_tx  # type: ignore[operator]
        return abs(d_e - d_o) > step.tolerance
    return False


def first_mismatch(script: Script, expected: Sequence[Reply | None], actual: Sequence[Reply | None],
                   loose: bool, tol_of: Callable[[Reply | None, Reply | None], float]
                   ) -> tuple[int, str] | None:
    for i, step in enumerate(script):
        e = expected[i] if i < len(expected) else None
        a = actual[i] if i < len(actual) else None
        why = reply_mismatch(step, e, a, loose, tol_of(e, a))
        if why:
            return i, why
    return None


def show(step: Step, reply: Reply | None) -> str:
    if reply is None:
        return "(nothing)"
    out = reply.text()
    if _trailing(reply):
        out += f" [after the CR: {_shown(_trailing(reply))}]"
    if reply.stray:
        out = f"[unasked: {reply.stray.decode('latin-1')!r}] " + out
    return out


@dataclass
class Verdict:
    grade: str  # PASS | FAIL | DEVIATION
    step: int | None = None
    expected: str = ""
    actual: str = ""
    detail: str = ""
    question: str | None = None
    alternative: str | None = None


def judge(ref: Reference, script: Script, actual: Sequence[Reply | None], *, loose: bool,
          questions: Sequence[str] = (), max_rate: float = 0.0) -> Verdict:
    """Grade a target's transcript of ``script`` against the reference (see module doc)."""

    tol_of = tolerance_of(max_rate, loose)
    expected = ref.transcript(script)
    miss = first_mismatch(script, expected, actual, loose, tol_of)
    if miss is None:
        return Verdict("PASS")
    index, why = miss
    step = script[index]
    exp_text = f"{step.describe()} → {show(step, expected[index])}"
    act_text = f"{step.describe()} → {show(step, actual[index] if index < len(actual) else None)}"
    for q in ref.candidate_questions(script, questions):
        for alt in ref.spec.questions[q].alternatives:
            if alt == ref.dialect[q]:
                continue
            other = ref.transcript(script, ref.with_choice(q, alt))
            if not answers_differ(step, expected[index], other[index] if index < len(other) else None):
                continue
            if first_mismatch(script, other, actual, loose, tol_of) is None:
                meaning = ref.spec.questions[q].alternatives[alt]
                return Verdict("DEVIATION", index, exp_text, act_text,
                               f"{q}={alt}: {meaning}", q, alt)
    return Verdict("FAIL", index, exp_text, act_text, why)
