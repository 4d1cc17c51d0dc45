"""Reference streaming senders for grbl, run against the reference unit in virtual time.

Three policies as senders use them (grbl's doc/script/stream.py shows the first two):
``send-response`` waits for each line's ok/error; ``counting`` keeps the bytes of unanswered
lines within the receive buffer; ``unbounded`` does not wait at all. ``poll`` adds a '?' every
so often (realtime, outside the count); ``extra`` inserts lines the sender forgets to count
(as a polling thread sending ``$G`` does). The result is the timed traffic both ways, ready
for :func:`conform.families.grbl.analysis.analyze.analyze_streams` or a capture Recorder.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

from conform.families.grbl.protocol.codec import split_unit


@dataclass
class Traffic:
    host: list[tuple[float, bytes]] = field(default_factory=list)
    unit: list[tuple[float, bytes]] = field(default_factory=list)
    answers: list[str] = field(default_factory=list)
    end: float = 0.0


def stream(unit: Any, lines: list[str], *, method: str = "counting", rx_buffer: int = 128,
           baud: int = 115200, poll: float | None = None, extra: dict[int, str] | None = None,
           t0: float = 0.0, timeout: float = 600.0) -> Traffic:
    """Send ``lines`` to ``unit`` with a streaming policy; returns the traffic both ways."""
    if method not in ("counting", "send-response", "unbounded"):
        raise ValueError(f"unknown streaming method {method!r}")
    byte_time = 10.0 / baud
    out = Traffic()
    t = t0
    counted: deque[int] = deque()         # sizes of lines sent and not answered
    uncounted = 0                         # answers owed to lines sent outside the count
    buf = b""
    i = 0
    next_poll = t0 if poll else None
    extra = dict(extra or {})
    owed = 0

    def write(data: bytes) -> None:
        nonlocal t
        t += len(data) * byte_time
        unit.receive(data, t)
        out.host.append((t, data))

    while (i < len(lines) or owed) and t - t0 < timeout:
        if next_poll is not None and t >= next_poll:
            write(b"?")
            next_poll += poll
        if i in extra:
            write((extra.pop(i) + "\n").encode())
            uncounted += 1
            owed += 1
        if i < len(lines):
            data = (lines[i] + "\n").encode()
            room = (method == "unbounded" or
                    (method == "send-response" and not counted) or
                    (method == "counting" and sum(counted) + len(data) <= rx_buffer))
            if room:
                write(data)
                counted.append(len(data))
                owed += 1
                i += 1
                continue
        # wait for something from the unit
        nd = unit.next_deadline()
        step = 0.001 if nd is None else max(nd - t, 0.0)
        if next_poll is not None:
            step = min(step, max(next_poll - t, 0.0))
        t += max(step, 1e-6)
        for due, data in unit.poll(t):
            out.unit.append((due, data))
            buf += data
        got, buf = split_unit(buf)
        for g in got:
            if g.kind in ("ok", "error"):
                out.answers.append(g.text)
                owed -= 1
                if uncounted:
                    uncounted -= 1   # the sender takes it for one of its counted lines
                if counted:
                    counted.popleft()
    out.end = t
    for due, data in unit.poll(t + 0.05):
        out.unit.append((due, data))
    return out
