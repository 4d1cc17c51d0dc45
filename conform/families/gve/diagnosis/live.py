"""GVE's live monitor for ``conform proxy --live``: commands (lines ending in the A1
terminator) and their answers in order, strictly simplex (GVE64 §13.3), the answer digit's
error code (§13.7; 1 on a vector is a full queue, not a refusal) and INTA (bit 3) as events.

It keeps up with 921 600 Bd in a few per cent of a core: lines are counted per read with
``bytes.count``, a read of nothing but ``0`` answers is taken whole, and only other answers
are looked at one by one.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from conform.diagnosis.live import LiveState

HEX = b"0123456789ABCDEF"


class GveLive:
    def __init__(self, variant: str | None) -> None:
        self.state = LiveState()
        self._reads: deque[tuple[int, float]] = deque()   # (lines sent up to it, its time)
        self._unit = b""
        self._inta = False

    def feed(self, direction: str, data: bytes, t: float) -> None:
        s = self.state
        if direction == "host":
            n = data.count(b"\r")
            if n:
                s.lines += n
                s.waiting += n
                s.t_line = t
                self._reads.append((s.lines, t))
            return
        buf = self._unit + data
        cut = buf.rfind(b"\r") + 1
        whole, self._unit = buf[:cut], buf[cut:]
        if not whole:
            return
        k = len(whole) // 2
        if whole == b"0\r" * k:                 # the usual read: OK answers only
            self._answered(k, t, s)
            self._inta = False
            return
        for line in whole[:-1].split(b"\r"):
            line = line.lstrip(b"\n")
            if not line or line[:1] == b"!" or line[0] not in HEX:
                continue        # an echo of `>`, or noise
            digit = HEX.index(line[0])
            self._answered(1, t, s)
            code = digit & 7
            if code not in (0, 1):
                s.errors += 1
                s.events.append(f"error {code}: `{line.decode('latin-1')}`")
            inta = bool(digit & 8)
            if inta and not self._inta:
                s.events.append("INTA: an interrupt braked the motion (alarm)")
            self._inta = inta

    def _answered(self, n: int, t: float, s: LiveState) -> None:
        s.answers += n
        s.t_answer = t
        s.waiting = max(0, s.waiting - n)
        reads = self._reads
        while len(reads) > 1 and reads[0][0] < s.answers:
            reads.popleft()            # the read holding the line just answered is first
        if reads and reads[0][0] >= s.answers:
            s.latency_s = t - reads[0][1]
            s.latency_max_s = max(s.latency_max_s, s.latency_s)


def live_monitor(variant: str | None) -> Any:
    return GveLive(variant)
