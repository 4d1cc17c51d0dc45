"""``conform proxy --live`` / ``sniff --live``: a terminal view that updates while it records.

The recorder hands every read to a bounded deque (one append on the pump thread, nothing
else); a view thread takes them four times a second and feeds its family's live monitor
(``Family.live_monitor``: counters in neutral words, :class:`LiveState`), then draws bytes
each way, lines and answers, bytes in flight against the receive buffer, answer latency,
errors and events as they happen, and the diagnosis so far. Until the family is known (no
``--variant``), the first bytes decide it (``conform.families.detect_family``).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol

if TYPE_CHECKING:
    from rich.console import Console, RenderableType

    from conform.capture.recorder import Recorder

REFRESH_S = 0.25
TAP_MAX = 200_000           # reads kept for the view; beyond, the oldest are let go
DETECT_BYTES = 512          # bytes each way looked at to tell the family
QUIET_S = 2.0               # this long without progress is worth saying


@dataclass
class LiveState:
    """What a family's live monitor keeps up to date."""

    lines: int = 0                       # host lines sent
    answers: int = 0                     # answers to them
    errors: int = 0                      # refusals among the answers
    waiting: int = 0                     # lines sent and not yet answered
    in_flight_bytes: int | None = None   # their bytes, where the unit's buffer counts bytes
    rx_capacity: int | None = None       # the unit's receive buffer, bytes
    latency_s: float | None = None       # the last line-to-answer time
    latency_max_s: float = 0.0
    t_line: float | None = None          # when the last line was sent
    t_answer: float | None = None        # when the last answer came
    events: deque[str] = field(default_factory=lambda: deque(maxlen=8))


class LiveMonitor(Protocol):
    """A family's live monitor (``Family.live_monitor``): fed every read as it comes, it keeps
    ``state`` current."""

    state: LiveState

    def feed(self, direction: str, data: bytes, t: float) -> None:
        """Bytes read from ``direction`` (``host`` or ``unit``) at ``t``."""


def so_far(s: LiveState, now: float) -> str:
    """The diagnosis so far, in one line, from the counters alone."""
    if any("ALARM" in e or "alarm" in e for e in s.events):
        return "unit-alarm: " + next(e for e in reversed(s.events) if "larm" in e)
    if s.in_flight_bytes is not None and s.rx_capacity and s.in_flight_bytes > s.rx_capacity:
        return (f"buffer-overflow risk: {s.in_flight_bytes} bytes in flight, receive buffer "
                f"{s.rx_capacity}")
    if s.waiting and s.t_answer is not None and now - max(s.t_answer, s.t_line or 0) > QUIET_S:
        return (f"unit-silent so far: {s.waiting} line(s) waiting "
                f"{now - max(s.t_answer, s.t_line or 0):.1f} s for an answer")
    if s.lines and not s.waiting and s.t_line is not None and now - s.t_line > QUIET_S:
        return f"sender-stopped so far: the unit is ready, no line for {now - s.t_line:.1f} s"
    if s.errors:
        return f"running, {s.errors} refused line(s)"
    return "running normally" if s.lines else "waiting for traffic"


class LiveView:
    def __init__(self, recorder: Recorder, variant: str | None, *, console: Console | None = None,
                 title: str = "") -> None:
        self.recorder = recorder
        self.variant = variant
        self.title = title
        self.tap: deque[tuple[str, bytes, float]] = deque(maxlen=TAP_MAX)
        self.monitor: LiveMonitor | Literal[False] | None = None  # False: the family has none
        self.family = ""
        self._seen = {"host": bytearray(), "unit": bytearray()}
        self._held: list[tuple[str, bytes, float]] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._console = console
        self.t0 = time.time()
        self.frames = 0
        self._wrap()

    def _wrap(self) -> None:
        """Every read the recorder gets also goes to the view's deque."""
        rec = self.recorder
        chunk = rec.chunk
        append = self.tap.append
        clock = rec.clock

        def tapped(direction: str, data: bytes, t_read: float | None = None,
                   t_first: float | None = None) -> None:
            t = clock() if t_read is None else t_read
            chunk(direction, data, t, t_first)
            append((direction, data, t))

        rec.chunk = tapped  # type: ignore[method-assign]  # the view taps every chunk

    def _choose(self, direction: str, data: bytes, t: float) -> None:
        from conform.families import detect_family, family, family_for_variant

        self._held.append((direction, data, t))
        self._seen[direction] += data[:DETECT_BYTES]
        fam = None
        if self.variant:
            fam = family_for_variant(self.variant)
        elif min(len(b) for b in self._seen.values()) >= DETECT_BYTES // 4 or \
                max(len(b) for b in self._seen.values()) >= DETECT_BYTES:
            d = detect_family(bytes(self._seen["host"]), bytes(self._seen["unit"]), {})
            if d.family != "unknown":
                fam = family(d.family)
        if fam is None:
            return
        make = getattr(fam, "live_monitor", None)
        self.monitor = make(self.variant) if make is not None else None
        self.family = fam.name
        if self.monitor is None:
            self.monitor = False        # this family has none: counts only
            return
        for item in self._held:
            self.monitor.feed(*item)
        self._held.clear()

    def step(self) -> None:
        """Feed what arrived since the last step to the monitor."""
        tap = self.tap
        while tap:
            item = tap.popleft()
            if self.monitor:
                self.monitor.feed(*item)
            elif self.monitor is None:
                self._choose(*item)

    def renderable(self) -> RenderableType:
        from rich.table import Table

        now = time.time()
        self.frames += 1
        t = Table(title=f"conform {self.title} (Ctrl-C to stop)", show_header=False,
                  expand=False)
        t.add_column(style="bold")
        t.add_column()
        b = getattr(self.recorder, "bytes", {})
        t.add_row("recording", f"{self.recorder.path}  {now - self.t0:.0f} s")
        t.add_row("bytes", f"host→unit {b.get('host', 0)}   unit→host {b.get('unit', 0)}")
        s: LiveState | None = self.monitor.state if self.monitor else None
        t.add_row("family", self.family or "not known yet")
        if s is not None:
            t.add_row("lines", f"{s.lines} sent, {s.answers} answered, {s.errors} refused, "
                               f"{s.waiting} waiting")
            if s.in_flight_bytes is not None:
                cap = s.rx_capacity or 0
                fill = min(20, round(20 * s.in_flight_bytes / cap)) if cap else 0
                t.add_row("in flight", f"[{'#' * fill}{'.' * (20 - fill)}] "
                                       f"{s.in_flight_bytes} / {cap} bytes")
            lat = "–" if s.latency_s is None else f"{1000 * s.latency_s:.1f} ms"
            t.add_row("latency", f"last {lat}, max {1000 * s.latency_max_s:.1f} ms")
            for e in list(s.events)[-4:]:
                t.add_row("event", e)
            t.add_row("so far", so_far(s, now))
        return t

    def start(self) -> None:
        from rich.console import Console
        from rich.live import Live

        console = self._console or Console(stderr=True)

        def run() -> None:
            with Live(self.renderable(), console=console, auto_refresh=False,
                      transient=False) as live:
                while not self._stop.wait(REFRESH_S):
                    self.step()
                    live.update(self.renderable(), refresh=True)
                self.step()
                live.update(self.renderable(), refresh=True)

        self._thread = threading.Thread(target=run, name="live-view", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)


def watching(capture: Any, view: LiveView) -> str | None:
    """Run a live capture (``conform.capture.live``) to its end with its view on; the
    capture's failure, if it ended by itself."""
    from conform.capture.live import run_until_signal

    view.start()
    try:
        return run_until_signal(capture)
    finally:
        view.stop()
