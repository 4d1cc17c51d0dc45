"""Deviant Marlin units (``emu:marlin-2.1:<mutant>``): each does one thing differently from
the source, as a firmware fork or a simulator might; a conformance run must catch every one.
"""

from __future__ import annotations

from typing import Any

from conform.families.marlin.spec import MarlinSpec, Variant
from conform.families.marlin.unit.unit import MarlinUnit, Queued


class ResendOffByOne(MarlinUnit):
    """Asks for the last line accepted instead of the next one."""

    def _line_error(self, message: str, why: str) -> bool:
        self.last_n -= 1
        try:
            return super()._line_error(message, why)
        finally:
            self.last_n += 1


class NoOkAfterResend(MarlinUnit):
    """Resend: without the ok after it (older Marlin did this)."""

    def _line_error(self, message: str, why: str) -> bool:
        r = super()._line_error(message, why)
        self._out.pop()
        return r


class AnswersDuplicate(MarlinUnit):
    """Answers a repeated line number with an error and a resend, as the docs suggest."""

    def _duplicate(self, n: int, line: bytes) -> bool:
        return self._line_error("Line Number is not Last Line Number+1", "line-number")


class RunsDuplicate(MarlinUnit):
    """Runs a repeated line number again: the line is executed twice."""

    def _duplicate(self, n: int, line: bytes) -> bool:
        self.queue.append(Queued(line.decode("latin-1"), n, self.now))
        return True


class NoChecksumCheck(MarlinUnit):
    """Takes a damaged line as it came."""

    def _checksum_ok(self, command: bytes, star: int) -> bool:
        return True


class CommentKeepsChecksum(MarlinUnit):
    """Treats ';' as an ordinary character, so a checksum after a comment survives."""

    def _stream_char(self, c: int) -> None:
        super()._stream_char(0x3A if c == 0x3B else c)


class NoKeepalive(MarlinUnit):
    """Never says busy: processing."""

    def _start(self, q: Queued) -> None:
        super()._start(q)
        self.cur_busy = False


class AnswersAfterHalt(MarlinUnit):
    """Goes on answering after M112."""

    def _kill(self, t: float) -> None:
        self._say(t, "Error:Printer halted. kill() called!")


class SilentUnknown(MarlinUnit):
    """Says ok to an unknown command without naming it."""

    def _unknown(self, q: Queued, t: float) -> None:
        return None


MUTANTS: dict[str, type[MarlinUnit]] = {
    "resend-off-by-one": ResendOffByOne,
    "no-ok-after-resend": NoOkAfterResend,
    "answers-duplicate": AnswersDuplicate,
    "runs-duplicate": RunsDuplicate,
    "no-checksum-check": NoChecksumCheck,
    "comment-keeps-checksum": CommentKeepsChecksum,
    "no-keepalive": NoKeepalive,
    "answers-after-halt": AnswersAfterHalt,
    "silent-unknown": SilentUnknown,
}


def make(v: Variant, spec: MarlinSpec, *, t0: float = 0.0, mutant: str | None = None,
         **options: Any) -> MarlinUnit:
    """The reference unit, or the deviant one called ``mutant``."""
    if mutant is None:
        return MarlinUnit(v, spec, t0=t0, **options)
    if mutant not in MUTANTS:
        from conform.errors import UserError

        raise UserError(f"no Marlin mutant {mutant!r} (known: {', '.join(MUTANTS)})")
    return MUTANTS[mutant](v, spec, t0=t0, **options)
