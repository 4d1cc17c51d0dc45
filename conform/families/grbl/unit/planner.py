"""Motion of the reference grbl unit in virtual time: a block queue with trapezoid profiles.

A deliberately simple model of grbl's planner (gnea/grbl grbl/planner.c), documented in
docs/grbl.md: every block is a straight move of ``length`` mm at a nominal rate (the programmed
feed, or the slowest axis' maximum rate for rapids and jogs, $110–$112) with the acceleration
the axes allow along its direction ($120–$122, mm/s²). The junction speed between two blocks
follows grbl's junction-deviation rule ($11); a block's profile is fixed when it starts, with
an exit speed from a backward pass over the blocks queued at that moment (so the machine can
always stop at the end of what it knows). Feed hold decelerates within the running block.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

TIMING_TOLERANCE = 0.1
"""Seconds by which this model's timeline of a move may lead or lag the firmware's (its
trapezoids against grbl's segment generator, and the moment a status report is taken): a
position reported while moving is right within the distance covered at the reported feed in
that time, the feed within what the axes' acceleration changes in it."""


@dataclass
class Move:
    """One planner block."""

    start: list[float]
    end: list[float]
    rate: float            # nominal, mm/s
    accel: float           # mm/s² along the path
    length: float
    unit: list[float]
    kind: str = "line"     # line | jog | probe | dwell | pause | end | marker
    tag: object = None     # what to do when the block completes (probe, program end ...)
    dwell: float = 0.0
    # profile, set when the block starts
    t0: float = 0.0
    v0: float = 0.0
    v1: float = 0.0
    vp: float = 0.0
    ta: float = 0.0
    tc: float = 0.0
    td: float = 0.0
    s_done: float = 0.0    # distance already covered before the current profile

    @property
    def duration(self) -> float:
        return self.ta + self.tc + self.td

    def profile(self, t0: float, v0: float, v1: float, remaining: float | None = None) -> None:
        """Trapezoid (or triangle) over the remaining length from speed v0 to v1."""
        L = self.length - self.s_done if remaining is None else remaining
        a, v = max(self.accel, 1e-9), self.rate
        v0 = min(v0, v)
        v1 = min(v1, math.sqrt(v0 * v0 + 2 * a * L), v)
        peak = math.sqrt(max(0.0, (2 * a * L + v0 * v0 + v1 * v1) / 2))
        vp = min(v, peak)
        da = (vp * vp - v0 * v0) / (2 * a)
        dd = (vp * vp - v1 * v1) / (2 * a)
        cruise = max(0.0, L - da - dd)
        self.t0, self.v0, self.v1, self.vp = t0, v0, v1, vp
        self.ta = (vp - v0) / a
        self.td = (vp - v1) / a
        self.tc = cruise / vp if vp > 0 else 0.0

    def at(self, t: float) -> tuple[float, float]:
        """(distance along the block, speed) at time t."""
        a = max(self.accel, 1e-9)
        tau = min(max(0.0, t - self.t0), self.duration)
        s = self.s_done
        if tau <= self.ta:
            return s + self.v0 * tau + a * tau * tau / 2, self.v0 + a * tau
        s += self.v0 * self.ta + a * self.ta ** 2 / 2
        tau -= self.ta
        if tau <= self.tc:
            return s + self.vp * tau, self.vp
        s += self.vp * self.tc
        tau -= self.tc
        return s + self.vp * tau - a * tau * tau / 2, self.vp - a * tau

    def point(self, s: float) -> list[float]:
        return [p + u * s for p, u in zip(self.start, self.unit, strict=True)]


@dataclass
class Planner:
    """The block queue and the block being executed."""

    size: int
    axis_rate: list[float]      # mm/s
    axis_accel: list[float]     # mm/s²
    junction_deviation: float
    blocks: deque[Move] = field(default_factory=deque)
    running: bool = False       # the head block has a profile and is moving
    holding: bool = False
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # planned end

    @property
    def free(self) -> int:
        return self.size - len(self.blocks)

    @property
    def full(self) -> bool:
        return len(self.blocks) >= self.size

    def make(self, start: list[float], end: list[float], rate: float | None, kind: str,
             tag: object = None) -> Move | None:
        """A block from start to end at ``rate`` mm/s (None: the axes' maximum, a rapid)."""
        delta = [e - s for s, e in zip(start, end, strict=True)]
        length = math.sqrt(sum(d * d for d in delta))
        if length < 1e-9:
            return None
        unit = [d / length for d in delta]
        limit_rate = min(r / abs(u) for r, u in zip(self.axis_rate, unit, strict=True) if u)
        limit_acc = min(a / abs(u) for a, u in zip(self.axis_accel, unit, strict=True) if u)
        v = limit_rate if rate is None else min(rate, limit_rate)
        return Move(list(start), list(end), max(v, 1e-6), limit_acc, length, unit, kind, tag)

    def push(self, move: Move) -> None:
        self.blocks.append(move)
        if move.kind not in ("dwell", "pause", "end", "marker"):
            self.position = list(move.end)

    def junction(self, a: Move, b: Move) -> float:
        """Maximum speed through the corner between a and b (grbl's junction deviation)."""
        if a.kind not in ("line", "jog", "probe") or b.kind not in ("line", "jog", "probe"):
            return 0.0
        cos_theta = -sum(x * y for x, y in zip(a.unit, b.unit, strict=True))
        if cos_theta > 0.999999:
            return 0.0
        if cos_theta < -0.999999:
            return min(a.rate, b.rate)
        sin_half = math.sqrt(max(0.0, 0.5 * (1.0 - cos_theta)))
        v2 = min(a.accel, b.accel) * self.junction_deviation * sin_half / (1.0 - sin_half)
        return min(math.sqrt(v2), a.rate, b.rate)

    def exit_speed(self) -> float:
        """Highest exit speed of the head block from which everything queued can still stop."""
        blocks = list(self.blocks)
        v = 0.0
        for i in range(len(blocks) - 1, 0, -1):
            b = blocks[i]
            if b.kind not in ("line", "jog", "probe"):
                v = 0.0
                continue
            v_entry = math.sqrt(v * v + 2 * b.accel * b.length)
            v = min(v_entry, self.junction(blocks[i - 1], b))
        return v

    def start_head(self, t: float, v0: float) -> None:
        head = self.blocks[0]
        head.profile(t, v0, self.exit_speed())
        self.running = True

    def hold(self, t: float) -> float:
        """Decelerate the running block to a stop; returns when it stands still."""
        if not self.blocks or not self.running:
            return t
        head = self.blocks[0]
        s, v = head.at(t)
        a = max(head.accel, 1e-9)
        stop = min(v * v / (2 * a), head.length - s)
        head.s_done = s
        head.t0, head.v0, head.vp = t, v, v
        head.ta = head.tc = 0.0
        head.td = v / a if stop >= v * v / (2 * a) - 1e-12 else (
            (v - math.sqrt(max(0.0, v * v - 2 * a * stop))) / a)
        head.v1 = v - a * head.td
        self.holding = True
        return t + head.td

    def resume(self, t: float) -> None:
        """Start again from where the held block stands."""
        self.holding = False
        if self.blocks:
            head = self.blocks[0]
            if self.running:
                head.s_done = head.at(t)[0]
            head.profile(t, 0.0, self.exit_speed())
            self.running = True

    def stopped(self, t: float) -> bool:
        """The hold's deceleration ended at t: keep the block, standing at its stop point.
        Returns False when the block was in fact finished (the stop fell at its end)."""
        head = self.blocks[0]
        s = head.at(t)[0]
        self.running = False
        if s >= head.length - 1e-9:
            return False
        head.s_done = s
        return True

    def where(self, t: float) -> tuple[list[float], float]:
        """Machine position and speed (mm/s) at t."""
        if self.blocks and not self.running:
            head = self.blocks[0]
            return head.point(head.s_done), 0.0
        if not self.blocks:
            return list(self.position), 0.0
        head = self.blocks[0]
        s, v = head.at(t)
        return head.point(min(s, head.length)), max(0.0, v)

    def clear(self, position: list[float]) -> None:
        self.blocks.clear()
        self.running = self.holding = False
        self.position = list(position)
