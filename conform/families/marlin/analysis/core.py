"""The Marlin analysis as one pass over both directions in time order, in bounded memory.

What it holds: counters; the ok latencies in a ``summaries.Quantiles`` (exact up to
``summaries.EXACT_VALUES`` answered lines, within 0.1 % beyond); the open window of lines
whose fate is not known yet (taken but not answered); the resend requests of the storm
being gathered; the findings, ``MAX_KEPT`` of each group listed and the rest counted; and,
for lines run twice and never, the first acceptance of each (line number, text), kept as a
64-bit hash of the text, its time, numbering and whether its ok came: 21 bytes per line
number in a temporary file read through a few cached blocks (:class:`Seen`), so the memory
stays flat; the disk it takes grows with the highest line number.

A line's fate is settled when its ok comes, when an ``Error:... Last Line:`` says it was
not taken, at a restart, or at the end; it then goes to the lines table (in send order) and
to the ran-twice and never-ran bookkeeping. Taken lines settle in the order they were sent.
"""

from __future__ import annotations

import math
import os
import struct
import tempfile
from bisect import bisect_right
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from conform.analysis.summaries import Quantiles
from conform.families.marlin.analysis.records import CLAUSE_Q, Finding, HostLine
from conform.families.marlin.analysis.series import Plotted

MAX_LISTED = 50
MAX_KEPT = 1000            # findings listed per group; the rest are counted
STORM_WINDOW = 0.5         # s: resend requests this close together belong to one storm
STORM_MIN = 3              # requests that make a storm
RESEND_TIMEOUT = 1.0       # s without an ok before a sender's repeat counts as a timeout resend
MAX_ASKED = 10_000         # distinct numbers counted per storm (min and max stay exact)
GROUPS = ("loop", "storm", "twice", "never", "busy")   # the order findings are listed in
_DENSE = 1 << 31           # line numbers kept in Seen's file; others (rare) in a dict


class Seen:
    """The first acceptance of each (line number, text hash): (t, numbering, answered).

    A fixed-size record per line number in a temporary file, read and written through a
    few cached blocks of ``BLOCK`` records (the numbers a session uses move slowly), so the
    memory it takes does not grow with the capture; a second text under a number already
    kept (rare) goes to a dict."""

    REC = struct.Struct("<qdib")        # text hash, time, numbering + 1 (0: empty), answered
    BLOCK = 1 << 16
    CACHED = 4

    def __init__(self) -> None:
        self.file: Any = None
        self.blocks: dict[int, bytearray] = {}       # in use order, the last used last
        self.dirty: set[int] = set()
        self.top = -1                                 # the highest number kept
        self.last = -1                                # the block used last
        self.other: dict[tuple[int, int], tuple[float, int, bool]] = {}

    def _block(self, b: int) -> bytearray:
        if b == self.last:                # the block in use (nearly always)
            return self.blocks[b]
        buf = self.blocks.pop(b, None)
        if buf is None:
            size = self.BLOCK * self.REC.size
            if self.file is None:
                self.file = tempfile.TemporaryFile(prefix="conform-seen-")
            data = os.pread(self.file.fileno(), size, b * size)
            buf = bytearray(data) + bytearray(size - len(data))
            if len(self.blocks) >= self.CACHED:
                old = next(iter(self.blocks))
                self._write(old, self.blocks.pop(old))
        self.blocks[b] = buf
        self.last = b
        return buf

    def _write(self, b: int, buf: bytearray) -> None:
        if b in self.dirty:
            os.pwrite(self.file.fileno(), buf, b * len(buf))
            self.dirty.discard(b)

    def get(self, n: int, h: int) -> tuple[float, int, bool] | None:
        if 0 <= n <= self.top and n < _DENSE:
            b, i = divmod(n, self.BLOCK)
            kh, t, e, ok = self.REC.unpack_from(self._block(b), i * self.REC.size)
            if e and kh == h:
                return t, e - 1, bool(ok)
        return self.other.get((n, h)) if self.other else None

    def first(self, n: int, h: int, t: float, epoch: int, ok: bool) -> None:
        """Keep (n, h) unless it is kept already."""
        if 0 <= n < _DENSE:
            b, i = divmod(n, self.BLOCK)
            buf = self._block(b)
            kh, _, e, _ = self.REC.unpack_from(buf, i * self.REC.size)
            if not e:
                self.REC.pack_into(buf, i * self.REC.size, h, t, epoch + 1, ok)
                self.dirty.add(b)
                self.top = max(self.top, n)
                return
            if kh == h:
                return
        self.other.setdefault((n, h), (t, epoch, ok))

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None
        self.blocks.clear()
        self.last = -1


@dataclass
class Storm:
    """Resend requests each within STORM_WINDOW of the last, and the lines taken meanwhile."""

    start: float
    end: float
    requests: int = 0
    asked: dict[int, int] = field(default_factory=dict)
    lo: int = 0
    hi: int = 0
    taken: list[float] = field(default_factory=list)   # send times of lines taken since start
    closed: bool = False
    count: int = 0                                      # taken within start..end, once closed

    def ask(self, t: float, n: int) -> None:
        self.end = t
        self.lo = n if not self.requests else min(self.lo, n)
        self.hi = n if not self.requests else max(self.hi, n)
        self.requests += 1
        if n in self.asked or len(self.asked) < MAX_ASKED:
            self.asked[n] = self.asked.get(n, 0) + 1


class Analyser:
    """Feed ``host(line)`` and ``unit(t, text)`` in time order, then ``finish(t_last)``."""

    def __init__(self, t0: float, keepalive: float, planner_blocks: int,
                 on_line: Callable[[HostLine], None] | None = None) -> None:
        self.t0, self.keepalive, self.planner_blocks = t0, keepalive, planner_blocks
        self.on_line = on_line
        self.groups: dict[str, list[Finding]] = {g: [] for g in GROUPS}
        self.counts: dict[str, int] = {}
        self.dropped = 0
        self.last_n = self.epoch = self.sent_max = 0
        self._now = t0
        self.asked: int | None = None
        self.pending: deque[HostLine] = deque()   # taken or unnumbered, waiting for their ok
        self.window: deque[HostLine] = deque()    # sent, not yet handed to on_line
        self.in_error = 0
        self.oks = self.errors_cs = self.errors_ln = self.errors_nocs = 0
        self.host_lines = self.numbered = self.accepted = self.repeats = self.motion = 0
        self.resends = 0
        self.empty = 0
        self.latency = Quantiles()
        self._lat: list[float] = []
        self.busy_periods = 0
        self.busy_s = 0.0
        self.busy_first: float | None = None
        self._busy_start: float | None = None
        self._busy_prev: float | None = None
        self.storm: Storm | None = None
        self.closed: deque[Storm] = deque()
        self.seen = Seen()
        self.prev: HostLine | None = None
        self.twice_c = self.twice_p = 0
        self.never: dict[tuple[int, int], HostLine] = {}
        self.last_taken_t = 0.0
        self.plotted = Plotted()             # what the report draws (analysis/series.py)

    def add(self, group: str, f: Finding) -> None:
        self.counts[f.kind] = self.counts.get(f.kind, 0) + 1
        if len(self.groups[group]) < MAX_KEPT:
            self.groups[group].append(f)
        else:
            self.dropped += 1

    # -- the two directions ----------------------------------------------------------------
    def host(self, x: HostLine) -> None:
        t = x.t
        self._tick(t)
        x.seq = self.host_lines
        self.host_lines += 1
        if self.on_line is not None:
            self.window.append(x)
        x.epoch = self.epoch
        self.plotted.in_flight.add(t - self.t0, len(self.pending) + 1)
        if x.n is None:
            x.accepted = True
            self.pending.append(x)
            return
        self.numbered += 1
        m110_first = x.text.startswith("M110")
        if x.n <= self.sent_max and not m110_first:
            x.repeat = True
            self.repeats += 1
            if self.asked is None or x.n < self.asked:
                self.add("loop", Finding("repeat-unasked", t - self.t0, "warning",
                                         f"N{x.n} sent again without a Resend: asking for it "
                                         "(the unit ignores the last two numbers silently)",
                                         CLAUSE_Q))
        elif x.n > self.sent_max + 1 and self.sent_max and not m110_first:
            self.add("loop", Finding("number-gap", t - self.t0, "error",
                                     f"N{x.n} sent after N{self.sent_max}: numbers skipped",
                                     CLAUSE_Q))
        self.sent_max = max(self.sent_max, x.n) if not m110_first else x.n
        m110 = m110_first or " M110" in x.text
        if (x.n == self.last_n + 1 or m110) and x.checksum_ok:
            self.last_n = x.n
            x.accepted = True
            self.pending.append(x)
            if m110:
                self.epoch += 1
        else:
            self._settle(x)

    def unit(self, t: float, line: str) -> None:
        self._tick(t)
        self._now = t
        if line.startswith("ok"):
            self.oks += 1
            if self.in_error:
                self.in_error -= 1
                return
            if " P" in line and " B" in line:
                try:
                    self.empty += int(line.split(" P", 1)[1].split()[0]) >= self.planner_blocks
                except ValueError:
                    pass
            if self.pending:
                x = self.pending.popleft()
                x.t_ok = t
                self._lat.append(t - x.t)
                self.plotted.latency.add(x.t - self.t0, (t - x.t) * 1000.0)
                if len(self._lat) >= 65536:
                    self._flush_latency()
                self._settle(x)
        elif line.startswith("Error:"):
            if "Last Line:" in line:
                self._error(line)
            elif "halted" in line:
                self.add("loop", Finding("halted", t - self.t0, "error", "the unit halted (M112 "
                                         "or kill()): it answers nothing until reset",
                                         "MarlinCore.cpp kill()"))
        elif line.startswith("Resend:"):
            try:
                asked = int(line.split(":", 1)[1])
            except ValueError:
                return
            self.asked = asked
            self.resends += 1
            self.plotted.resends.add(t - self.t0, asked)
            if self.storm is None:
                self.storm = Storm(t, t)
            self.storm.ask(t, asked)
        elif line.startswith("echo:busy:"):
            self._busy(t)
        elif line == "start":
            self.epoch += 1
            self.last_n = self.sent_max = 0
            self.asked = None
            while self.pending:
                self._settle(self.pending.popleft())
            if self.host_lines:     # the boot at a capture's start, before the host wrote: no loss
                self.add("loop", Finding("reset", t - self.t0, "warning", "the unit restarted "
                                         "(start): line numbers begin again at 1, queued lines "
                                         "are lost", "MarlinCore.cpp setup()"))
        self._judge_storms()

    def _error(self, line: str) -> None:
        try:
            last = int(line.rsplit("Last Line:", 1)[1])
        except ValueError:
            return
        self.plotted.errors.add(self._now - self.t0, 0 if "checksum" in line else
                                1 if "Line Number" in line else 2)
        if "checksum" in line:
            self.errors_cs += 1
        elif "Line Number" in line:
            self.errors_ln += 1
        else:
            self.errors_nocs += 1
        keep: deque[HostLine] = deque()
        for x in self.pending:
            if x.n is not None and x.n > last and x.t_ok is None:
                x.accepted = False
                self._settle(x)
            else:
                keep.append(x)
        self.pending = keep
        self.last_n = last
        self.in_error += 1

    def _busy(self, t: float) -> None:
        if self.busy_first is None:
            self.busy_first = t
        prev = self._busy_prev
        if prev is None or t - prev > self.keepalive * 1.5:
            if self._busy_start is not None and prev is not None:
                self.busy_s += prev - self._busy_start + self.keepalive
                self.plotted.busy_period(self._busy_start - self.keepalive - self.t0,
                                         prev - self.t0)
            self.busy_periods += 1
            self._busy_start = t
        self._busy_prev = t

    # -- a line's fate ---------------------------------------------------------------------
    def _settle(self, x: HostLine) -> None:
        x.done = True
        if x.accepted:
            self.accepted += 1
            self.last_taken_t = max(self.last_taken_t, x.t)
            self.motion += x.text[:2] in ("G0", "G1", "G2", "G3")
            if x.n is not None:
                self._taken(x)
        elif x.n is not None and not x.text.startswith("M110"):
            key = (x.n, hash(x.text))
            if self.seen.get(*key) is None:
                other = self.never.get(key)
                if other is None or other.seq > x.seq:
                    self.never[key] = x
        while self.window and self.window[0].done:
            self.on_line(self.window.popleft())  # type: ignore[misc]  # (window only with it)

    def _taken(self, x: HostLine) -> None:
        """A numbered line taken: lines run twice (as ``_twice`` judged them over the whole
        capture), the never-ran candidates it answers, the storms it counts in."""
        assert x.n is not None
        h = hash(x.text)
        self.never.pop((x.n, h), None)
        first = self.seen.get(x.n, h)
        prev = self.prev
        if first is not None and first[1] != x.epoch and not x.text.startswith("M110"):
            sure = first[2]
            self.twice_c += sure
            self.twice_p += not sure
            self.add("twice", Finding(
                "ran-twice", x.t - self.t0, "hazard" if sure else "warning",
                f"N{x.n} {x.text!r} ran {'twice' if sure else 'possibly twice'} (taken at "
                f"{first[0] - self.t0:.3f} s{', answered ok' if sure else ', its ok never came'}"
                ", again after the numbering began anew)", CLAUSE_Q,
                {"n": x.n, "confirmed": sure}))
        elif (prev is not None and prev.text == x.text and prev.n is not None
              and x.n == prev.n + 1 and (prev.t_ok is None or prev.t_ok > x.t)
              and x.t - prev.t >= RESEND_TIMEOUT):
            self.twice_p += 1
            self.add("twice", Finding("ran-twice", x.t - self.t0, "warning",
                                      f"N{x.n} repeats N{prev.n}'s {x.text!r} after "
                                      f"{x.t - prev.t:.1f} s without an ok: possibly run twice",
                                      CLAUSE_Q, {"n": x.n, "confirmed": False}))
        self.seen.first(x.n, h, x.t, x.epoch, x.t_ok is not None)
        self.prev = x
        for s in self.closed:
            s.count += s.start <= x.t <= s.end
        if self.storm is not None and x.t >= self.storm.start:
            self.storm.taken.append(x.t)

    # -- storms ----------------------------------------------------------------------------
    def _tick(self, t: float) -> None:
        """Close the storm no later request can join."""
        s = self.storm
        if s is not None and t - s.end > STORM_WINDOW:
            s.count += bisect_right(s.taken, s.end)
            s.taken = []
            s.closed = True
            self.closed.append(s)
            self.storm = None

    def _judge_storms(self, final: bool = False) -> None:
        """A closed storm is judged once every line sent before its last request is settled:
        fewer lines taken than requests made is a storm (the link makes no progress)."""
        while self.closed and (final or not self.pending or self.pending[0].t > self.closed[0].end):
            s = self.closed.popleft()
            if s.requests >= STORM_MIN and s.count < s.requests:
                most = max(set(list(s.asked)), key=s.asked.__getitem__)
                self.add("storm", Finding(
                    "resend-storm", s.start - self.t0, "error",
                    f"{s.requests} Resend: requests in {s.end - s.start:.2f} s (asked for "
                    f"N{s.lo}..N{s.hi}, most N{most})", CLAUSE_Q,
                    {"start": s.start - self.t0, "end": s.end - self.t0, "requests": s.requests,
                     "asked": sorted(s.asked)[:MAX_LISTED]}))

    # -- the end ---------------------------------------------------------------------------
    def _flush_latency(self) -> None:
        if self._lat:
            self.latency.add(np.array(self._lat))
            self._lat = []

    def finish(self, t_last: float) -> tuple[list[Finding], dict[str, Any]]:
        self._tick(math.inf)
        while self.pending:
            self._settle(self.pending.popleft())
        self._judge_storms(final=True)
        never_c = never_p = 0
        for x in sorted(self.never.values(), key=lambda y: y.seq):
            sure = x.t < self.last_taken_t
            never_c += sure
            never_p += not sure
            self.add("never", Finding("never-ran", x.t - self.t0, "hazard" if sure else "warning",
                                      f"N{x.n} {x.text!r} was sent but never taken"
                                      + ("" if sure else " (the capture ends first)"), CLAUSE_Q,
                                      {"n": x.n, "confirmed": sure}))
        if self._busy_start is not None and self._busy_prev is not None:
            self.busy_s += self._busy_prev - self._busy_start + self.keepalive
            self.plotted.busy_period(self._busy_start - self.keepalive - self.t0,
                                     self._busy_prev - self.t0)
        if self.busy_periods and self.busy_first is not None:
            self.add("busy", Finding("busy", self.busy_first - self.t0, "info",
                                     f"{self.busy_periods} busy periods, {self.busy_s:.1f} s in "
                                     "all", "gcode.cpp host_keepalive"))
        self._flush_latency()
        self.seen.close()
        p50, p95, p99, top = (round(v * 1000.0, 3) if self.latency.n else None
                              for v in self.latency.nearest([0.5, 0.95, 0.99, 1.0]))
        duration = t_last - self.t0
        n = self.numbered
        metrics = {
            "host_lines": self.host_lines, "numbered": n, "accepted": self.accepted,
            "oks": self.oks, "duration_s": round(duration, 6),
            "lines_per_s": round(self.host_lines / duration, 3) if duration > 0 else 0.0,
            "ok_p50_ms": p50, "ok_p95_ms": p95, "ok_p99_ms": p99, "ok_max_ms": top,
            "resends": self.resends, "resend_ratio": round(self.resends / n, 6) if n else 0.0,
            "storms": self.counts.get("resend-storm", 0), "checksum_errors": self.errors_cs,
            "line_number_errors": self.errors_ln, "no_checksum_errors": self.errors_nocs,
            "busy_periods": self.busy_periods, "busy_s": round(self.busy_s, 3),
            "planner_empty": self.empty, "twice_confirmed": self.twice_c,
            "twice_possible": self.twice_p, "never_confirmed": never_c,
            "never_possible": never_p, "repeats": self.repeats,
            "hazards": self.twice_c + never_c, "finding_counts": self.ordered_counts(),
        }
        return [f for g in GROUPS for f in self.groups[g]], metrics

    def ordered_counts(self) -> dict[str, int]:
        """Finding counts by kind, in the order the kinds were first listed."""
        order = [f.kind for g in GROUPS for f in self.groups[g]]
        out = {k: self.counts[k] for k in dict.fromkeys(order)}
        return out | {k: v for k, v in self.counts.items() if k not in out}


def merged(host: Iterator[HostLine], unit: Iterator[tuple[float, bytes]]
           ) -> Iterator[tuple[float, HostLine | None, str]]:
    """Both directions in time order, the unit's line first at the same time (a host answering
    it cannot have sent before it came): (t, None, unit line) or (t, host line, "")."""
    h = next(host, None)
    u = next(unit, None)
    while h is not None or u is not None:
        if u is not None and (h is None or u[0] <= h.t):
            yield u[0], None, u[1].decode("latin-1")
            u = next(unit, None)
        else:
            assert h is not None
            yield h.t, h, ""
            h = next(host, None)
