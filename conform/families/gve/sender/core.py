"""The reference sender, sans-I/O: a job in, command bytes out, answers in, with a clock.

    s = Sender(items, variant, policy="careful", checksums=True, packet=10)
    s.start(t)
    data = s.poll(t)          # bytes to write now, or b""
    s.receive(answer, t)      # bytes read from the unit
    s.deadline()              # when to call poll() again if nothing arrives
    s.done, s.failed

Policies (what to do when an answer is uncertain or refused):

* ``careful``: strictly simplex, and it acts only on conclusive evidence. After a garbled
  answer or none it waits for stale bytes to settle, then asks ``>`` (it repeats the last
  command and its answer, GVE64 §13.5.13):

  - the echo is our line (and differs from the line before it): it arrived, and the
    repeated answer is its answer;
  - the echo is the line sent before ours: ours never arrived, send it again;
  - no echo where the unit echoes (``repeat_echo``): our ``>`` was damaged, ask again;
  - anything else (no echo in a unit that does not echo, our line identical to the one
    before, a damaged line the unit kept, A29): ask ``@`` and compare the index with the one
    read before our line went out (``>`` and ``@`` do not advance it, A10): unchanged means
    ours never arrived (send it again); advanced by ours means it arrived, and the ``>``
    answer is its answer where the unit does not echo; otherwise the sender stops (H, D)
    rather than guess.

  ``@`` is never asked between our line and ``>``: ``>`` would then repeat the ``@``.
  Queue full (1): wait ``queue_wait`` and send the vector again.
* ``blind``: send the same line again after a garbled answer or none (a double move if the
  first was taken); retry queue-full immediately.
* ``move-on``: take a garbled answer or none as success (a lost vector if it was not taken).
* ``careless``: ``blind`` after a garbled answer, ``move-on`` after no answer.

Packets (``packet`` > 1): runs of C and B lines go out as ``*S`` … ``*E<n>`` with one answer
(GVE64 §13.3.3); an answer ``k,m`` with an error means the first m were taken.
At the end the sender polls ``F`` until the unit is idle and reads the position twice, so
the capture shows where the machine ended.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from conform.families.gve.protocol import Answer, parse_answer
from conform.families.gve.protocol.checksum import append_checksum, verify
from conform.families.gve.sender.job import PACKABLE, Item
from conform.families.gve.spec.model import Variant

POLICIES = ("careful", "blind", "move-on", "careless")
RUN_BIT = 0x40
STOP_BIT = 0x01  # ST6 bit 0: braking after a stop request (GVE64 §13.5.12)


@dataclass
class Unit_:
    """One thing to deliver: a single command or a packet of C/B lines."""

    items: list[Item]
    packet: bool = False
    tries: int = 0
    refused: int = 0

    @property
    def motion(self) -> bool:
        return any(i.motion for i in self.items)


@dataclass
class Stats:
    sent: int = 0
    answers: int = 0
    garbled: int = 0
    timeouts: int = 0
    queue_full: int = 0
    resent: int = 0
    repeats: int = 0
    index_checks: int = 0
    acknowledged: int = 0  # job lines answered 0 (packets: every member)
    unacknowledged: int = 0  # job lines given up or moved past without an answer 0
    errors: list[str] = field(default_factory=list)


class Sender:
    def __init__(self, items: list[Item], variant: Variant, *, policy: str = "careful",
                 checksums: bool = False, packet: int = 1, timeout: float = 0.25,
                 queue_wait: float = 0.02, max_tries: int = 200, address: int | None = None,
                 finish: bool = True, poll_interval: float = 0.1,
                 index_every: str = "answered-except-recovery", repeat_echo: bool = True,
                 give_up: float = 5.0) -> None:
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}")
        self.variant = variant
        self.policy = policy
        self.checksums = checksums
        self.packet = max(1, int(packet))
        self.timeout = timeout
        self.queue_wait = queue_wait
        self.max_tries = max_tries
        self.address = variant.interpolator_address if address is None else address
        self.poll_interval = poll_interval
        self.repeat_echo = repeat_echo  # `>` sends the repeated line before its answer (A9)
        self.finish = finish
        self.give_up = give_up  # seconds without a byte from the unit before failing
        self._heard = 0.0
        self.stats = Stats()
        self.cs_on = False  # checksums as the unit has them now
        self.units: deque[Unit_] = deque(self._group(items))
        self.total = len(items)
        self.done = False
        self.failed: str | None = None
        self.index: int | None = None  # the unit's @ index as we believe it
        self._buf = b""
        self._out = b""
        self._out_t = 0.0
        self._wake = 0.0
        self._deadline: float | None = None
        self._await: str | None = None  # what the line in flight is: unit/repeat/index/...
        self._current: Unit_ | None = None
        self._lines: list[bytes] = []
        self._phase = "start"
        self._stable: list[tuple[str, ...]] = []
        self._sent_line = b""
        self._before = b""  # the line sent just before the current job unit
        self._repeat_ans: Answer | None = None
        self._recoveries = 0
        self.interrupted = False  # an answer carried INTA: the unit was stopped (§13.7)
        self.last_position: tuple[int, ...] | None = None

    # ------------------------------------------------------------------ job shaping
    def _group(self, items: list[Item]) -> list[Unit_]:
        if self.packet <= 1:
            return [Unit_([i]) for i in items]
        out: list[Unit_] = []
        run: list[Item] = []
        vectors = 0

        def flush() -> None:
            nonlocal run, vectors
            if run:
                if vectors > 1:
                    out.append(Unit_(run, packet=True))
                else:
                    out.extend(Unit_([i]) for i in run)
            run, vectors = [], 0

        for it in items:
            if it.name in PACKABLE:
                run.append(it)
                vectors += it.name == "C"
                if vectors >= self.packet:
                    flush()
            else:
                flush()
                out.append(Unit_([it]))
        flush()
        return out

    # ------------------------------------------------------------------ encoding
    def line(self, body: bytes, *, checksum: bool | None = None) -> bytes:
        raw = b"!%d" % self.address + body
        on = self.cs_on if checksum is None else checksum
        return (append_checksum(raw) if on else raw) + b"\r"

    def _unit_bytes(self, u: Unit_) -> bytes:
        if not u.packet:
            return self.line(u.items[0].body)
        parts = [self.line(b"*S")] + [self.line(i.body) for i in u.items]
        parts.append(self.line(b"*E%d" % len(u.items)))
        return b"".join(parts)

    # ------------------------------------------------------------------ driver API
    @property
    def progress(self) -> tuple[int, int]:
        """(job lines finished, job lines in all)."""
        left = sum(len(u.items) for u in self.units)
        if self._current is not None:
            left += len(self._current.items)
        return self.total - left, self.total

    def start(self, t: float) -> None:
        self._wake = t
        self._heard = t
        self._phase = "checksum" if self.checksums else (
            "sync" if self.policy == "careful" else "job")

    def deadline(self) -> float | None:
        if self.done:
            return None
        if self._out:
            return self._out_t
        if self._await is not None:
            return self._deadline
        return self._wake

    def poll(self, t: float) -> bytes:
        """Bytes to write now (empty if waiting)."""
        if self.done:
            return b""
        if self._out:
            return self.take_pending()
        if self._await is not None:
            if self._deadline is not None and t >= self._deadline:
                self._on_timeout(t)
            if self._out:
                return self.take_pending()
            if self._await is not None:
                return b""
        if t < self._wake:
            return b""
        return self._next(t)

    def receive(self, data: bytes, t: float) -> None:
        if data:
            self._heard = t
        self._buf += data
        while b"\r" in self._buf:
            line, _, self._buf = self._buf.partition(b"\r")
            self._on_line(line, t)

    def interrupt_lines(self) -> list[bytes]:
        """What to send to leave the unit halted and empty after Ctrl-C: H then D."""
        return [self.line(b"H"), self.line(b"D")]

    # ------------------------------------------------------------------ sending
    def _send(self, data: bytes, what: str, t: float, timeout: float | None = None) -> bytes:
        self._await = what
        self._deadline = t + (self.timeout if timeout is None else timeout)
        self._lines = []
        self._sent_line = data
        self.stats.sent += 1
        return data

    def _next(self, t: float) -> bytes:
        ph = self._phase
        if self.interrupted and ph in ("job", "drain"):
            # a stop input or H: no more vectors; wait for the brake, then D (GVE64 §13.5.9)
            ph = self._phase = "stop-wait"
        if ph == "stop-wait":
            return self._send(self.line(b"F"), "stopwait", t)
        if ph == "stop-delete":
            return self._send(self.line(b"D"), "stopdelete", t)
        if ph == "checksum":
            return self._send(self.line(b"%+", checksum=False), "checksum", t)
        if ph == "sync":
            return self._send(self.line(b"@"), "sync", t)
        if ph == "job":
            if self._current is None:
                if not self.units:
                    if not self.finish:
                        self.done = True
                        return b""
                    self._phase = "drain"
                    return self._next(t)
                self._current = self.units.popleft()
            u = self._current
            u.tries += 1
            if u.tries > self.max_tries:
                self._fail(f"gave up on `{u.items[0].body.decode()}` after {self.max_tries} "
                           "tries")
                return b""
            if u.tries > 1:
                self.stats.resent += 1
            # a HALT or W answers only when the motion has stopped
            slow = u.items[0].name in ("H", "W")
            self._repeat_ans = None
            if u.tries == 1:
                self._before = self._sent_line.split(b"\r")[-2] if b"\r" in self._sent_line else b""
            return self._send(self._unit_bytes(u), "unit", t, 60.0 if slow else None)
        if ph == "recover":
            self._phase = "job"
            self.stats.repeats += 1
            return self._send(self.line(b">"), "repeat", t)
        if ph == "recover-index":
            self._phase = "job"
            self.stats.index_checks += 1
            return self._send(self.line(b"@"), "index", t)
        if ph == "drain":
            return self._send(self.line(b"F"), "drain", t)
        if ph == "position":
            cmd = b"P4" if self.variant.has("P4") else b"PF"
            return self._send(self.line(cmd), "position", t)
        return b""

    def _fail(self, why: str) -> None:
        self.failed = why
        self.done = True
        self._await = None

    # ------------------------------------------------------------------ answers
    def _on_line(self, line: bytes, t: float) -> None:
        what = self._await
        if what is None:
            return  # unsolicited: ignore
        if what == "repeat" and line[:1] == b"!":
            self._lines.append(line)  # the echo of the repeated command
            return
        ans = parse_answer(line, self.cs_on or what == "checksum")
        self._await = None
        self.stats.answers += 1
        bad = not isinstance(ans, Answer) or ans.checksum_ok is False
        if bad:
            self.stats.garbled += 1
        elif ans.inta and what not in ("stopwait", "stopdelete"):  # type: ignore[union-attr]
            self.interrupted = True
        handler = getattr(self, "_after_" + what)
        handler(ans if not bad else None, t)

    def _on_timeout(self, t: float) -> None:
        what = self._await
        self._await = None
        self.stats.timeouts += 1
        if t - self._heard >= self.give_up:
            self._fail(f"no answer from the unit for {t - self._heard:.1f} s (is it connected, "
                       "powered and at this baud?)")
            return
        handler = getattr(self, "_after_" + str(what))
        handler(None, t, timed_out=True)

    def _ok_index(self, ans: Answer | None, counted: int = 1) -> None:
        if self.index is not None and ans is not None and ans.code != 2 and not (
                self.cs_on and ans.code == 4):
            self.index = (self.index + counted) & 0xFF

    def _after_checksum(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        if ans is not None and ans.code == 4 and ans.checksum_ok:
            ans = Answer(0, ans.inta, (), ans.checksum, True, ans.raw)  # already on: the 4 came summed
        if ans is None or ans.code != 0:
            self._wake = t + self.queue_wait
            return  # send %+ again
        self.cs_on = True
        self._phase = "sync" if self.policy == "careful" else "job"

    def _after_sync(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        if ans is None or not ans.fields:
            self._wake = t
            return
        try:
            self.index = int(ans.fields[0])
        except ValueError:
            self.index = None
        self._phase = "job"

    def _after_unit(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        u = self._current
        assert u is not None
        if ans is not None:
            self._resolve(u, ans, t)
            return
        pol = self.policy
        if pol == "careful":
            self._recover(t, "recover")
            return
        if pol == "blind" or (pol == "careless" and not timed_out):
            self._wake = t  # same unit again
            return
        self._done_unit(t, acked=False)  # move on

    def _pending_send(self, data: bytes) -> None:
        self._out = data
        self._out_t = (self._deadline or 0.0) - self.timeout

    def _resolve(self, u: Unit_, ans: Answer, t: float) -> None:
        counted = 1
        if u.packet:
            counted = 2 + (int(ans.fields[0]) if ans.fields and ans.fields[0].isdigit() else 0)
        self._ok_index(ans, counted)
        if ans.code == 0:
            self._done_unit(t, acked=True)
            return
        if ans.code == 1 and u.motion:
            self.stats.queue_full += 1
            if u.packet and ans.fields and ans.fields[0].isdigit():
                taken = int(ans.fields[0])
                self.stats.acknowledged += taken
                u.items = u.items[taken:]
                if not u.items:
                    self._done_unit(t)
                    return
            careful = self.policy == "careful"
            self._wake = t + (self.queue_wait if careful else 0.0)
            return
        if ans.code in (2, 3, 4, 5) and u.refused < 5:
            # the job line is valid by the tables, so a refusal means it was damaged on the
            # way (or cut off): certainly not taken, so sending it again is safe
            u.refused += 1
            self._wake = t
            return
        if ans.code == 7:
            self._wake = t + self.queue_wait
            return
        name = u.items[0].body.decode()
        self.stats.errors.append(f"`{name}` answered {ans.raw.decode('ascii', 'replace')}")
        if u.motion:
            self._fail(f"`{name}` refused with error {ans.code}")
            return
        self._done_unit(t, acked=False)

    def _done_unit(self, t: float, acked: bool | None = None) -> None:
        u = self._current
        if u is not None and acked is not None:
            if acked:
                self.stats.acknowledged += len(u.items)
            else:
                self.stats.unacknowledged += len(u.items)
        self._current = None
        self._recoveries = 0
        self._wake = t

    def _last_line(self, u: Unit_) -> bytes:
        return self._unit_bytes(u).split(b"\r")[-2]

    def _recover(self, t: float, phase: str) -> None:
        """Ask ``>`` (or ``@``) after a settle time in which stale bytes are ignored."""
        self._recoveries += 1
        if self._recoveries > 50:
            self._fail("no clean answer to `>`/`@` after 50 tries")
            return
        self._phase = phase
        self._wake = t + min(self.timeout, 0.05)

    def _after_repeat(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        u = self._current
        assert u is not None
        echo = self._lines[-1] if self._lines else None
        if ans is None or (echo is None and self.repeat_echo) or (
                echo is not None and self.cs_on and not verify(echo)):
            self._recover(t, "recover")  # the answer, the echo or our `>` was damaged: ask again
            return
        ours = self._last_line(u)
        if echo is not None and ours != self._before:
            if echo == ours:
                self._resolve(u, ans, t)
                return
            if echo == self._before:
                self._wake = t  # the unit's last line is the one before ours: ours never arrived
                return
        # the echo is our text but so was the line before: once the index shows that ours
        # arrived, ours is the last line and the repeated answer is its answer
        self._repeat_ans = ans if (not self.repeat_echo or echo == ours) else None
        self._recover(t, "recover-index")

    def _after_index(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        u = self._current
        assert u is not None
        if ans is None or not ans.fields:
            self._recover(t, "recover-index")
            return
        field = ans.fields[0]
        try:
            now = int(field, 16) if len(field) == 2 and not field.isdigit() else int(field)
        except ValueError:
            self._recover(t, "recover-index")
            return
        if self.index is None:
            self._fail("cannot tell whether the line arrived: the index was never read")
            return
        counted = 1
        if u.packet:
            counted = 2 + (int(self._repeat_ans.fields[0]) if self._repeat_ans is not None
                           and self._repeat_ans.fields and self._repeat_ans.fields[0].isdigit() else 0)
        if now == self.index:
            self._wake = t  # our line never arrived: send it again
            return
        if now == (self.index + counted) & 0xFF and self._repeat_ans is not None:
            self._resolve(u, self._repeat_ans, t)
            return
        name = u.items[0].body.decode()
        if now == (self.index + counted) & 0xFF:
            self._fail(f"`{name}` arrived (index {now}) but its answer cannot be read back: "
                       "stopping rather than risk a double or lost move")
        else:
            self._fail(f"index {now} is neither {self.index} (`{name}` not arrived) nor "
                       f"{(self.index + counted) & 0xFF} (arrived): cannot tell, stopping")

    def _after_stopwait(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        braking = True
        if ans is not None and ans.fields:
            try:
                braking = bool(int(ans.fields[0], 16) & STOP_BIT)
            except ValueError:
                braking = True
        if braking:
            self._wake = t + min(self.poll_interval, 0.05)
            return
        self._phase = "stop-delete"
        self._wake = t

    def _after_stopdelete(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        if ans is None or ans.code == 7:  # lost, or still running: ask again
            self._wake = t + self.queue_wait
            return
        done, total = self.progress
        if ans.code == 0:
            self._fail(f"stopped by the unit (INTA: a stop input or H) after {done} of {total} "
                       "job lines; the rest of its queue was deleted with D, the position kept")
        else:
            self._fail(f"stopped by the unit (INTA) after {done} of {total} job lines; D was "
                       f"answered {ans.raw.decode('ascii', 'replace')}: the queue may remain")

    def _after_drain(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        busy = True
        if ans is not None and ans.fields:
            try:
                busy = bool(int(ans.fields[0], 16) & RUN_BIT)
            except ValueError:
                busy = True
            self._ok_index(ans)
        if busy:
            self._wake = t + self.poll_interval
            return
        self._phase = "position"
        self._wake = t

    def _after_position(self, ans: Answer | None, t: float, timed_out: bool = False) -> None:
        if ans is not None:
            self._ok_index(ans)
            self._stable.append(ans.fields)
        if len(self._stable) >= 2 and self._stable[-1] == self._stable[-2]:
            try:
                self.last_position = tuple(int(x) for x in self._stable[-1])
            except ValueError:
                self.last_position = None
            self.done = True
            return
        if len(self._stable) > 20:
            self.done = True
            return
        self._wake = t + self.poll_interval

    # ``_send`` from a handler: the bytes go out on the next poll
    def take_pending(self) -> bytes:
        out, self._out = self._out, b""
        return out
