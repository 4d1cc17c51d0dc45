"""grbl's live monitor for ``conform proxy --live``: lines and their ok/error:N in order, the
bytes of the unanswered lines against the receive buffer (what a character-counting sender
must keep within it, interface.md §Streaming), ALARM and Hold as events.

Realtime bytes (``?``, ``!``, ``~``, Ctrl-X, 0x80+) are taken out of band by grbl and never
answered; they are removed before the lines are counted (``bytes.translate``, at C speed).
"""

from __future__ import annotations

from collections import deque
from typing import Any

from conform.diagnosis.live import LiveState
from conform.families.grbl.analysis.analyze import DEFAULT_VARIANT
from conform.families.grbl.spec.load import load_grbl


class GrblLive:
    def __init__(self, variant: str | None) -> None:
        spec = load_grbl()
        vid = variant if variant in spec.variants else DEFAULT_VARIANT
        v = spec.variant(vid)
        self.state = LiveState(in_flight_bytes=0, rx_capacity=v.rx_buffer)
        self._realtime = bytes(b for b in spec.realtime if b <= 0x7F) + bytes(range(0x80, 256))
        self._sizes: deque[tuple[int, float]] = deque()
        self._line = 0            # bytes of the host line begun
        self._unit = b""

    def feed(self, direction: str, data: bytes, t: float) -> None:
        s = self.state
        if direction == "host":
            data = data.translate(None, self._realtime).replace(b"\r", b"\n")
            parts = data.split(b"\n")
            for part in parts[:-1]:
                size = self._line + len(part) + 1
                self._line = 0
                self._sizes.append((size, t))
                s.in_flight_bytes = (s.in_flight_bytes or 0) + size
                s.lines += 1
                s.waiting += 1
                s.t_line = t
            self._line += len(parts[-1])
            return
        lines = (self._unit + data).split(b"\n")
        self._unit = lines.pop()
        for raw in lines:
            self._answer(raw.rstrip(b"\r"), t, s)

    def _answer(self, line: bytes, t: float, s: LiveState) -> None:
        if line == b"ok" or line.startswith(b"error:"):
            s.answers += 1
            s.t_answer = t
            if self._sizes:
                size, t_sent = self._sizes.popleft()
                s.in_flight_bytes = max(0, (s.in_flight_bytes or 0) - size)
                s.waiting = max(0, s.waiting - 1)
                s.latency_s = t - t_sent
                s.latency_max_s = max(s.latency_max_s, s.latency_s)
            if line != b"ok":
                s.errors += 1
                s.events.append(line.decode("latin-1"))
        elif line.startswith(b"ALARM:"):
            s.events.append(line.decode("latin-1"))
        elif line.startswith((b"<Hold", b"<Door")) and s.waiting:
            text = line.decode("latin-1").split("|")[0] + ">"
            if not s.events or s.events[-1] != text:
                s.events.append(text)
        elif line.startswith(b"Grbl "):
            s.events.append("reset: " + line.decode("latin-1"))
            self._sizes.clear()
            s.waiting, s.in_flight_bytes = 0, 0


def live_monitor(variant: str | None) -> Any:
    return GrblLive(variant)
