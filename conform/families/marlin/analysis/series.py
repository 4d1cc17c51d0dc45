"""What the Marlin report plots, gathered as the capture streams in memory that does not grow
with the session: each series keeps at most ``KEEP`` points (past that, every other point is
dropped and the stride doubles, so a long session keeps an even sample of the whole)."""

from __future__ import annotations

from dataclasses import dataclass, field

KEEP = 20_000


@dataclass
class Series:
    """Points (t, y): t in seconds from the session's start."""

    t: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    stride: int = 1
    seen: int = 0

    def add(self, t: float, y: float) -> None:
        self.seen += 1
        if (self.seen - 1) % self.stride:
            return
        self.t.append(t)
        self.y.append(y)
        if len(self.t) >= KEEP:
            self.t, self.y = self.t[::2], self.y[::2]
            self.stride *= 2


@dataclass
class Plotted:
    """The session over time: ok latency per answered line, Resend: requests (the number asked
    for), lines in flight when each host line was sent, busy periods (start, end)."""

    latency: Series = field(default_factory=Series)        # (t sent, ms to its ok)
    resends: Series = field(default_factory=Series)        # (t, line number asked for)
    errors: Series = field(default_factory=Series)         # (t, 0 checksum / 1 number / 2 none)
    in_flight: Series = field(default_factory=Series)      # (t, lines sent, not yet answered)
    busy: list[tuple[float, float]] = field(default_factory=list)
    busy_dropped: int = 0

    def busy_period(self, start: float, end: float) -> None:
        if len(self.busy) < KEEP:
            self.busy.append((start, end))
        else:
            self.busy_dropped += 1
