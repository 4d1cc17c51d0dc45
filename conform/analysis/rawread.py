"""Read the raw byte channels of a capture fast and without trusting the file.

The analyser needs only the raw chunks (the bytes are the truth) plus the small channels
(link events, metadata). ``conform.capture.reader`` builds one Python object per message,
which is too slow for a million exchanges, so this module walks the MCAP records itself:
top-level records are bounded by the file size, chunks are decompressed and CRC-checked,
and message records inside a chunk are sliced with ``struct`` without building objects.
The JSON payloads of the raw channels are parsed in bulk (``pyarrow.json``) and their
base64 data decoded with numpy. A damaged chunk is skipped, a truncated file is read up to
the damage; both are reported in :class:`ReadStatus`, never raised. Only a file that is not
MCAP at all raises ``UserError``.
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zstandard

from conform.capture.scan import data_records, decompress_chunk
from conform.capture.schemas import TOPIC_HOST, TOPIC_LINK, TOPIC_UNIT
from conform.jsondoc import JsonObject

OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 1, 2, 3, 4, 5, 6
OP_METADATA, OP_DATA_END = 0x0C, 0x0F
RAW_TOPICS = {TOPIC_HOST: "host", TOPIC_UNIT: "unit"}
Progress = Callable[[int, int], None]
_U64 = struct.Struct("<Q").unpack_from
BATCH_BYTES = 8 * 1024 * 1024  # decompressed bytes decoded at a time


def _gather(arr: np.ndarray, at: np.ndarray, width: int, dtype: str) -> np.ndarray:
    """Little-endian integers of ``width`` bytes at each index of ``at``."""
    return arr[at[:, None] + np.arange(width)].copy().view(dtype).ravel()


@dataclass
class ReadStatus:
    """What the walk over the file found."""

    path: Path
    size: int = 0
    complete: bool = False
    problem: str | None = None
    damaged_chunks: int = 0
    bad_payloads: int = 0
    bad_times: int = 0  # reads whose time was not a usable number (timed by their neighbour)
    notes: list[str] = field(default_factory=list)
    valid_bytes: int = 0  # end of the last intact top-level record

    @property
    def truncated(self) -> bool:
        return not self.complete

    def record_damage(self, note: str) -> None:
        """A top-level record skipped (``conform.capture.scan.data_records``)."""
        self.damaged_chunks += 1
        self.notes.append(note)

    @property
    def clean(self) -> bool:
        """Complete, and nothing in it was damaged or unreadable."""
        return self.complete and self.problem is None and not self.damaged_chunks \
            and not self.bad_payloads and not self.bad_times

    def describe(self) -> str:
        """One line saying what is wrong ("" for a clean capture)."""
        if self.clean:
            return ""
        what = [] if self.complete else [f"truncated ({self.problem})"]
        if self.complete and self.problem:
            what.append(self.problem)
        if self.damaged_chunks:
            what.append(f"{self.damaged_chunks} damaged record(s) skipped")
        if self.bad_payloads:
            what.append(f"{self.bad_payloads} unreadable message(s) or schema(s)")
        if self.bad_times:
            what.append(f"{self.bad_times} read(s) with an unusable time (NaN, infinite, out "
                        "of range or before the read preceding it), timed as the read before")
        return "; ".join(what)


@dataclass
class Direction:
    """Every byte of one direction in file order, with the chunk each came in."""

    name: str
    data: np.ndarray  # uint8, all chunks concatenated
    start: np.ndarray  # int64, index of each chunk's first byte in ``data``
    length: np.ndarray  # int64
    offset: np.ndarray  # int64, the stream offset the capture claims (-1 if unknown)
    t_read: np.ndarray  # float64 seconds
    t_first: np.ndarray  # float64 seconds (nan where the capture gave none)
    order: np.ndarray  # int64, message index in the file (both directions share one count)

    @property
    def chunks(self) -> int:
        return len(self.start)

    @classmethod
    def empty(cls, name: str) -> Direction:
        z = np.zeros(0, np.int64)
        return cls(name, np.zeros(0, np.uint8), z, z, z, np.zeros(0), np.zeros(0), z)


@dataclass
class RawCapture:
    status: ReadStatus
    metadata: dict[str, dict[str, str]]
    host: Direction
    unit: Direction
    link_events: list[JsonObject]
    topics: dict[str, int]  # messages per topic

    released: bool = False  # the per-read tables and bytes were let go (``release``)

    def direction(self, name: str) -> Direction:
        return self.host if name == "host" else self.unit

    def release(self) -> None:
        """Let go of the bytes and the per-read tables (the largest arrays of a long
        capture) once the lines are decoded; ``Analysis.chunks`` reads them again."""
        self.host, self.unit = Direction.empty("host"), Direction.empty("unit")
        self.released = True


class _Collector:
    def __init__(self) -> None:
        self.channels: dict[int, tuple[str, str]] = {}  # id -> (topic, encoding)
        self.metadata: dict[str, dict[str, str]] = {}
        self.spans: dict[str, list[tuple]] = {"host": [], "unit": []}
        self.buffers: list[np.ndarray] = []
        self.size = 0
        self.parts: dict[str, list[Direction]] = {"host": [], "unit": []}
        self.status: ReadStatus | None = None
        self.raw_encoded: dict[str, bool] = {"host": False, "unit": False}
        self.link: list[JsonObject] = []
        self.topics: dict[str, int] = {}
        self.count = 0

    def channel(self, body: bytes) -> None:
        cid, _schema = struct.unpack_from("<HH", body, 0)
        (n,) = struct.unpack_from("<I", body, 4)
        topic = body[8 : 8 + n].decode("utf-8", "replace")
        (m,) = struct.unpack_from("<I", body, 8 + n)
        enc = body[12 + n : 12 + n + m].decode("utf-8", "replace")
        self.channels.setdefault(cid, (topic, enc))

    def schema(self, body: bytes) -> None:
        """A JSON schema that is not JSON makes the file unreadable for Foxglove: say so."""
        (n,) = struct.unpack_from("<I", body, 2)
        (m,) = struct.unpack_from("<I", body, 6 + n)
        encoding = body[10 + n : 10 + n + m]
        (k,) = struct.unpack_from("<I", body, 10 + n + m)
        if encoding == b"jsonschema":
            try:
                json.loads(body[14 + n + m : 14 + n + m + k])
            except (ValueError, RecursionError):
                assert self.status is not None
                self.status.bad_payloads += 1
                self.status.notes.append("a channel's JSON schema is not JSON")

    def metadata_record(self, body: bytes) -> None:
        (n,) = struct.unpack_from("<I", body, 0)
        name = body[4 : 4 + n].decode("utf-8", "replace")
        (total,) = struct.unpack_from("<I", body, 4 + n)
        pos, end = 8 + n, 8 + n + total
        out: dict[str, str] = {}
        while pos < end:
            (k,) = struct.unpack_from("<I", body, pos)
            key = body[pos + 4 : pos + 4 + k].decode("utf-8", "replace")
            pos += 4 + k
            (v,) = struct.unpack_from("<I", body, pos)
            out[key] = body[pos + 4 : pos + 4 + v].decode("utf-8", "replace")
            pos += 4 + v
        self.metadata[name] = out

    def records(self, data: bytes, pos: int, end: int) -> None:
        """Every record in data[pos:end] (the inside of a chunk), message fields vectorised."""
        positions: list[int] = []
        app = positions.append
        q = _U64
        while pos < end:
            if pos + 9 > end:
                raise ValueError("chunk ends inside a record header")
            app(pos)
            pos += 9 + q(data, pos + 1)[0]
        if pos > end:
            raise ValueError("chunk record runs past the chunk")
        if not positions:
            return
        arr = np.frombuffer(data, np.uint8)
        at = np.asarray(positions, np.int64)
        ops = arr[at]
        lens = _gather(arr, at + 1, 8, "<u8").astype(np.int64)
        for i in np.flatnonzero(ops == OP_CHANNEL).tolist():
            self.channel(data[at[i] + 9 : at[i] + 9 + lens[i]])
        for i in np.flatnonzero(ops == OP_SCHEMA).tolist():
            self.schema(data[at[i] + 9 : at[i] + 9 + lens[i]])
        msg = np.flatnonzero(ops == OP_MESSAGE)
        if len(msg) == 0:
            return
        pm = at[msg]
        if (lens[msg] < 22).any():
            raise ValueError("message record too short")
        cid = _gather(arr, pm + 9, 2, "<u2")
        log_time = _gather(arr, pm + 15, 8, "<u8").astype(np.int64)
        order = self.count + np.arange(len(msg), dtype=np.int64)
        self.count += len(msg)
        base = self.size
        kept = False
        for c in np.unique(cid).tolist():
            sel = cid == c
            ch = self.channels.get(c)
            if ch is None:
                continue
            topic = ch[0]
            n = int(sel.sum())
            self.topics[topic] = self.topics.get(topic, 0) + n
            d = RAW_TOPICS.get(topic)
            if d is not None:
                self.spans[d].append((base + pm[sel] + 31, lens[msg][sel] - 22,
                                      log_time[sel], order[sel]))
                kept = True
                if ch[1] != "json":
                    self.raw_encoded[d] = True
            elif topic == TOPIC_LINK:
                for p, ln, lt in zip(pm[sel].tolist(), lens[msg][sel].tolist(),
                                     log_time[sel].tolist(), strict=True):
                    self._link(data[p + 31 : p + 9 + ln], lt)
        if kept:
            self.buffers.append(arr)
            self.size += len(arr)
            if self.size >= BATCH_BYTES:
                self.flush()

    def flush(self) -> None:
        """Decode the raw payloads of the chunks read so far and let their bytes go."""
        if not self.buffers:
            return
        big = np.concatenate(self.buffers) if len(self.buffers) > 1 else self.buffers[0]
        found: list[np.ndarray] = []

        def marks() -> list[np.ndarray]:  # quotes and commas, found once if needed
            if not found:
                found.extend((np.flatnonzero(big == ord('"')), np.flatnonzero(big == ord(","))))
            return found

        assert self.status is not None
        for d in ("host", "unit"):
            part = _parse_payloads(d, self, big, marks, self.status)
            if part.chunks:
                self.parts[d].append(part)
            self.spans[d] = []
        self.buffers = []
        self.size = 0

    def _link(self, payload: bytes, log_time: int) -> None:
        try:
            obj = json.loads(payload)
        except (ValueError, RecursionError):
            obj = None
        t = obj.get("t", log_time / 1e9) if isinstance(obj, dict) else None
        if not isinstance(obj, dict) or not isinstance(obj.get("kind"), str) \
                or not isinstance(t, (int, float)) or isinstance(t, bool) or not np.isfinite(t):
            assert self.status is not None
            self.status.bad_payloads += 1
            return
        obj["t"] = float(t)
        self.link.append(obj)


def _chunk_data(body: bytes) -> bytes:
    # Chunk: start u64, end u64, uncompressed size u64, crc u32, compression str, records str
    _start, _end, usize, crc = struct.unpack_from("<QQQI", body, 0)
    (n,) = struct.unpack_from("<I", body, 28)
    compression = body[32 : 32 + n].decode("ascii", "replace")
    (rlen,) = struct.unpack_from("<Q", body, 32 + n)
    pos = 40 + n
    if pos + rlen > len(body):
        raise ValueError("chunk records run past the record")
    raw = body[pos : pos + rlen]
    return decompress_chunk(compression, raw, usize, crc)


def walk_iter(path: Path, status: ReadStatus, col: _Collector, progress: Progress | None
              ) -> Iterator[None]:
    """Walk the capture's records one at a time (``conform.capture.scan.data_records``): the
    caller takes ``col.parts`` between records."""
    status.path = path
    for pos, op, head, body, in_summary in data_records(status, progress):
        if in_summary or op == OP_FOOTER:
            continue
        try:
            if op == OP_CHUNK:
                try:
                    data = _chunk_data(body)
                    col.records(data, 0, len(data))
                    yield
                except (ValueError, struct.error, zstandard.ZstdError, MemoryError) as exc:
                    status.damaged_chunks += 1
                    status.notes.append(f"damaged chunk at byte {pos} skipped: {exc}")
            elif op == OP_METADATA:
                col.metadata_record(body)
            elif op in (OP_CHANNEL, OP_MESSAGE, OP_SCHEMA):
                col.records(head + body, 0, 9 + len(body))
                yield
        except (ValueError, struct.error, UnicodeDecodeError) as exc:
            status.problem = f"damaged record (opcode 0x{op:02x}) at byte {pos}: {exc}"
            return


_B64 = np.full(256, 255, np.uint8)
for _i, _c in enumerate(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/"):
    _B64[_c] = _i
_B64[ord("=")] = 0


def b64decode_many(chars: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Decode many base64 strings stored back to back (``chars[offsets[i]:offsets[i+1]]``).

    Returns (bytes, lengths). Raises ValueError for anything that is not canonical base64.
    """
    lens = np.diff(offsets)
    if len(lens) == 0:
        return np.zeros(0, np.uint8), np.zeros(0, np.int64)
    if (lens % 4).any():
        raise ValueError("base64 length is not a multiple of 4")
    total = int(offsets[-1] - offsets[0])
    c = chars[int(offsets[0]) : int(offsets[0]) + total]
    vals = _B64[c]
    if (vals == 255).any():
        raise ValueError("not base64")
    pad = np.zeros(len(lens), np.int64)
    ends = offsets[1:] - offsets[0]
    nz = lens > 0
    pad[nz] = (c[ends[nz] - 1] == ord("=")).astype(np.int64) + (c[ends[nz] - 2] == ord("="))
    quads = vals.reshape(-1, 4).astype(np.uint32)
    word = (quads[:, 0] << 18) | (quads[:, 1] << 12) | (quads[:, 2] << 6) | quads[:, 3]
    out = np.empty((len(word), 3), np.uint8)
    out[:, 0] = word >> 16
    out[:, 1] = (word >> 8) & 0xFF
    out[:, 2] = word & 0xFF
    flat = out.reshape(-1)
    out_lens = lens // 4 * 3 - pad
    if pad.any():
        keep = np.ones(len(flat), bool)
        out_ends = np.cumsum(lens // 4 * 3)
        for p in (1, 2):
            sel = pad >= p
            keep[out_ends[sel] - p] = False
        flat = flat[keep]
    return flat, out_lens


def _parse_payloads(name: str, col: _Collector, big: np.ndarray,
                    marks: Callable[[], list[np.ndarray]], status: ReadStatus) -> Direction:
    spans = col.spans[name]
    if not spans:
        return Direction.empty(name)
    starts = np.concatenate([s[0] for s in spans])
    lens = np.concatenate([s[1] for s in spans])
    times = np.concatenate([s[2] for s in spans]) / 1e9
    orders = np.concatenate([s[3] for s in spans])

    def payloads() -> list[bytes]:
        return [big[a : a + n].tobytes() for a, n in zip(starts.tolist(), lens.tolist(),
                                                          strict=True)]

    if col.raw_encoded[name]:
        return _raw_direction(name, payloads(), times, orders)
    v1 = b'{"direction":"%s","data":"' % name.encode()
    if big[starts[0] : starts[0] + len(v1)].tobytes() == v1:  # format 1, conform's layout
        try:
            return _fast_json(name, big, starts, lens, times, orders, *marks())
        except ValueError:
            pass
    pl = payloads()
    batch = [b'"reads"' in p for p in pl]
    if any(batch):  # format 2; a format-1 payload among batches is not readable
        status.bad_payloads += len(batch) - sum(batch)
        return _batch_direction(name, [p for p, b in zip(pl, batch, strict=True) if b], status)
    try:
        return _bulk_json(name, pl, times, orders)
    except (ValueError, KeyError, TypeError, ImportError):
        return _slow_json(name, pl, times, orders, status)


def _tail_values(big: np.ndarray, commas: np.ndarray, ends: np.ndarray,
                 keys: tuple[bytes, ...], want: tuple[int, ...], width: int = 24
                 ) -> list[np.ndarray]:
    """Numbers of the last fields of every payload (``,"key":number`` … ``}``) as float64.

    conform's payloads end with ``"offset":N,"t_read":X,"t_first":X,"seq":N}``; the fields
    are found from the last commas, so the free text before them cannot confuse the search.
    Only the fields whose index is in ``want`` are converted.
    """
    k = np.searchsorted(commas, ends)  # index of the first comma at or after each end
    out = []
    cols = np.arange(width)
    for j, key in enumerate(keys):
        ci = k - (len(keys) - j)
        if (ci < 0).any():
            raise ValueError("too few fields")
        c = commas[ci]
        pat = np.frombuffer(b"," + key, np.uint8)
        if j not in want:  # a delimiter only: its first letters are proof enough
            if not ((big[c + 1] == pat[1]) & (big[c + 2] == pat[2])).all():
                raise ValueError(f"{key!r} not where expected")
            continue
        idx = np.minimum(c[:, None] + np.arange(len(pat)), len(big) - 1)
        if not (big[idx] == pat).all():
            raise ValueError(f"{key!r} not where expected")
        vs = c + len(pat)
        nxt = commas[ci + 1] if j + 1 < len(keys) else ends - 1
        n = nxt - vs
        if (n <= 0).any() or (n > width).any():
            raise ValueError(f"{key!r}: bad value")
        win = big[np.minimum(vs[:, None] + cols, len(big) - 1)]
        out.append(_numbers(win, n))
    return out


def _numbers(win: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Parse plain decimal numbers (digits, one optional point) held in byte windows."""
    width = win.shape[1]
    valid = np.arange(width)[None, :] < n[:, None]
    dot = (win == ord(".")) & valid
    digit = (win >= ord("0")) & (win <= ord("9")) & valid
    if not ((digit | dot) == valid).all() or (dot.sum(axis=1) > 1).any():
        w = win.copy()
        w[~valid] = 0
        return w.view(f"S{width}").ravel().astype(float)  # signs, exponents: the slow way
    has_dot = dot.any(axis=1)
    dpos = np.where(has_dot, dot.argmax(axis=1), n)
    d = win.astype(np.float64) - ord("0")
    d[~digit] = 0.0
    out = np.empty(len(n))
    col = np.arange(width)
    for p in np.unique(dpos).tolist():  # usually one or two point positions: one matmul each
        sel = dpos == p
        powers = np.where(col < p, 10.0 ** (p - 1 - col), 10.0 ** -(col - p).clip(1, 300))
        powers[col == p] = 0.0
        out[sel] = d[sel] @ powers
    return out


def _fast_json(name: str, big: np.ndarray, starts: np.ndarray, lens: np.ndarray,
               times: np.ndarray, orders: np.ndarray, quotes: np.ndarray,
               commas: np.ndarray) -> Direction:
    """conform's own payloads (json.dumps, keys in schema order) without a JSON parser."""
    prefix = np.frombuffer(b'{"direction":"%s","data":"' % name.encode(), np.uint8)
    if (lens <= len(prefix)).any():
        raise ValueError("short payload")
    head = big[starts[:, None] + np.arange(len(prefix))]
    if not (head == prefix).all():
        raise ValueError("not conform's layout")
    ends = starts + lens
    ds = starts + len(prefix)
    k = np.searchsorted(quotes, ds)
    if (k >= len(quotes)).any():
        raise ValueError("unterminated data")
    de = quotes[k]
    if (de >= ends).any():
        raise ValueError("unterminated data")
    n = de - ds
    total = int(n.sum())
    rel = np.repeat(ds - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    chars = big[np.arange(total) + rel]
    data, out_lens = b64decode_many(chars, np.concatenate([[0], np.cumsum(n)]))
    if (big[ends - 1] != ord("}")).any():
        raise ValueError("payload does not end with }")
    off, t_first = _tail_values(
        big, commas, ends, (b'"offset":', b'"t_read":', b'"t_first":', b'"seq":'), (0, 2))
    offset = off.astype(np.int64)
    t_read = times  # the message's log time is the read time (to the nanosecond)
    start = np.concatenate([[0], np.cumsum(out_lens)[:-1]]).astype(np.int64)
    return Direction(name, data, start, out_lens.astype(np.int64), offset, t_read, t_first,
                     orders)


def _batch_direction(name: str, payloads: list[bytes], status: ReadStatus) -> Direction:
    """Format 2: each message a batch of reads (``conform.RawBatch``), bytes stored once."""
    from conform.capture.batch import unbatch_arrays

    parts = []
    for raw in payloads:
        try:
            parts.append(unbatch_arrays(raw))
        except ValueError:
            status.bad_payloads += 1
    if not parts:
        return Direction.empty(name)
    data = np.frombuffer(b"".join(p[0] for p in parts), np.uint8)
    lens = np.concatenate([p[1] for p in parts])
    start = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)
    offset = np.concatenate([p[2] + np.concatenate([[0], np.cumsum(p[1])[:-1]])
                             for p in parts]).astype(np.int64)
    return Direction(name, data, start, lens, offset, *(np.concatenate([p[k] for p in parts])
                                                        for k in (3, 4, 5)))


def _raw_direction(name: str, payloads: list[bytes], times: np.ndarray,
                   orders: np.ndarray) -> Direction:
    """A foreign capture whose raw channel carries the bytes themselves."""
    lens = np.fromiter((len(p) for p in payloads), np.int64, len(payloads))
    data = np.frombuffer(b"".join(payloads), np.uint8)
    start = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)
    return Direction(name, data, start, lens, np.full(len(lens), -1, np.int64), times,
                     np.full(len(lens), np.nan), orders)


def _bulk_json(name: str, payloads: list[bytes], times: np.ndarray,
               orders: np.ndarray) -> Direction:
    import pyarrow as pa
    import pyarrow.json as pj

    schema = pa.schema([("data", pa.string()), ("offset", pa.int64()),
                        ("t_read", pa.float64()), ("t_first", pa.float64())])
    # pyarrow's reader must only ever see one JSON object per line: a payload such as
    # ``null`` makes it crash the process, so anything else goes the slow, careful way
    if not all(p[:1] == b"{" and p[-1:] == b"}" for p in payloads):
        raise ValueError("not one JSON object per payload")
    blob = b"\n".join(payloads)
    if blob.count(b"\n") != len(payloads) - 1:
        raise ValueError("multi-line JSON")
    opts = pj.ParseOptions(explicit_schema=schema, unexpected_field_behavior="ignore")
    table = pj.read_json(io.BytesIO(blob), parse_options=opts,
                         read_options=pj.ReadOptions(block_size=1 << 24))
    if table.num_rows != len(payloads):
        raise ValueError("row count")
    col = table.column("data").combine_chunks()
    if col.null_count:
        raise ValueError("missing data")
    offs = np.frombuffer(col.buffers()[1], np.int32, len(col) + 1, col.offset * 4)
    chars = np.frombuffer(col.buffers()[2], np.uint8)
    data, lens = b64decode_many(chars, offs.astype(np.int64))
    start = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)

    def num(colname: str, fill: float) -> np.ndarray:
        return table.column(colname).to_numpy(zero_copy_only=False).astype(float)

    t_read = num("t_read", np.nan)
    t_read = np.where(np.isnan(t_read), times, t_read)
    t_first = num("t_first", np.nan)
    offset = table.column("offset").to_numpy(zero_copy_only=False).astype(float)
    offset = np.where(np.isnan(offset), -1, offset).astype(np.int64)
    return Direction(name, data, start, lens.astype(np.int64), offset, t_read, t_first, orders)


def _slow_json(name: str, payloads: list[bytes], times: np.ndarray, orders: np.ndarray,
               status: ReadStatus) -> Direction:
    import base64
    import binascii

    chunks: list[bytes] = []
    keep: list[int] = []
    offset: list[int] = []
    t_read: list[float] = []
    t_first: list[float] = []
    for i, raw in enumerate(payloads):
        try:
            obj = json.loads(raw)
            b = base64.b64decode(obj["data"], validate=True)
        except (ValueError, binascii.Error, TypeError, AttributeError, KeyError, RecursionError):
            status.bad_payloads += 1
            continue
        if not isinstance(obj, dict) or not b:
            status.bad_payloads += 1
            continue
        chunks.append(b)
        keep.append(i)
        offset.append(_num(obj.get("offset"), -1))
        t_read.append(_num(obj.get("t_read"), times[i]))
        t_first.append(_num(obj.get("t_first"), np.nan))
    lens = np.fromiter((len(c) for c in chunks), np.int64, len(chunks))
    start = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)
    return Direction(name, np.frombuffer(b"".join(chunks), np.uint8), start, lens,
                     np.asarray(offset, np.int64), np.asarray(t_read, float),
                     np.asarray(t_first, float), orders[np.asarray(keep, np.int64)])


def _num(value: Any, default: float) -> Any:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value) < 2**62
    return value if ok else default


def _merge(name: str, parts: list[Direction]) -> Direction:
    if not parts:
        return Direction.empty(name)
    if len(parts) == 1:
        return parts[0]
    shift = np.cumsum([0] + [len(p.data) for p in parts[:-1]])
    return Direction(
        name, np.concatenate([p.data for p in parts]),
        np.concatenate([p.start + k for p, k in zip(parts, shift, strict=True)]),
        *(np.concatenate([getattr(p, f) for p in parts])
          for f in ("length", "offset", "t_read", "t_first", "order")))


MAX_TIME = 1e11  # seconds since the epoch (the year 5138): later is not a time
