"""Reading a capture a bounded part at a time, with the state that crosses part boundaries.

Family-agnostic machinery of the streaming analysis:

* :class:`RawStream` walks the file (``rawread``'s record walk and payload decoding) and hands
  out the raw reads of each direction a part at a time, in file order, as soon as a batch of
  chunks is decoded (``rawread.BATCH_BYTES`` of decompressed records, or ``reads_per_part``
  reads when smaller parts are asked for). Read times are made sane on the way
  (:class:`TimeSanitizer`, with the last good time and the running maximum carried from
  one part to the next); ``read_raw`` joins the parts into whole directions.
* :class:`LineBuffer` holds one direction's bytes from the first line not yet consumed to
  the last byte received, with the reads that cover them (a read cut by the start of the
  buffer keeps its full length and a negative start, so the times of its bytes are
  interpolated exactly as over the whole stream). The line splitter runs over the buffer;
  the caller consumes whole lines and the remainder waits for the next part.

Nothing here knows the protocol: the GVE decoding and pairing that drive these live in
``frames`` and ``exchanges``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from conform.analysis.rawread import (
    MAX_TIME,
    Direction,
    Progress,
    RawCapture,
    ReadStatus,
    _Collector,
    _merge,
    walk_iter,
)
from conform.capture.scan import check_magic
from conform.capture.session import BITS_PER_BYTE
from conform.errors import UserError

MAX_LEAD = 10.0  # s: a first-byte time more than this before its read is not believed


class TimeSanitizer:
    """Read times made usable, a part at a time: a NaN, infinite, negative or absurd
    ``t_read`` takes the last good one before it (the first good one at the start), as does
    one earlier than the read before it (reads of one direction come back in stream order);
    a ``t_first`` that is not finite or not within ``MAX_LEAD`` before its read is dropped
    (estimated from the baud later). The last good read time and the running maximum are
    carried, so the result does not depend on where parts are cut."""

    def __init__(self) -> None:
        self.last_good: float | None = None
        self.run_max = -np.inf

    def apply(self, d: Direction) -> int:
        """Fix ``d``'s times in place; how many reads had an unusable time."""
        if d.chunks == 0:
            return 0
        t = d.t_read
        bad = ~np.isfinite(t) | (t < 0) | (t > MAX_TIME)
        n = int(bad.sum())
        if n:
            good = np.flatnonzero(~bad)
            k = np.maximum.accumulate(np.where(bad, -1, np.arange(len(t))))
            first = self.last_good if self.last_good is not None else (
                float(t[good[0]]) if len(good) else 0.0)
            t = np.where(k >= 0, t[np.maximum(k, 0)], first)
        if (~bad).any():
            self.last_good = float(d.t_read[np.flatnonzero(~bad)[-1]])
        mono = np.maximum.accumulate(np.concatenate([[self.run_max], t]))[1:]
        back = mono > t
        if back.any():
            n += int((back & ~bad).sum())
        t = mono
        self.run_max = float(t[-1])
        d.t_read = t
        tf = d.t_first
        with np.errstate(invalid="ignore"):
            off = ~np.isfinite(tf) | (tf > t + 1e-6) | (t - tf > MAX_LEAD) | bad
        d.t_first = np.where(off, np.nan, tf)
        return n


def _pieces(d: Direction, reads: int | None) -> Iterator[Direction]:
    """``d`` cut into parts of at most ``reads`` reads (whole when None)."""
    if reads is None or d.chunks <= reads:
        yield d
        return
    for lo in range(0, d.chunks, reads):
        hi = min(d.chunks, lo + reads)
        b0 = int(d.start[lo])
        b1 = int(d.start[hi - 1] + d.length[hi - 1])
        yield Direction(d.name, d.data[b0:b1], d.start[lo:hi] - b0, d.length[lo:hi],
                        d.offset[lo:hi], d.t_read[lo:hi], d.t_first[lo:hi], d.order[lo:hi])


class RawStream:
    """The raw reads of a capture, a part at a time (see the module docstring).

    ``parts()`` yields :class:`Direction` parts (their ``name`` says the direction);
    ``capture()`` gives the status, metadata, link events and topic counts read so far (all
    of them once ``parts()`` is exhausted), with no bytes (``released``).
    """

    def __init__(self, path: str | os.PathLike[str], progress: Progress | None = None,
                 reads_per_part: int | None = None) -> None:
        self.path = check_magic(path)
        self.status = ReadStatus(self.path)
        self.col = _Collector()
        self.col.status = self.status
        self.progress = progress
        self.reads_per_part = reads_per_part
        self.sane = {"host": TimeSanitizer(), "unit": TimeSanitizer()}
        self.done = False

    def parts(self) -> Iterator[Direction]:
        try:
            for _ in walk_iter(self.path, self.status, self.col, self.progress):
                yield from self._drain()
        except OSError as exc:
            raise UserError(f"{self.path}: cannot read: {exc.strerror}") from None
        self.col.flush()
        yield from self._drain()
        if self.status.bad_payloads:
            self.status.notes.append(
                f"{self.status.bad_payloads} raw chunk message(s) unreadable, skipped")
        self.done = True

    def _drain(self) -> Iterator[Direction]:
        for name in ("host", "unit"):
            parts, self.col.parts[name] = self.col.parts[name], []
            for part in parts:
                if len(part.length) == 0:  # nothing readable in it
                    continue
                self.status.bad_times += self.sane[name].apply(part)
                yield from _pieces(part, self.reads_per_part)

    def capture(self) -> RawCapture:
        return RawCapture(self.status, self.col.metadata, Direction.empty("host"),
                          Direction.empty("unit"), self.col.link, self.col.topics,
                          released=True)


def first_byte_times(d: Direction, baud: float | None, trust: bool, prev: float
                     ) -> np.ndarray:
    """First-byte time of every chunk of a part: the capture's, or estimated from ``baud``;
    ``prev`` is the running maximum of the earlier parts' read times (-inf for the first)."""
    est = d.t_read - (d.length * BITS_PER_BYTE / baud if baud else 0.0)
    if d.chunks:
        before = np.maximum.accumulate(np.concatenate([[prev], d.t_read]))[:-1]
        est = np.maximum(est, np.minimum(before, d.t_read))
    if trust:
        return np.where(np.isnan(d.t_first), est, d.t_first)
    return est


@dataclass
class LineBuffer:
    """One direction's bytes not yet consumed and the reads that cover them."""

    name: str
    baud: float | None
    trust: bool
    data: np.ndarray = None  # type: ignore[assignment]
    start: np.ndarray = None  # type: ignore[assignment]  # of each read, in ``data``
    length: np.ndarray = None  # type: ignore[assignment]
    t_read: np.ndarray = None  # type: ignore[assignment]
    t_first: np.ndarray = None  # type: ignore[assignment]  # taken or estimated
    order: np.ndarray = None  # type: ignore[assignment]
    base: int = 0  # stream offset of data[0]
    prev: float = -np.inf  # running maximum of the read times so far
    reads: int = 0  # reads received
    ended: bool = False

    def __post_init__(self) -> None:
        z = np.zeros(0, np.int64)
        self.data = np.zeros(0, np.uint8)
        self.start, self.length, self.order = z, z, z
        self.t_read, self.t_first = np.zeros(0), np.zeros(0)

    def append(self, part: Direction) -> None:
        if part.chunks == 0:
            return
        tf = first_byte_times(part, self.baud, self.trust, self.prev)
        self.prev = max(self.prev, float(part.t_read.max()))
        shift = len(self.data)
        self.data = np.concatenate([self.data, part.data]) if shift else part.data
        self.start = np.concatenate([self.start, part.start + shift])
        self.length = np.concatenate([self.length, part.length])
        self.t_read = np.concatenate([self.t_read, part.t_read])
        self.t_first = np.concatenate([self.t_first, tf])
        self.order = np.concatenate([self.order, part.order])
        self.reads += part.chunks

    def view(self) -> Direction:
        """The buffer as a ``Direction`` (``t_first`` the first-byte times in use)."""
        n = len(self.start)
        return Direction(self.name, self.data, self.start, self.length,
                         np.full(n, -1, np.int64), self.t_read, self.t_first, self.order)

    def horizon(self) -> float:
        """Every line still to come ends at or after this time (a read's bytes are timed
        between its first-byte time, at most ``MAX_LEAD`` before it, and its read time)."""
        if self.ended:
            return np.inf
        return self.prev - MAX_LEAD if self.reads else -np.inf

    def consume(self, upto: int) -> None:
        """Let go of ``data[:upto]`` (whole lines) and of the reads wholly inside it."""
        if upto <= 0:
            return
        keep = self.start + self.length > upto
        self.data = self.data[upto:].copy()
        self.start = self.start[keep] - upto
        self.length = self.length[keep]
        self.t_read = self.t_read[keep]
        self.t_first = self.t_first[keep]
        self.order = self.order[keep]
        self.base += upto


class ReadStats:
    """What the reads of one direction tell, gathered part by part: a lower bound on the
    baud (bytes that arrived between two reads took that long: the 98th percentile of
    10 x bytes / interval over reads of 4 bytes or more), reads whose stream offset does
    not follow the previous one, and whether every first-byte time equals its read time
    (a direction with no wire to cross)."""

    def __init__(self, name: str) -> None:
        from conform.analysis.summaries import Quantiles

        self.name = name
        self.reads = 0
        self.rates = Quantiles()
        self.last_t: float | None = None
        self.real = 0  # stream offset the next read should claim
        self.gaps = 0
        self.gap_t = 0.0
        self.exact = True

    def feed(self, d: Direction) -> None:
        if d.chunks == 0:
            return
        t = d.t_read if self.last_t is None else np.concatenate([[self.last_t], d.t_read])
        n = d.length if self.last_t is None else d.length
        dt = np.diff(t)
        nn = n[1:] if self.last_t is None else n
        ok = (dt > 0) & (nn >= 4)
        self.rates.add(10.0 * nn[ok] / dt[ok])
        self.last_t = float(d.t_read[-1])
        real = self.real + np.concatenate([[0], np.cumsum(d.length)[:-1]])
        gaps = np.flatnonzero((d.offset >= 0) & (d.offset != real))
        if len(gaps):
            if not self.gaps:
                self.gap_t = float(d.t_read[gaps[0]])
            self.gaps += len(gaps)
        self.real += int(d.length.sum())
        self.exact = self.exact and bool(np.all(np.abs(d.t_read - d.t_first) < 1e-5))
        self.reads += d.chunks

    def baud_bound(self) -> float | None:
        if self.reads < 3 or self.rates.n < 3:
            return None
        return self.rates.quantile([0.98])[0]

    def gap(self) -> tuple[str, float, int] | None:
        return (self.name, self.gap_t, self.gaps) if self.gaps and self.reads > 1 else None


def read_raw(path: str | os.PathLike[str], progress: Progress | None = None) -> RawCapture:
    """Read ``path`` (an MCAP capture) as far as it is intact: ``RawStream``'s parts
    (times made usable as they come, ``TimeSanitizer``) joined into whole directions."""
    rs = RawStream(path, progress)
    parts: dict[str, list[Direction]] = {"host": [], "unit": []}
    for part in rs.parts():
        parts[part.name].append(part)
    c = rs.capture()
    return RawCapture(c.status, c.metadata, _merge("host", parts["host"]),
                      _merge("unit", parts["unit"]), c.link_events, c.topics)
