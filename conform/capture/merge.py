"""Merge two independently read directions into one causal timeline (the sniffer's core).

On a Y-cable tap each direction arrives through its own adapter and reader thread, so read
timestamps are skewed by USB latency and thread scheduling: an answer's read may return
before the read of the command it answers. ``Merger`` estimates each chunk's first-byte
time (``t_read - len*10/baud``, never before the previous read on that port), holds chunks
for a short window, and emits them ordered by that estimate with two tie-breaks:

* at equal times the host's bytes go first (a command precedes its answer);
* cause and effect: a unit chunk that starts a new answer line while no command is owed an
  answer is moved after the next buffered host chunk that completes a command owed one
  (``HostLines``: every line, unless the protocol family says otherwise, e.g. GVE's
  packets, which owe one answer after their end). If no such host chunk turns up within
  ``hold`` seconds the unit bytes are emitted where their time puts them (unsolicited
  output such as MPG reports).

Sans-I/O: ``push`` and ``tick`` take times and return what is ready; no threads, no clock.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from conform.capture.session import wire_time

_RANK = {"host": 0, "unit": 1}
_TERMINATORS = b"\r\n"


@dataclass
class MergedChunk:
    direction: str
    data: bytes
    t_read: float
    t_first: float  # estimated first-byte time (what the recorder stores)
    t_order: float  # what the merge sorted by (t_first, moved later for causality)
    seq: int
    reordered: bool = False


class HostLines:
    """Counts host lines that are owed an answer: one each, by default. A protocol family
    whose lines owe none or share one gives its own ``owes`` (``Family.host_lines``)."""

    def __init__(self) -> None:
        self.partial = b""

    def copy(self) -> HostLines:
        return copy.copy(self)

    def owes(self, line: bytes) -> int:
        """Answers a complete, non-empty host line (stripped) is owed."""
        return 1

    def feed(self, data: bytes) -> int:
        owed = 0
        buf = self.partial + data
        start = 0
        for i, b in enumerate(buf):
            if b in _TERMINATORS:
                line = buf[start:i].strip()
                start = i + 1
                if line:
                    owed += self.owes(line)
        self.partial = buf[start:][-256:]
        return owed


class UnitLines:
    """Counts complete answer lines and knows whether the next byte starts a new one."""

    def __init__(self) -> None:
        self.at_line_start = True

    def feed(self, data: bytes) -> int:
        answers = 0
        for b in data:
            if b in _TERMINATORS:
                if not self.at_line_start:
                    answers += 1
                self.at_line_start = True
            else:
                self.at_line_start = False
        return answers


class Merger:
    """Two directions in, one causally ordered sequence of chunks out."""

    def __init__(
        self, baud: int | None, *, read_size: int = 256, slack: float = 0.02, hold: float = 0.3,
        host_lines: HostLines | None = None,
    ) -> None:
        self.baud = baud
        self.window = wire_time(read_size, baud) + slack
        self.hold = max(hold, self.window)
        self._pending: list[MergedChunk] = []
        self._last_read = {"host": float("-inf"), "unit": float("-inf")}
        self._seq = 0
        self._host = host_lines if host_lines is not None else HostLines()
        self._unit = UnitLines()
        self._owed = 0
        self.emitted_until = float("-inf")
        self.late = 0  # chunks that arrived after later ones had been emitted

    def push(self, direction: str, data: bytes, t_read: float) -> list[MergedChunk]:
        """A read returned ``data`` at ``t_read``; returns the chunks now safe to emit."""
        if direction not in _RANK:
            raise ValueError(f"direction must be 'host' or 'unit', not {direction!r}")
        if data:
            t_first = t_read - wire_time(len(data), self.baud)
            t_first = max(t_first, min(self._last_read[direction], t_read))
            self._last_read[direction] = max(self._last_read[direction], t_read)
            self._seq += 1
            if t_first < self.emitted_until:
                self.late += 1
            self._pending.append(MergedChunk(direction, data, t_read, t_first, t_first,
                                             self._seq))
        return self.tick(t_read)

    def tick(self, now: float) -> list[MergedChunk]:
        """Emit what no later read can precede any more."""
        return self._drain(now, final=False)

    def flush(self) -> list[MergedChunk]:
        """Emit everything still held (end of capture)."""
        return self._drain(float("inf"), final=True)

    def _sort(self) -> None:
        self._pending.sort(key=lambda c: (c.t_order, _RANK[c.direction], c.seq))

    def _next_command(self) -> MergedChunk | None:
        """The first pending host chunk that completes a command owed an answer."""
        tracker = self._host.copy()
        for c in self._pending:
            if c.direction == "host" and tracker.feed(c.data):
                return c
        return None

    def _drain(self, now: float, final: bool) -> list[MergedChunk]:
        out: list[MergedChunk] = []
        horizon = now - self.window
        while self._pending:
            self._sort()
            head = self._pending[0]
            if not final and head.t_order > horizon:
                break
            if head.direction == "unit" and self._unit.at_line_start and self._owed == 0:
                cmd = self._next_command()
                if cmd is not None:
                    # after the command's last byte; at a tie the host rank sorts it first
                    head.t_order = max(head.t_order, cmd.t_read, cmd.t_order)
                    head.reordered = True
                    continue
                if not final and head.t_read > now - self.hold:
                    break  # its command may still be on its way from the other reader
            self._pending.pop(0)
            if head.direction == "host":
                self._owed += self._host.feed(head.data)
            else:
                self._owed = max(0, self._owed - self._unit.feed(head.data))
            self.emitted_until = max(self.emitted_until, head.t_order)
            out.append(head)
        return out
