"""Format 2 of a capture: the reads and the decoded lines of a moment, one message each.

A recorder at 921 600 Bd sees thousands of reads and lines a second; one MCAP message per
read and per line (format 1) costs more CPU to encode than the traffic allows. Format 2
keeps the same channels but batches them (docs/capture-format.md):

* ``/serial/host``, ``/serial/unit``: ``conform.RawBatch``, the bytes of consecutive reads
  in one direction stored once (base64 of their concatenation) with a packed table of
  per-read lengths, times and a call-order number shared by both directions (so the causal
  order of reads survives batching);
* ``/frames``, ``/exchanges``: ``conform.FrameBatch`` / ``conform.ExchangeBatch``, the
  decoded lines and exchanges of the same moment, one list per field (``columns``;
  ``rows`` turns a batch back into ``conform.Frame`` / ``conform.Exchange`` dicts).

``BatchSession`` is sans-I/O like ``CaptureSession``: chunks in, nothing out until
``flush(t)`` returns the batch records. Link events and logs are returned at once.
"""

from __future__ import annotations

import binascii
import json
from operator import itemgetter
from typing import Any

import numpy as np
import pybase64  # SIMD base64: a recorder and a shift's analysis move megabytes of it

from conform.capture.schemas import (
    DIRECTION_TOPIC,
    DIRECTIONS,
    NEUTRAL,
    TOPIC_EXCHANGES,
    TOPIC_FRAMES,
    CaptureFields,
)
from conform.capture.session import CaptureSession, Decoder, Record, to_ns
from conform.jsondoc import JsonObject

BATCH_BYTES = 32 * 1024  # a direction's pending bytes that force a batch out

FRAME_KEYS = NEUTRAL.frame_keys  # the neutral fields; a family's decoder adds its own
EXCHANGE_KEYS = NEUTRAL.exchange_keys
BATCH_KEYS = {TOPIC_FRAMES: FRAME_KEYS, TOPIC_EXCHANGES: EXCHANGE_KEYS}  # a batched topic's


def row_columns(items: list[tuple[Any, ...]], keys: tuple[str, ...]) -> JsonObject:
    """Items as one batch: ``count`` and one list per field (JSON of lists costs less), from
    tuples whose fields are in ``keys`` order."""
    out: JsonObject = {"count": len(items)}
    if items:
        out.update(zip(keys, map(list, zip(*items, strict=True)), strict=True))
    else:
        out.update((k, []) for k in keys)
    return out


def rows(payload: JsonObject, keys: tuple[str, ...] = ()) -> list[JsonObject]:
    """The items of a batch: the fields ``keys`` (None where a batch lacks one) and every
    other column it carries (a family's fields: the batch names them, so no family is
    needed to read it); ``ValueError`` if its columns do not hold together."""
    n = payload.get("count")
    if not isinstance(n, int) or isinstance(n, bool) or n < 0:
        raise ValueError("batch without a count")
    keys = tuple(keys) + tuple(k for k in payload if k != "count" and k not in keys)
    cols = []
    for k in keys:
        col = payload.get(k, [None] * n)
        if not isinstance(col, list) or len(col) != n:
            raise ValueError(f"batch column {k!r} is not a list of {n}")
        cols.append(col)
    return [dict(zip(keys, values, strict=True)) for values in zip(*cols, strict=True)] \
        if n else []


def is_batch(payload: JsonObject) -> bool:
    return "count" in payload


# one entry of a RawBatch's ``reads``: bytes the read returned, its call order (one count for
# both directions), when it returned and the estimated arrival of its first byte
READ_DTYPE = np.dtype([("length", "<u4"), ("order", "<u8"), ("t_read", "<f8"),
                       ("t_first", "<f8")])


def raw_batch(direction: str, offset: int, data: bytes | bytearray, lengths: list[int],
              t_read: list[float], t_first: list[float], order: list[int]) -> Record:
    """The ``conform.RawBatch`` record of consecutive reads in one direction."""
    reads = np.empty(len(lengths), READ_DTYPE)
    reads["length"] = lengths
    reads["order"] = order
    reads["t_read"] = t_read
    reads["t_first"] = t_first
    payload = {"direction": direction, "offset": offset, "count": len(lengths),
               "t_start": t_read[0], "t_end": t_read[-1], "bytes": len(data),
               "reads": pybase64.b64encode(reads.tobytes()).decode("ascii"),
               "data": pybase64.b64encode(data).decode("ascii")}
    return Record(DIRECTION_TOPIC[direction], to_ns(t_read[0]), payload)


class _Pending:
    """Reads of one direction waiting for the next batch."""

    __slots__ = ("data", "offset", "lengths", "t_read", "t_first", "order")

    def __init__(self) -> None:
        self.data = bytearray()
        self.offset = 0
        self.lengths: list[int] = []
        self.t_read: list[float] = []
        self.t_first: list[float] = []
        self.order: list[int] = []


class BatchSession(CaptureSession):
    """``CaptureSession`` writing format 2: ``chunk`` buffers, ``flush`` emits the batches.

    Frames and exchanges are collected as rows (tuples in the order of the decoder's
    ``fields``: ``CaptureFields.frame_keys`` / ``exchange_keys``, the neutral fields then the
    family's): from a decoder that collects them itself (``feed_rows`` / ``take_rows`` /
    ``finish_rows``), or taken from the records of any other ``Decoder``.
    """

    def __init__(self, *, baud: int | None = None, decoder: Decoder | None = None,
                 name: str = "conform", batch_bytes: int = BATCH_BYTES) -> None:
        super().__init__(baud=baud, decoder=decoder, name=name)
        self.fields: CaptureFields = getattr(decoder, "fields", None) or NEUTRAL
        self._keys = {TOPIC_FRAMES: self.fields.frame_keys,
                      TOPIC_EXCHANGES: self.fields.exchange_keys}
        self._get = {t: itemgetter(*k) for t, k in self._keys.items()}
        self.batch_bytes = batch_bytes
        self._pending = {d: _Pending() for d in DIRECTIONS}
        self._rows: dict[str, list[tuple[Any, ...]]] = {TOPIC_FRAMES: [], TOPIC_EXCHANGES: []}
        self._t_rows: float | None = None
        self._calls = 0
        self._feed_rows = getattr(decoder, "feed_rows", None)

    def chunk(self, direction: str, data: bytes, t_read: float, t_first: float | None = None
              ) -> list[Record]:
        """Buffer one read; returns the batches if this read filled one."""
        if not data:
            return super().chunk(direction, data, t_read, t_first)
        offset, t_first = self.advance(direction, len(data), t_read, t_first)
        p = self._pending[direction]
        if not p.lengths:
            p.offset = offset
        p.data += data
        p.lengths.append(len(data))
        p.t_read.append(t_read)
        p.t_first.append(t_first)
        p.order.append(self._calls)
        self._calls += 1
        if self._feed_rows is not None:
            self._feed_rows(direction, data, offset, t_read, t_first)
        elif self.decoder is not None:
            for rec in self.decoder.feed(direction, data, offset, t_read, t_first):
                self._derived(rec)
        if len(p.data) >= self.batch_bytes:
            return self.flush()
        return []

    def _derived(self, rec: Record) -> None:
        """A frame or exchange record of a decoder without rows, as a row."""
        if self._t_rows is None:
            self._t_rows = rec.log_time / 1e9
        try:
            row = self._get[rec.topic](rec.payload)
        except KeyError:  # a decoder that leaves fields out
            row = tuple(rec.payload.get(k) for k in self._keys[rec.topic])
        self._rows[rec.topic].append(row)

    def flush(self) -> list[Record]:
        """Everything buffered as batch records (raw first, then frames and exchanges)."""
        out: list[Record] = []
        for d in DIRECTIONS:
            p = self._pending[d]
            if not p.lengths:
                continue
            out.append(raw_batch(d, p.offset, p.data, p.lengths, p.t_read, p.t_first, p.order))
            self._pending[d] = _Pending()
        if self._feed_rows is not None:
            t_rows, frames, exchanges = self.decoder.take_rows()  # type: ignore[union-attr]
        else:
            t_rows, frames, exchanges = (self._t_rows, self._rows[TOPIC_FRAMES],
                                         self._rows[TOPIC_EXCHANGES])
            self._rows = {TOPIC_FRAMES: [], TOPIC_EXCHANGES: []}
            self._t_rows = None
        t = to_ns(t_rows or 0.0)
        if frames:
            out.append(Record(TOPIC_FRAMES, t, row_columns(frames, self._keys[TOPIC_FRAMES])))
        if exchanges:
            out.append(Record(TOPIC_EXCHANGES, t,
                              row_columns(exchanges, self._keys[TOPIC_EXCHANGES])))
        return out

    def finish(self, t: float) -> list[Record]:
        """The decoder's leftovers and every pending batch."""
        if self._feed_rows is not None:
            self.decoder.finish_rows(t)  # type: ignore[union-attr]
        else:
            for rec in super().finish(t):
                self._derived(rec)
        return self.flush()


def is_raw_batch(payload: JsonObject) -> bool:
    return "reads" in payload


def payload_bytes(payload: JsonObject) -> bytes:
    """The bytes a raw message carries (a format 1 read or a format 2 batch: both keep them
    as base64 in ``data``); ``ValueError`` if they are not base64."""
    try:
        return pybase64.b64decode(payload.get("data", ""), validate=True)
    except (TypeError, AttributeError, binascii.Error) as exc:
        raise ValueError(f"bad raw message: {exc}") from None


def unbatch_arrays(raw: bytes | JsonObject) -> tuple[bytes, Any, int, Any, Any, Any]:
    """A ``conform.RawBatch`` message (JSON text or parsed) as (bytes, lengths, offset, t_read,
    t_first, order), numpy arrays; ``ValueError`` if it does not hold together."""
    try:
        obj = json.loads(raw) if isinstance(raw, (bytes, bytearray, str)) else raw
        packed = pybase64.b64decode(obj["reads"], validate=True)
        data = pybase64.b64decode(obj["data"], validate=True)
        offset = obj["offset"]
        if not isinstance(offset, int) or isinstance(offset, bool) or not 0 <= offset < 2**62:
            raise ValueError("offset is not a stream offset")
        if len(packed) % READ_DTYPE.itemsize:
            raise ValueError("reads are not whole entries")
        reads = np.frombuffer(packed, READ_DTYPE)
    except (KeyError, TypeError, ValueError, AttributeError, RecursionError,
            binascii.Error) as exc:
        raise ValueError(f"bad raw batch: {exc}") from None
    lengths = reads["length"].astype(np.int64)
    if (lengths <= 0).any() or int(lengths.sum()) != len(data) \
            or obj.get("count", len(reads)) != len(reads):
        raise ValueError("bad raw batch: lengths, count and data disagree")
    return (data, lengths, offset, reads["t_read"].astype(np.float64),
            reads["t_first"].astype(np.float64), reads["order"].astype(np.int64))


def unbatch_raw(payload: JsonObject, log_time: int) -> list[JsonObject]:
    """The reads of a ``conform.RawBatch`` as chunk dicts like format 1's (with ``bytes``);
    ``ValueError`` if the batch does not hold together."""
    data, lengths, offset, t_read, t_first, order = unbatch_arrays(payload)
    direction = str(payload.get("direction"))
    out = []
    pos = 0
    for n, tr, tf, o in zip(lengths.tolist(), t_read.tolist(), t_first.tolist(),
                            order.tolist(), strict=True):
        out.append({"direction": direction, "bytes": data[pos : pos + n], "length": n,
                    "offset": offset + pos, "t_read": tr, "t_first": tf, "order": o,
                    "log_time": to_ns(tr) if tr == tr else log_time})
        pos += n
    return out
