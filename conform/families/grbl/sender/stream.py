"""grbl's reference streamer: the two streaming methods grbl documents (interface.md,
"Streaming Protocol"), over any target with ``send(bytes)``, ``receive(deadline)`` and
``now()`` (the engine's ``EmuTarget`` on a virtual clock, a ``LinkTarget`` on the wall clock).

``counting``: keep the bytes of the lines sent and not yet answered (newline included) within
grbl's serial receive buffer, sending the next line as soon as it fits; ``send-response``: one
line, then wait for its ``ok`` or ``error:N``. Every line gets exactly one answer, in order,
so the oldest unanswered line is the one answered.

It stops on ``error:N`` (naming the job line), on ``ALARM:N``, on grbl restarting (its
banner: what was in its buffers is gone) and on a silent link: when nothing has come for a
second it asks ``?`` (a realtime byte, outside the count, that grbl answers in any state), and
when nothing has come for ``timeout`` seconds the link is taken as lost.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from conform.conformance.target import HarnessError
from conform.families.grbl.protocol.codec import UnitLine, split_unit
from conform.families.grbl.sender.job import JobLine
from conform.families.grbl.spec.load import GrblSpec

METHODS = ("counting", "send-response")
POLL_SILENCE = 1.0   # seconds without a byte before '?' is asked
POLL_IDLE = 0.2      # seconds between '?' while waiting for the motion to end
_STATE = re.compile(r"^<([A-Za-z]+)")
_POS = re.compile(r"[|,]([MW]Pos):([-\d.,]+)")


class LinkLost(HarnessError):
    """Nothing came back for the timeout, or the port failed."""


@dataclass
class Stopped:
    """Why the stream stopped before the job's end."""

    kind: str            # error | alarm | restart
    message: str
    after: int | None    # index of the job line it concerns (None: before any)
    flush: bool = False  # lines sent after it are in grbl's buffers: halt the unit


@dataclass
class Stats:
    sent: int = 0
    ok: int = 0
    errors: int = 0
    max_in_flight: int = 0
    polls: int = 0
    t0: float = 0.0
    t_end: float = 0.0
    state: str = ""       # the last state a status report gave
    position: str = ""    # its position field (MPos:x,y,z or WPos:x,y,z)
    stopped: Stopped | None = None
    answered: list[str] = field(default_factory=list)

    @property
    def seconds(self) -> float:
        return self.t_end - self.t0


class Streamer:
    """Stream ``lines`` to ``target`` with ``method``; :meth:`run` returns the stats."""

    def __init__(self, target: Any, lines: list[JobLine], spec: GrblSpec, *, rx_buffer: int,
                 method: str = "counting", timeout: float = 5.0, job: str = "job",
                 progress: Callable[[Streamer], None] | None = None) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown streaming method {method!r}")
        self.target = target
        self.lines = lines
        self.spec = spec
        self.rx_buffer = rx_buffer
        self.method = method
        self.timeout = timeout
        self.job = job
        self.progress = progress
        self.stats = Stats()
        self.pending: deque[int] = deque()   # job line indexes sent and not answered
        self.in_flight = 0                   # their bytes
        self._buf = b""
        self._heard = 0.0                    # when the unit was last heard
        self._asked = 0.0                    # when '?' was last sent

    # -- the phases ------------------------------------------------------------------------------
    def run(self) -> Stats:
        """Ready check, the stream, then the wait for the motion to end."""
        st = self.stats
        st.t0 = self.target.now()
        self.ready()
        i = 0
        while st.stopped is None and (i < len(self.lines) or self.pending):
            if i < len(self.lines) and self._room(self.lines[i].size):
                self._send_line(i)
                i += 1
                continue
            self._listen()
        if st.stopped is None:
            self.settle()
        st.t_end = self.target.now()
        return st

    def ready(self) -> None:
        """Ask ``?`` until a status report comes: the unit is there and may take a job (Idle or
        Check); a banner on the way (a unit that resets as the port opens) is waited out."""
        self.target.drain()   # what came before us (a banner, answers to another program)
        self._heard = self._asked = self.target.now()
        self.target.send(b"?")
        wait = max(2.0, self.timeout)
        while not self.stats.state:
            self._listen(poll_every=0.5, silence=wait)
        state = self.stats.state
        if state == "Alarm":
            raise ReadyError(f"the unit is in Alarm ({self.stats.position or 'position unknown'}): "
                             "unlock ($X) or home ($H) first; nothing was sent")
        if state not in ("Idle", "Check"):
            raise ReadyError(f"the unit is busy ({state}); a job starts from Idle; nothing was "
                             "sent")

    def settle(self) -> None:
        """After the last answer: ask ``?`` until the motion has ended (Idle)."""
        self.stats.state = ""
        while self.stats.stopped is None and self.stats.state not in ("Idle", "Check", "Alarm"):
            self._listen(poll_every=POLL_IDLE)

    # -- sending -------------------------------------------------------------------------------
    def _room(self, size: int) -> bool:
        if self.method == "send-response":
            return not self.pending
        return self.in_flight + size <= self.rx_buffer

    def _send_line(self, i: int) -> None:
        line = self.lines[i]
        self.target.send(line.block + b"\n")
        self.pending.append(i)
        self.in_flight += line.size
        self.stats.sent += 1
        self.stats.max_in_flight = max(self.stats.max_in_flight, self.in_flight)
        if self.progress is not None:
            self.progress(self)

    # -- listening -----------------------------------------------------------------------------
    def _listen(self, poll_every: float | None = None, silence: float | None = None) -> None:
        """Read what comes within a short while and act on each line; ask ``?`` after
        ``poll_every`` s of silence (a second, or half the timeout when that is shorter);
        raise ``LinkLost`` after ``silence`` (the timeout)."""
        t = self.target
        now = t.now()
        limit = self.timeout if silence is None else silence
        if poll_every is None:
            poll_every = min(POLL_SILENCE, limit / 2)
        if now - self._heard >= limit:
            raise LinkLost(f"nothing from the unit for {limit:g} s")
        if now - max(self._heard, self._asked) >= poll_every:
            t.send(b"?")
            self._asked = now
            self.stats.polls += 1
        data = t.receive(min(now + 0.05, self._heard + limit))
        if not data:
            return
        self._heard = t.now()
        got, self._buf = split_unit(self._buf + data, self.spec)
        for line in got:
            self._answer(line)
            if self.stats.stopped is not None:
                return
        if self.progress is not None:
            self.progress(self)

    def _answer(self, u: UnitLine) -> None:
        st = self.stats
        if u.kind in ("ok", "error"):
            if not self.pending:   # an answer to no line of ours (a line sent before us)
                return
            i = self.pending.popleft()
            self.in_flight -= self.lines[i].size
            st.answered.append(u.text)
            if u.kind == "ok":
                st.ok += 1
                return
            st.errors += 1
            meaning = self.spec.errors[u.code].name if u.code in self.spec.errors else "unknown"
            st.stopped = Stopped("error", f"{self.lines[i].where(self.job)}: {u.text} "
                                 f"({meaning})", i, flush=bool(self.pending))
        elif u.kind == "alarm":
            meaning = self.spec.alarms[u.code].name if u.code in self.spec.alarms else "unknown"
            last = self._last_answered()
            where = f"after {self.lines[last].where(self.job)}" if last is not None else \
                "before any job line was answered"
            st.stopped = Stopped("alarm", f"{u.text} ({meaning}) {where}: grbl stopped the job "
                                 "and locks out until $X or $H", last)
        elif u.kind == "banner" and st.sent:
            last = self._last_answered()
            st.stopped = Stopped("restart", f"grbl restarted ({u.text!r}) with {len(self.pending)} "
                                 "job lines unanswered: what was in its buffers is lost", last)
        elif u.kind == "status":
            m = _STATE.match(u.text)
            st.state = m.group(1) if m else st.state
            pos = _POS.search(u.text)
            st.position = f"{pos.group(1)}:{pos.group(2)}" if pos else st.position

    def _last_answered(self) -> int | None:
        n = self.stats.ok + self.stats.errors
        return n - 1 if n else None


class ReadyError(Exception):
    """The unit is not ready for a job (Alarm, busy): nothing was sent."""
