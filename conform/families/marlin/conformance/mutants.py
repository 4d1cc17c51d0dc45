"""Deviant Marlin units (``emu:marlin-2.1:<mutant>``): each does one thing differently from
the source, as a firmware fork or a simulator might; a conformance run must catch every one.
"""

from __future__ import annotations

from typing import Any

from conform.families.marlin.conformance.deviants import DEVIANTS
from conform.families.marlin.spec import MarlinSpec, Variant
from conform.families.marlin.unit.unit import HeatWait, MarlinUnit, Queued, _code


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
        self._say(t, "echo:M112 Shutdown", "Error:Printer halted. kill() called!")


class SilentUnknown(MarlinUnit):
    """Says ok to an unknown command without naming it."""

    def _unknown(self, q: Queued, t: float) -> None:
        return None


class SilentHeatingWait(MarlinUnit):
    """Waits for the temperature without a report each second."""

    def _plan_wait(self, h: int, t: float) -> HeatWait:
        w = super()._plan_wait(h, t)
        w.reports = 1 << 30              # the first report is never due
        return w


class OkOnReaching(MarlinUnit):
    """Answers M109 / M190 as soon as the temperature is in the window (no residency)."""

    def _plan_wait(self, h: int, t: float) -> HeatWait:
        w = super()._plan_wait(h, t)
        w.end = max(t, min(w.end, w.window_at))
        return w


class IdleWhileHeating(MarlinUnit):
    """Says no busy: processing while waiting for a temperature (as without
    BUSY_WHILE_HEATING) although the configuration has it."""

    def _start(self, q: Queued) -> None:
        super()._start(q)
        if self.wait is not None:
            self.cur_busy = False


class PromptWithoutSupport(MarlinUnit):
    """Takes M876 as a known command although HOST_PROMPT_SUPPORT is off."""

    def _unknown(self, q: Queued, t: float) -> None:
        if _code(q.text) != "M876":
            super()._unknown(q, t)


class UserWaitAlways(MarlinUnit):
    """Has M0/M1 whatever the configuration, and its wait ignores M108 (a fork that compiles
    M0 without HAS_RESUME_CONTINUE and waits out the time)."""

    def _command(self, code: str) -> Any:
        return self.spec.commands[code] if code in ("M0", "M1") else super()._command(code)

    def _break_wait(self, t: float) -> None:
        if self._kind != "user_wait":
            super()._break_wait(t)


class DeafWhileBusy(MarlinUnit):
    """Reads nothing while a command blocks (as a reading of the main loop alone suggests):
    a line error, and an unnumbered M112, are answered only after the block."""

    def _read_serial(self) -> None:
        if self.cur is None:
            super()._read_serial()


class SilentShutdown(MarlinUnit):
    """Halts on M112 without echoing its message (no ``echo:M112 Shutdown``)."""

    def _say(self, t: float, *lines: str) -> None:
        super()._say(t, *(x for x in lines if x != "echo:M112 Shutdown"))


class SlowKeepalive(MarlinUnit):
    """Says busy: processing every 4 s instead of DEFAULT_KEEPALIVE_INTERVAL (2 s)."""

    def _fire(self) -> None:
        busy_due = self.cur is not None and self.cur_busy and self.next_busy <= self.now
        super()._fire()
        if busy_due and self.cur is not None:
            self.next_busy = self.now + 2 * self.v.keepalive


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
    "silent-heating-wait": SilentHeatingWait,
    "ok-on-reaching": OkOnReaching,
    "idle-while-heating": IdleWhileHeating,
    "prompt-without-support": PromptWithoutSupport,
    "user-wait-always": UserWaitAlways,
    "deaf-while-busy": DeafWhileBusy,
    "silent-shutdown": SilentShutdown,
    "slow-keepalive": SlowKeepalive,
}
MUTANTS.update(DEVIANTS)      # settings, EEPROM, reports, tools, messages, dwell, modes


def make(v: Variant, spec: MarlinSpec, *, t0: float = 0.0, mutant: str | None = None,
         **options: Any) -> MarlinUnit:
    """The reference unit, or the deviant one called ``mutant``."""
    if mutant is None:
        return MarlinUnit(v, spec, t0=t0, **options)
    if mutant not in MUTANTS:
        from conform.errors import UserError

        raise UserError(f"no Marlin mutant {mutant!r} (known: {', '.join(MUTANTS)})")
    return MUTANTS[mutant](v, spec, t0=t0, **options)
