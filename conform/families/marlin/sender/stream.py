"""Marlin's reference streamer behind ``conform send``: numbered, checksummed lines (queue.cpp
checks both), ``M110 N0`` first so the unit's line count starts where ours does, one line in
flight, and the line the unit names sent again on ``Resend: N`` (its ``Error:…`` comes first,
an ``ok`` after, which acknowledges the resend request, not a line).

An ``echo:Unknown command`` is counted and named (Marlin skips the line and goes on, and so
does the sender: slicers write commands a build leaves out, such as G21 without
INCH_MODE_SUPPORT). It stops on a unit that restarts
(``start``) or halts (``Error:Printer halted``, ``!!``), on a line the unit keeps asking for,
and on a silent link (nothing, not even ``busy: processing``, for ``timeout`` seconds). A
lost ``ok`` is found the way hosts find it: after two seconds of silence an unnumbered ``M105``
is sent; Marlin answers in order, so its ``ok T:…`` before our line's ``ok`` means that
``ok`` was lost (and a line that never arrived is asked for again by the next line's
``Resend:``), and after it the answer is a late one to pass over. After
the last line it sends ``M400`` (wait for the moves to end) and ``M114`` (where the unit
stands).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from conform.conformance.target import HarnessError
from conform.errors import UserError, read_user_text
from conform.families.marlin.protocol.codec import frame, split_lines

RESEND_LIMIT = 5   # the same line asked for again this many times: the link is too noisy
POKE = 2.0         # seconds of silence before an unnumbered M105 asks for a sign of life


class LinkLost(HarnessError):
    """Nothing came back for the timeout."""


@dataclass(frozen=True)
class JobLine:
    number: int    # 1-based line of the job file
    text: str      # as written
    command: str   # without comment and surrounding spaces


def load_job(path: str, *, max_cmd_size: int) -> list[JobLine]:
    """The job's commands (``;`` comments and blank lines left out); one ``UserError`` line
    for a line Marlin would cut or that carries its own number or checksum."""
    out: list[JobLine] = []
    for n, text in enumerate(read_user_text(path).splitlines(), 1):
        command = text.split(";", 1)[0].strip()
        if not command:
            continue
        if command[:1] in ("N", "n") or "*" in command:
            raise UserError(f"{path}:{n}: the line has its own number or checksum; the sender "
                            "numbers and checksums every line itself")
        if not command.isascii() or any(ord(c) < 0x20 for c in command):
            raise UserError(f"{path}:{n}: a byte that is not G-code text; nothing was sent")
        longest = len(frame(n + 2, command)) - 1   # as framed, without the newline
        if longest > max_cmd_size - 2:
            raise UserError(f"{path}:{n}: {longest} bytes once numbered and checksummed; Marlin "
                            f"reads {max_cmd_size - 2} of a line (MAX_CMD_SIZE {max_cmd_size}) "
                            "and skips the rest; nothing was sent")
        out.append(JobLine(n, text, command))
    if not out:
        raise UserError(f"{path}: no line to send (only blank lines and comments)")
    return out


@dataclass
class Stats:
    sent: int = 0          # job lines acknowledged or in flight (resends not counted)
    ok: int = 0
    resends: int = 0
    unknown: list[str] = field(default_factory=list)   # job lines the unit did not know
    t0: float = 0.0
    t_end: float = 0.0
    position: str = ""
    stopped: str | None = None

    @property
    def seconds(self) -> float:
        return self.t_end - self.t0


class Streamer:
    def __init__(self, target: Any, lines: list[JobLine], *, timeout: float, job: str,
                 progress: Callable[[Streamer], None] | None = None) -> None:
        self.target = target
        self.lines = lines
        self.timeout = timeout
        self.job = job
        self.progress = progress
        self.stats = Stats()
        self._buf = b""
        self._late = 0   # answers owed to M105s whose exchange ended before them

    def run(self) -> Stats:
        st = self.stats
        st.t0 = self.target.now()
        self.target.drain()
        outcome = "restarted"
        while outcome == "restarted":   # a board that resets as the port opens: again after start
            outcome = self._exchange(0, "M110 N0", ready=True)
        if outcome != "ok":
            raise UserError(f"the unit did not take M110 N0: {outcome}; nothing else was sent",
                            exit_code=1)
        for k, line in enumerate(self.lines, 1):
            st.sent = k
            outcome = self._exchange(k, line.command)
            if outcome.startswith("Unknown command"):
                st.unknown.append(f"{self.job}:{line.number} {line.text.strip()!r}")
                outcome = "ok"
            if outcome != "ok":
                st.stopped = f"{self.job}:{line.number} {line.text.strip()!r}: {outcome}"
                break
            st.ok += 1
            if self.progress is not None:
                self.progress(self)
        if st.stopped is None:
            n = len(self.lines)
            self._exchange(n + 1, "M400")
            heard: list[str] = []
            self._exchange(n + 2, "M114", heard=heard)
            st.position = next((x for x in heard if x.startswith("X:")), "")
        st.t_end = self.target.now()
        return st

    def _exchange(self, n: int, command: str, *, ready: bool = False,
                  heard: list[str] | None = None) -> str:
        """Send line ``n`` until the unit takes it: ``ok``, ``restarted`` (while getting
        ready), or why the job cannot go on."""
        asked = 0
        while True:
            self.target.send(frame(n, command))
            outcome, resend = self._await(heard, ready)
            if resend is None:
                return outcome
            if resend != n and n != 0:   # M110 N0 not taken: the unit asks for its own next
                return (f"the unit asks for line {resend} while line {n} was the one in "
                        "flight; its line count is not ours")
            asked += 1
            self.stats.resends += 1
            if asked > RESEND_LIMIT:
                return f"the unit asked for it again {asked} times (a link this noisy is lost)"

    def _await(self, heard: list[str] | None, ready: bool) -> tuple[str, int | None]:
        """Read until the ``ok`` that ends this exchange; (outcome, the line asked for again)."""
        resend: int | None = None
        unknown = ""
        poked = 0
        heard_at = self.target.now()
        while True:
            now = self.target.now()
            if now - heard_at >= self.timeout:
                raise LinkLost(f"nothing from the unit for {self.timeout:g} s")
            if now - heard_at >= POKE * (poked + 1):
                self.target.send(b"M105\n")
                poked += 1
            data = self.target.receive(min(now + 0.05, heard_at + self.timeout))
            if not data:
                continue
            heard_at = self.target.now()
            lines, self._buf = split_lines(self._buf + data)
            for text in (x.decode("latin-1").strip() for x in lines):
                if heard is not None:
                    heard.append(text)
                if text.startswith("Resend:"):
                    digits = text.split(":", 1)[1].strip()
                    resend = int(digits) if digits.isdigit() else -1
                elif text.startswith("echo:Unknown command"):
                    unknown = text.removeprefix("echo:")
                elif text.startswith(("Error:Printer halted", "!!")):
                    return f"the unit halted ({text})", None
                elif text == "start":
                    if ready:
                        return "restarted", None
                    return "the unit restarted (start): the lines in its queue are lost", None
                elif text.startswith("ok") and " T:" in text and (self._late or poked):
                    if self._late:   # the answer to an M105 of an exchange that has ended
                        self._late -= 1
                        continue
                    poked -= 1       # ours came first: the line's own ok was lost
                    self._late += poked
                    return (unknown or "ok"), resend
                elif text.startswith("ok"):
                    self._late += poked
                    return (unknown or "ok"), resend
