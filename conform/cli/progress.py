"""Progress for long commands, the same way everywhere.

On a terminal: rich bars on stderr, each naming the step it is on. Off a terminal (CI logs,
pipes): one line on stderr every few seconds while something runs, so a long stretch is never
silent and a log shows where a stalled run stood. ``--quiet`` (or ``enabled=False``) shows
nothing. Commands only call :func:`progress`, :meth:`Tracker.task` and :meth:`Task.update`.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

#: seconds between two lines off a terminal (``CONFORM_PROGRESS_SECONDS`` overrides it)
DEFAULT_INTERVAL = 5.0


def _interval() -> float:
    try:
        return max(0.05, float(os.environ.get("CONFORM_PROGRESS_SECONDS", DEFAULT_INTERVAL)))
    except ValueError:
        return DEFAULT_INTERVAL


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"


class Task:
    """One bar: a description, a count (or bytes) done of a total, and the current step."""

    def __init__(self, tracker: Tracker, description: str, total: float | None,
                 unit: str, poll: Callable[[], str] | None = None) -> None:
        self.tracker = tracker
        self.poll = poll
        self.description = description
        self.total = total
        self.unit = unit
        self.completed = 0.0
        self.step = ""
        self.started = time.monotonic()
        self._id: Any = None

    def update(self, *, advance: float = 0, completed: float | None = None,
               total: float | None = None, step: str | None = None) -> None:
        if completed is not None:
            self.completed = completed
        self.completed += advance
        if total is not None:
            self.total = total
        if step is not None:
            self.step = step
        self.tracker._refresh(self)

    def line(self) -> str:
        """The plain-text state: ``description 120/363 (33%) step, 12 s``."""
        parts = [self.description]
        if self.unit == "bytes":
            done = _size(self.completed)
            parts.append(f"{done} of {_size(self.total)}" if self.total else done)
        elif self.total:
            parts.append(f"{self.completed:.0f}/{self.total:.0f}")
        if self.total:
            parts.append(f"({100 * self.completed / self.total:.0f}%)")
        if self.step:
            parts.append(f"— {self.step}")
        return " ".join(parts) + f", {time.monotonic() - self.started:.0f} s"


class Tracker:
    """The tasks of one command; shown as bars, as periodic lines, or not at all."""

    def __init__(self, label: str, mode: str, stream: TextIO, interval: float,
                 transient: bool = False) -> None:
        self.label = label
        self.transient = transient
        self.mode = mode
        self.stream = stream
        self.interval = interval
        self.tasks: list[Task] = []
        self._bar: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def task(self, description: str, total: float | None = None, *, unit: str = "items",
             poll: Callable[[], str] | None = None) -> Task:
        """A new bar; ``poll`` (for open-ended work such as a recording) returns the current
        step text and is asked before each refresh."""
        t = Task(self, description, total, unit, poll)
        self.tasks.append(t)
        if self._bar is not None:
            t._id = self._bar.add_task(description, total=total, step="")
        return t

    def say(self, message: str) -> None:
        """A one-off message (kept above the bars on a terminal)."""
        if self.mode == "off":
            return
        if self._bar is not None:
            self._bar.console.print(message, markup=False, highlight=False)
        else:
            print(f"{self.label}: {message}", file=self.stream, flush=True)

    def _refresh(self, task: Task) -> None:
        if self._bar is not None and task._id is not None:
            self._bar.update(task._id, completed=task.completed, total=task.total,
                             step=task.step)

    def _tick(self) -> None:
        interval = self.interval if self.mode == "lines" else 0.5
        while not self._stop.wait(interval):
            for t in list(self.tasks):
                if t.poll is not None:
                    try:
                        t.update(step=t.poll())
                    except Exception:  # noqa: BLE001 - a display must never end a command
                        pass
                if self.mode == "lines" and (t.total is None or t.completed < t.total):
                    print(f"{self.label}: {t.line()}", file=self.stream, flush=True)

    def __enter__(self) -> Tracker:
        if self.mode == "bar":
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
            )

            self._bar = Progress(TextColumn("{task.description}"), BarColumn(),
                                 MofNCompleteColumn(), TextColumn("{task.fields[step]}"),
                                 TimeElapsedColumn(), console=Console(file=self.stream),
                                 transient=self.transient,
                                 # stdout into the live display only when both are the terminal
                                 redirect_stdout=sys.stdout.isatty())
            self._bar.__enter__()
        if self.mode != "off":
            self._thread = threading.Thread(target=self._tick, name="progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._bar is not None:
            self._bar.__exit__(*exc)


def mode_for(stream: TextIO, quiet: bool = False) -> str:
    """``bar`` on a terminal, ``lines`` off one, ``off`` when quiet."""
    if quiet:
        return "off"
    try:
        return "bar" if stream.isatty() else "lines"
    except (AttributeError, ValueError):
        return "lines"


@contextmanager
def progress(label: str, *, quiet: bool = False, stream: TextIO | None = None,
             interval: float | None = None, transient: bool = False) -> Iterator[Tracker]:
    """``with progress("conform run") as p: t = p.task("checks", 363); t.update(advance=1)``;
    ``transient`` bars vanish when done (for commands whose result is a few lines)."""
    out = stream if stream is not None else sys.stderr
    with Tracker(label, mode_for(out, quiet), out,
                 interval if interval is not None else _interval(), transient) as tracker:
        yield tracker


def recording(tracker: Tracker, recorder: Any, what: str) -> Task:
    """An open-ended task for a live recording: the bytes each way so far, polled."""
    tracker.say(f"recording {what} to {recorder.path} (Ctrl-C to stop)")

    def now() -> str:
        b = getattr(recorder, "bytes", {})
        return ", ".join(f"{d} {_size(n)}" for d, n in b.items()) or "waiting"

    return tracker.task("recording", None, poll=now)
