"""Record a serial session into a crash-safe MCAP file, from any number of threads.

The proxy, the sniffer and the emulator (``conform emulate --record``) all use this::

    rec = Recorder("run.mcap", {"capture_method": "emulator", "variant": "gve64-v19",
                                "baud": 115200, "unit_port": pty.path})
    rec.chunk("host", b"!0L1000,0,0\\r", rec.now())   # bytes from the sender
    rec.chunk("unit", b"0\\r", rec.now())             # bytes from the unit
    rec.link_event("disconnect", "unit port vanished", side="unit")
    rec.log("info", "sender reconnected")
    rec.close()                                      # run.mcap.part -> run.mcap

Calls only queue the data (cheap, never blocks on disk); one writer thread batches, decodes
frames and writes. The file is ``<path>.part`` until ``close()`` finishes it cleanly and
renames it; the writer flushes a chunk at least every ``flush_interval`` seconds (default
0.25), so a killed recorder loses at most that much and ``conform capture recover`` salvages
the rest.
"""

from __future__ import annotations

import os
import queue
import socket
import sys
import threading
import time
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from conform import __version__
from conform.capture.batch import BatchSession
from conform.capture.schemas import DIRECTIONS, FORMAT_VERSION, LINK_KINDS
from conform.capture.session import Decoder, Record
from conform.capture.sink import McapSink
from conform.errors import UserError

PART_SUFFIX = ".part"
CLOCK_SOURCE = "time.monotonic anchored to time.time at start (seconds since Unix epoch)"
CALLERS_CLOCK = "caller's clock"  # an emulator's virtual clock: its times are not wall-clock times


class RecordingError(UserError):
    """The recording could not be written (disk full, permissions...)."""


def part_path(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    return p.with_name(p.name + PART_SUFFIX)


class WallClock:
    """Monotonic time expressed as seconds since the epoch: steady, yet readable as a date."""

    def __init__(self) -> None:
        self._wall0 = time.time()
        self._mono0 = time.monotonic()

    def __call__(self) -> float:
        return self._wall0 + (time.monotonic() - self._mono0)


_STOP = object()


class Recorder:
    """Thread-safe MCAP recorder for one serial session (see the module docstring).

    ``metadata`` goes into an MCAP Metadata record named ``conform.session`` (keys such as
    ``capture_method``, ``host_port``, ``unit_port``, ``baud``, ``variant``, ``clock_source``).
    ``baud`` (or ``metadata["baud"]``) is the line's speed, from which the recorder estimates
    first-byte times unless ``backdate`` is False;
    ``variant`` (or ``metadata["variant"]``) enables decoded ``/frames`` and ``/exchanges``.
    ``clock`` supplies default timestamps (the emulator passes its own for a virtual clock).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        metadata: Mapping[str, object] | None = None,
        *,
        baud: int | None = None,
        variant: str | None = None,
        decode: bool = True,
        backdate: bool = True,
        decoder: Decoder | None = None,
        flush_interval: float = 0.25,
        chunk_size: int = 64 * 1024,
        clock: Any = None,
        name: str = "conform",
        overwrite_part: bool = False,
    ) -> None:
        self.path = Path(path)
        self.part = part_path(self.path)
        meta = dict(metadata or {})
        self.clock = clock if clock is not None else WallClock()
        self.flush_interval = flush_interval
        baud = baud if baud is not None else _int_or_none(meta.get("baud"))
        variant = variant if variant is not None else _str_or_none(meta.get("variant"))
        notes: list[str] = []
        if decoder is None and decode and variant:
            decoder, why = _make_decoder(variant, baud)
            if why:
                notes.append(why)
        # backdate=False: the bytes were read all at once from a pty and paced afterwards (an
        # emulator recording itself), so a chunk's first byte is dated when it was read
        self._session = BatchSession(baud=baud if backdate else None, decoder=decoder, name=name)
        self.decoding = decoder is not None
        if self.part.exists() and not overwrite_part:
            raise RecordingError(
                f"{self.part}: an unfinished recording is in the way; "
                f"salvage it with `conform capture recover {self.part}` or delete it"
            )
        try:
            self.part.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.part, "wb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise RecordingError(f"{self.part}: cannot create: {exc.strerror}") from None
        self._sink = McapSink(self._file, chunk_size=chunk_size,
                              topics=self._session.fields.channels())
        t0 = self.clock()
        meta.setdefault("clock_source", CLOCK_SOURCE if clock is None else CALLERS_CLOCK)
        meta.setdefault("tool", "conform")
        meta.setdefault("tool_version", __version__)
        meta.setdefault("format_version", FORMAT_VERSION)
        meta.setdefault("started", datetime.fromtimestamp(t0, UTC).isoformat())
        meta.setdefault("hostname", socket.gethostname())
        meta["baud"] = baud if baud is not None else ""
        meta["variant"] = variant or ""
        meta["frames_decoded"] = self.decoding
        self.metadata = meta
        self._sink.metadata("conform.session", meta)
        for rec in self._session.log("info", f"recording started: {self.path.name}", t0):
            self._sink.write(rec)
        for note in notes:
            for rec in self._session.log("warning", note, t0):
                self._sink.write(rec)
        self._sink.flush()
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._closed = False
        self._wake = threading.Event()  # set by close(): stop gathering, finish now
        self._close_lock = threading.Lock()
        self.error: BaseException | None = None
        self.bytes = dict.fromkeys(DIRECTIONS, 0)
        self.max_backlog = 0  # most items ever waiting for the writer thread
        self.cpu_s = 0.0  # CPU time the writer thread used (encoding, decoding, writing)
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    # -- the API the proxy, the sniffer and the emulator call ------------------------------
    def now(self) -> float:
        """The recorder's clock: seconds since the epoch, monotonic during the session."""
        return self.clock()

    def chunk(
        self, direction: str, data: bytes, t_read: float | None = None,
        t_first: float | None = None,
    ) -> None:
        """Bytes one read returned: ``direction`` is ``"host"`` (from the sender) or ``"unit"``.

        ``t_read`` is when the read returned (default: now); ``t_first`` the first byte's
        arrival if known, else estimated from the baud rate.
        """
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be 'host' or 'unit', not {direction!r}")
        if not data:
            return
        self._check_open()
        t = self.clock() if t_read is None else t_read
        self.bytes[direction] += len(data)
        self._queue.put(("chunk", direction, bytes(data), t, t_first))

    def link_event(
        self, kind: str, detail: str = "", *, side: str = "session", t: float | None = None
    ) -> None:
        """A port opened, closed, failed, vanished, came back or changed baud."""
        if kind not in LINK_KINDS:
            raise ValueError(f"link event kind must be one of {LINK_KINDS}, not {kind!r}")
        self._check_open()
        self._queue.put(("link", kind, side, detail, self.clock() if t is None else t))

    def log(
        self, level: str | int, text: str, *, t: float | None = None, name: str | None = None
    ) -> None:
        """A human-readable line for Foxglove's Log panel (levels: debug..fatal)."""
        self._check_open()
        caller = sys._getframe(1)
        self._queue.put(("log", level, text, self.clock() if t is None else t, name,
                         caller.f_code.co_filename, caller.f_lineno))

    def close(self, summary: Mapping[str, object] | None = None) -> Path:
        """Drain the queue, finish the file and rename ``.part`` to the final name."""
        with self._close_lock:
            if self._closed:
                return self.path
            self._closed = True
        self._queue.put(_STOP)
        self._wake.set()
        self._thread.join()
        try:
            if self.error is None:
                t = self.clock()
                for rec in self._session.finish(t):
                    self._sink.write(rec)
                for rec in self._session.log("info", "recording finished", t):
                    self._sink.write(rec)
                end = {"ended": datetime.fromtimestamp(t, UTC).isoformat(),
                       "bytes_host": self._session.offsets["host"],
                       "bytes_unit": self._session.offsets["unit"],
                       "messages": self._sink.count, "max_backlog": self.max_backlog,
                       "recorder_cpu_s": round(self.cpu_s, 3)}
                end.update(summary or {})
                self._sink.metadata("conform.session_end", end)
                self._sink.finish()
        except OSError as exc:
            self.error = exc
        finally:
            self._file.close()
        if self.error is not None:
            raise RecordingError(f"{self.part}: recording failed: {self.error}")
        os.replace(self.part, self.path)
        return self.path

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the writer thread -----------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f"{self.path}: recorder is closed")
        if self.error is not None:
            raise RecordingError(f"{self.part}: recording failed: {self.error}")

    def _records(self, item: tuple[Any, ...]) -> list[Record]:
        kind = item[0]
        if kind == "chunk":
            return self._session.chunk(item[1], item[2], item[3], item[4])
        if kind == "link":
            return self._session.link_event(item[1], item[2], item[3], item[4])
        _, level, text, t, name, file, line = item
        return self._session.log(level, text, t, name=name, file=file, line=line)

    def _run(self) -> None:
        """Write what the queue brings; while data flows, gather it for a flush interval.

        A reader thread queues a read every few milliseconds; waking for each one and
        decoding it alone costs more than decoding the same reads a quarter second at a time
        (cold caches, a thread switch per read). So after the first item the writer waits
        until the flush is due, then takes everything queued, decodes, writes and flushes.
        The first item after a quiet spell is flushed at once, as before.
        """
        last_flush = float("-inf")
        try:
            while True:
                item = self._queue.get()  # quiet: sleep until something comes
                while True:
                    if item is _STOP:
                        self._write(self._session.flush())
                        return
                    self._write(self._records(item))
                    self.max_backlog = max(self.max_backlog, self._queue.qsize())
                    try:
                        item = self._queue.get_nowait()
                        continue
                    except queue.Empty:
                        pass
                    left = last_flush + self.flush_interval - time.monotonic()
                    if left > 0 and not self._wake.is_set():
                        self._wake.wait(left)  # close() cuts this short
                        try:
                            item = self._queue.get_nowait()
                            continue
                        except queue.Empty:
                            pass
                    self._write(self._session.flush())
                    self._sink.flush()
                    last_flush = time.monotonic()
                    break
        except BaseException as exc:  # noqa: BLE001 - reported by close() and the next call
            self.error = exc
        finally:
            self.cpu_s = time.thread_time()

    def _write(self, records: list[Record]) -> None:
        for rec in records:
            self._sink.write(rec)


def _make_decoder(variant: str, baud: int | None) -> tuple[Decoder | None, str]:
    """The live frame decoder of the family serving ``variant`` (``Family.live_decoder``), or
    ``None`` and the reason: a family without one is recorded raw and decoded when analysed."""
    from conform.families import family_for_variant

    try:
        fam = family_for_variant(variant)
        decoder = fam.live_decoder(variant, baud=baud)
    except (ImportError, UserError, KeyError, LookupError) as exc:
        return None, f"frames not decoded: {exc}"
    if decoder is None:
        return None, f"frames not decoded while recording: {variant} traffic is decoded by " \
                     "conform analyze from the raw bytes"
    return decoder, ""


def _int_or_none(value: object) -> int | None:
    try:
        return int(value) if value not in (None, "") else None  # type: ignore[call-overload]
    except (TypeError, ValueError):
        return None


def _str_or_none(value: object) -> str | None:
    return str(value) if value not in (None, "") else None
