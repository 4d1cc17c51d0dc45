"""Decode recorded bytes into frames (commands, answers) and pair them into exchanges.

A passive observer of the wire, built on the protocol codec: it splits each direction into
lines (keeping each line's byte offset and estimated first-byte time), parses host lines
with ``CommandParser`` and unit lines with ``parse_answer``, follows the checksum mode
(``%+``/``%-``, and ``J`` resets it) and packets (``*S`` .. ``*E<n>``: one answer, after the
end), and pairs each command owed an answer with the next answer line. The protocol is
simplex, so a command sent while an earlier one is still unanswered means the sender gave
up on the earlier one: that one becomes an ``unanswered`` exchange. Lines the unit would
ignore (another unit's address, garbage; ``Rejection.code`` is None) are owed no answer.

When a capture starts mid-session with checksums already on, the first command that only
parses with a valid checksum switches the mode on (shown in ``checksum_mode``); once a ``%``
or ``J`` has been seen the mode is known and only they change it.

The recorder decodes as it records, thousands of lines a second, so the hot path works on
plain tuples: a frame or an exchange is one tuple in the order of ``FRAME_KEYS`` /
``EXCHANGE_KEYS`` (``feed_rows`` / ``take_rows``), which the recorder turns into the columns
of a batch without ever building a dict per line. What a line decodes to depends only on
its bytes and the checksum mode, and traffic repeats (``0`` answers, polls, the same
moves), so those results are kept per distinct line in a bounded cache.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, NamedTuple

from conform.capture.merge import HostLines
from conform.capture.schemas import TOPIC_EXCHANGES, TOPIC_FRAMES
from conform.capture.session import Record, escape_bytes, to_ns
from conform.families.gve.capture_fields import CAPTURE_FIELDS, EXCHANGE_KEYS, FRAME_KEYS
from conform.families.gve.protocol import Answer, Command, CommandParser, Rejection, parse_answer
from conform.families.gve.protocol.checksum import split_checksum, verify
from conform.families.gve.spec import Dialect, Variant, load_spec

_PACKET_START = re.compile(rb"^!\d\*S")
_PACKET_END = re.compile(rb"^!\d\*E")
Item = tuple[str, float, dict[str, Any]]  # (topic, time in seconds, payload)
Span = tuple[bytes, int, int, float]  # a line: bytes without terminator, offset, length, t_first
Row = tuple[Any, ...]  # a frame or an exchange, its fields in FRAME_KEYS / EXCHANGE_KEYS order
MAX_LINE = 4096  # a "line" longer than this is noise: cut it so memory stays bounded
CACHE_LINES = 4096  # distinct lines whose decoding is kept (per checksum state)


@dataclass
class Line:
    direction: str
    data: bytes  # without the terminator
    offset: int  # stream offset of the first byte
    length: int  # bytes including the terminator
    t_first: float
    t_last: float


class LineTracker:
    """Split one direction into lines with offsets and times (A1 terminator modes)."""

    def __init__(self, direction: str, mode: str = "cr") -> None:
        if mode not in ("cr", "cr-or-lf", "crlf"):
            raise ValueError(f"unknown terminator mode {mode!r}")
        self.direction = direction
        self.mode = mode
        self._buf = bytearray()
        self._start = 0  # offset of the first byte in _buf
        self._t_start: float | None = None
        self._pending_cr = False  # crlf mode: a CR waiting for its LF

    @property
    def partial(self) -> bytes:
        return bytes(self._buf)

    def feed(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Line]:
        if self.mode == "cr":
            return self._feed_cr(data, offset, t_read, t_first)
        return self._feed_bytes(data, offset, t_read, t_first)

    def spans(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Span]:
        """The lines ``data`` completes as (bytes, offset, length, t_first); each one's
        ``t_last`` is ``t_read`` (the recorder's hot path: no object per line)."""
        if self.mode == "cr":
            return self._spans_cr(data, offset, t_read, t_first)
        return [(ln.data, ln.offset, ln.length, ln.t_first)
                for ln in self._feed_bytes(data, offset, t_read, t_first)]

    def _feed_cr(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Line]:
        d = self.direction
        return [Line(d, b, o, n, t0, t_read)
                for b, o, n, t0 in self._spans_cr(data, offset, t_read, t_first)]

    def _spans_cr(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Span]:
        """CR-terminated lines, split in C (``bytes.split``); a chunk that could hold a
        line longer than ``MAX_LINE`` goes through ``_cut_cr``, which cuts it."""
        n = len(data)
        if not n:
            return []
        buf = self._buf
        parts = data.split(b"\r")
        if len(buf) + max(map(len, parts)) > MAX_LINE:
            return [(ln.data, ln.offset, ln.length, ln.t_first)
                    for ln in self._cut_cr(data, offset, t_read, t_first)]
        per_byte = (t_read - t_first) / n
        tail = parts.pop()  # the bytes after the last CR (b"" if data ends with one)
        out: list[Span] = []
        pos = 0
        if buf and parts:  # the line carried over from the previous read ends here
            head = parts[0]
            out.append((bytes(buf) + head, self._start, len(buf) + len(head) + 1,
                        self._t_start))  # type: ignore[arg-type]
            buf.clear()
            self._t_start = None
            pos = len(head) + 1
            parts = parts[1:]
        elif buf:  # no CR: the carried-over line goes on
            buf += tail
            return out
        for part in parts:
            start = pos
            pos += len(part) + 1
            if part[:1] == b"\n":  # an LF outside a line is ignored
                line = part.lstrip(b"\n")
                start += len(part) - len(line)
                part = line
            t0 = t_first + start * per_byte
            out.append((part, offset + start, len(part) + 1, t0 if t0 < t_read else t_read))
        if tail[:1] == b"\n":
            line = tail.lstrip(b"\n")
            pos += len(tail) - len(line)
            tail = line
        if tail:
            buf += tail
            self._start = offset + pos
            self._t_start = min(t_read, t_first + pos * per_byte)
        return out

    def _cut_cr(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Line]:
        """CR-terminated lines, cutting noise at ``MAX_LINE`` + 1 bytes."""
        lines: list[Line] = []
        n = len(data)
        per_byte = (t_read - t_first) / n if n else 0.0
        buf = self._buf
        i = 0
        while i < n:
            if not buf and self._t_start is None:
                while i < n and data[i] == 0x0A:  # an LF outside a line is ignored
                    i += 1
                if i == n:
                    break
                self._start = offset + i
                self._t_start = min(t_read, t_first + i * per_byte)
            j = data.find(b"\r", i)
            end = n if j < 0 else j
            if len(buf) + end - i > MAX_LINE:  # noise: cut at MAX_LINE + 1 bytes
                take = MAX_LINE + 1 - len(buf)
                buf += data[i : i + take]
                lines.append(self._take(offset + i + take - 1, t_read))
                i += take
                continue
            buf += data[i:end]
            if j < 0:
                break
            lines.append(self._take(offset + j, t_read))
            i = j + 1
        return lines

    def _feed_bytes(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Line]:
        lines: list[Line] = []
        per_byte = (t_read - t_first) / len(data) if data else 0.0
        for i, b in enumerate(data):
            pos = offset + i
            t_byte = min(t_read, t_first + i * per_byte)
            if not self._buf and self._t_start is None:
                self._start = pos
                self._t_start = t_byte
            end = False
            if self.mode == "cr":
                if b == 0x0D:
                    end = True
                elif b == 0x0A and not self._buf:
                    self._t_start = None  # an LF outside a line is ignored
                    continue
            elif self.mode == "cr-or-lf":
                if b in (0x0D, 0x0A):
                    if not self._buf:
                        self._t_start = None  # empty line: dropped
                        continue
                    end = True
            else:  # crlf
                if self._pending_cr:
                    self._pending_cr = False
                    if b == 0x0A:
                        end = True
                    else:
                        self._buf.append(0x0D)
                if not end and b == 0x0D:
                    self._pending_cr = True
                    continue
            if end:
                lines.append(self._take(pos, t_read))
                continue
            self._buf.append(b)
            if len(self._buf) > MAX_LINE:
                lines.append(self._take(pos, t_read))
        return lines

    def _take(self, pos: int, t_read: float) -> Line:
        """The line that ends at stream offset ``pos``; the buffer starts afresh."""
        assert self._t_start is not None
        line = Line(self.direction, bytes(self._buf), self._start, pos + 1 - self._start,
                    self._t_start, t_read)
        self._buf.clear()
        self._t_start = None
        return line

    def rest(self, t: float) -> Line | None:
        """The unterminated tail, if any (end of capture)."""
        if not self._buf or self._t_start is None:
            return None
        return Line(self.direction, bytes(self._buf), self._start, len(self._buf),
                    self._t_start, t)


_PLAIN = frozenset((bool, int, float, str, type(None)))


def _jsonable(value: Any) -> Any:
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, bytes):
        return escape_bytes(value)
    return str(value)


class _Owed(NamedTuple):
    """A command waiting for its answer (the protocol is simplex: at most one)."""

    name: str | None
    text: str
    offset: int
    t_last: float
    packet: int | None
    packet_commands: int | None
    checksum_after: bool | None  # the mode a '%' command switches to if accepted
    resets: bool  # J: checksums off after the answer


class _HostLine:
    """What a host line decodes to in one checksum state (cached per distinct line)."""

    __slots__ = ("kind", "text", "address", "name", "args", "code", "checksum", "status",
                 "error", "starts_packet", "ends_packet", "checksum_after", "resets", "silent")


class _UnitLine:
    """What a unit line decodes to with or without a checksum (cached per distinct line)."""

    __slots__ = ("kind", "text", "code", "inta", "fields", "checksum", "status", "error",
                 "is_answer", "bang")


_EMPTY: list[Any] = []  # the args/fields of a frame without any (shared: never mutated)


class FrameDecoder:
    """Feed raw chunks in capture order; get ``/frames`` and ``/exchanges`` records.

    ``feed_rows``/``finish_rows`` collect frames and exchanges as tuples (see the module
    docstring) until ``take_rows``; ``feed``/``feed_items``/``finish`` return them one by one
    as records or dicts.
    """

    fields = CAPTURE_FIELDS  # the capture columns of its rows, after the neutral ones

    def __init__(self, variant: Variant, dialect: Dialect | None = None) -> None:
        spec = load_spec()
        self.dialect = dialect if dialect is not None else spec.dialect()
        self.parser = CommandParser(variant, self.dialect)
        mode = self.dialect["A1"]
        self.lines = {"host": LineTracker("host", mode), "unit": LineTracker("unit", mode)}
        self.checksum_on = False
        self.mode_known = False  # until a '%' or 'J' is seen, checksums may already be on
        self.packet_id = 0
        self.in_packet = False
        self.packet_members = 0
        self.owed: _Owed | None = None
        # decoded lines per (checksum on, mode known) for the host, per checksum for the unit
        self._host_cache: dict[tuple[bool, bool], dict[bytes, _HostLine]] = {}
        self._unit_cache: dict[bool, dict[bytes, _UnitLine]] = {False: {}, True: {}}
        self.frame_rows: list[Row] = []
        self.exchange_rows: list[Row] = []
        self.t_rows: float | None = None  # time of the first frame or exchange collected
        self._items: list[Item] | None = None  # set while feed_items collects dicts

    # -- entry points ----------------------------------------------------------------------
    def feed_rows(self, direction: str, data: bytes, offset: int, t_read: float,
                  t_first: float) -> None:
        """Decode one read; its frames and exchanges wait in ``frame_rows``/``exchange_rows``."""
        spans = self.lines[direction].spans(data, offset, t_read, t_first)
        if not spans:
            return
        if direction == "host":
            for span in spans:
                self._command(span, t_read)
        else:
            for span in spans:
                self._answer(span, t_read)

    def finish_rows(self, t: float) -> None:
        """The unterminated tails and the command still waiting, into the rows."""
        for tracker in self.lines.values():
            line = tracker.rest(t)
            if line is not None:
                self._frame((line.direction, "garbled", escape_bytes(line.data), line.offset,
                             line.length, line.t_first, line.t_last, None, None, _EMPTY, None,
                             None, _EMPTY, None, "none", self.checksum_on, None, None,
                             "unterminated line at the end of the capture"), line.t_last)
        if self.owed is not None:
            self._unanswered()

    def take_rows(self) -> tuple[float | None, list[Row], list[Row]]:
        """(time of the first item, frames, exchanges) collected since the last call."""
        out = (self.t_rows, self.frame_rows, self.exchange_rows)
        self.frame_rows, self.exchange_rows, self.t_rows = [], [], None
        return out

    def feed(self, direction: str, data: bytes, offset: int, t_read: float,
             t_first: float) -> list[Record]:
        return [Record(topic, to_ns(t), payload)
                for topic, t, payload in self.feed_items(direction, data, offset, t_read, t_first)]

    def finish(self, t: float) -> list[Record]:
        return [Record(topic, to_ns(t), payload) for topic, t, payload in self.finish_items(t)]

    def feed_items(self, direction: str, data: bytes, offset: int, t_read: float,
                   t_first: float) -> list[Item]:
        """Like ``feed``, as plain (topic, time in seconds, payload) tuples."""
        self._items = items = []
        try:
            self.feed_rows(direction, data, offset, t_read, t_first)
        finally:
            self._items = None
        return items

    def finish_items(self, t: float) -> list[Item]:
        self._items = items = []
        try:
            self.finish_rows(t)
        finally:
            self._items = None
        return items

    # -- output ----------------------------------------------------------------------------
    def _frame(self, row: Row, t: float) -> None:
        if self._items is not None:
            frame = dict(zip(FRAME_KEYS, row, strict=True))
            frame["args"], frame["fields"] = list(frame["args"]), list(frame["fields"])
            self._items.append((TOPIC_FRAMES, t, frame))
            return
        if self.t_rows is None:
            self.t_rows = t
        self.frame_rows.append(row)

    def _exchange(self, row: Row, t: float) -> None:
        if self._items is not None:
            self._items.append((TOPIC_EXCHANGES, t, dict(zip(EXCHANGE_KEYS, row, strict=True))))
            return
        if self.t_rows is None:
            self.t_rows = t
        self.exchange_rows.append(row)

    def _unanswered(self) -> None:
        """The waiting command as an ``unanswered`` exchange."""
        o = self.owed
        assert o is not None
        self.owed = None
        self._exchange(("unanswered", o.text, None, o.t_last, None, None, o.offset, None,
                        o.name, None, None, o.packet, o.packet_commands), o.t_last)

    # -- host side -------------------------------------------------------------------------
    def _parse_command(self, raw: bytes) -> Command | Rejection:
        result = self.parser.parse(raw, self.checksum_on)
        if isinstance(result, Rejection) and not self.mode_known and not self.checksum_on \
                and verify(raw):
            # a capture that starts mid-session with checksums already on
            other = self.parser.parse(raw, True)
            if isinstance(other, Command):
                self.checksum_on = self.mode_known = True
                return other
        return result

    def _decode_command(self, raw: bytes) -> _HostLine:
        """Parse a host line in the current checksum state (may switch checksums on)."""
        result = self._parse_command(raw)
        h = _HostLine()
        h.kind = "command" if isinstance(result, Command) else "rejection"
        h.text = escape_bytes(raw)
        h.address, h.name = result.address, result.name
        h.checksum, h.status = None, "none"
        if self.checksum_on:
            _, value = split_checksum(raw)
            h.checksum = f"{value:02X}" if value is not None else None
            if isinstance(result, Rejection) and result.kind == "checksum":
                h.status = "missing" if value is None else "bad"
            elif value is not None:
                h.status = "ok" if verify(raw) else "bad"
            else:
                h.status = "missing"
        h.checksum_after, h.resets, h.silent = None, False, False
        if isinstance(result, Command):
            args = result.args
            if not args:
                h.args = _EMPTY
            elif _PLAIN.issuperset(map(type, args)):  # numbers and letters: as they are
                h.args = list(args)
            else:
                h.args = [_jsonable(a) for a in args]
            h.code = h.error = None
            if result.name == "%":
                h.checksum_after = result.args[0] == "+"
            h.resets = result.name == "J"
            h.starts_packet, h.ends_packet = result.name == "*S", result.name == "*E"
        else:
            h.args = _EMPTY
            h.code = result.code
            h.error = f"{result.kind}: {result.detail}"
            h.starts_packet = False
            # a damaged *E still ends the packet; the unit answers it (with an error)
            h.ends_packet = _PACKET_END.match(raw) is not None
            h.silent = result.code is None
        return h

    def _command(self, span: Span, t_last: float) -> None:
        raw, offset, length, t_first = span
        key = (self.checksum_on, self.mode_known)
        cache = self._host_cache.get(key)
        if cache is None:
            cache = self._host_cache[key] = {}
        h = cache.get(raw)
        if h is None:
            if len(cache) >= CACHE_LINES:
                cache.clear()
            # a line that switches checksums on (mode unknown) is cached under a state that
            # never comes back: once switched, the mode is known
            h = cache[raw] = self._decode_command(raw)
        owed = True
        packet = role = packet_commands = None
        if h.starts_packet:
            self.packet_id += 1
            self.in_packet, self.packet_members = True, 0
            packet, role = self.packet_id, "start"
            owed = False
        elif self.in_packet:
            packet = self.packet_id
            if h.ends_packet:
                self.in_packet = False
                role, packet_commands = "end", self.packet_members
            else:
                self.packet_members += 1
                role = "member"
                owed = False
        elif h.silent:
            owed = False  # the unit stays silent (another address, not a command)
        self._frame(("host", h.kind, h.text, offset, length, t_first, t_last, h.address, h.name,
                     h.args, h.code, None, _EMPTY, h.checksum, h.status, self.checksum_on,
                     packet, role, h.error), t_last)
        if owed:
            if self.owed is not None:  # simplex: the sender gave up waiting for it
                self._unanswered()
            in_packet = role is not None
            self.owed = _Owed(h.name, h.text, offset, t_last, packet, packet_commands,
                              None if in_packet else h.checksum_after,
                              False if in_packet else h.resets)

    # -- unit side -------------------------------------------------------------------------
    def _decode_answer(self, raw: bytes, with_sum: bool) -> _UnitLine:
        parsed = parse_answer(raw, with_sum)
        u = _UnitLine()
        u.text = escape_bytes(raw)
        u.bang = raw[:1] == b"!"
        u.is_answer = isinstance(parsed, Answer)
        u.checksum, u.status = None, "none"
        if isinstance(parsed, Answer):
            u.kind, u.error = "answer", None
            u.code, u.inta = parsed.code, parsed.inta
            u.fields = list(parsed.fields) if parsed.fields else _EMPTY
            if parsed.checksum is not None:
                u.checksum = f"{parsed.checksum:02X}"
            if parsed.checksum_ok is None:
                u.status = "none"
            elif parsed.checksum_ok:
                u.status = "ok"
            else:
                u.status = "missing" if parsed.checksum is None else "bad"
        else:
            u.kind, u.error = "garbled", parsed.detail
            u.code = u.inta = None
            u.fields = _EMPTY
        return u

    def _answer(self, span: Span, t_last: float) -> None:
        raw, offset, length, t_first = span
        o = self.owed
        if o is not None and o.name == ">" and raw[:1] == b"!":
            # `>` first sends the line it repeats (A9), then that line's answer
            self._frame(("unit", "echo", escape_bytes(raw), offset, length, t_first, t_last,
                         None, None, _EMPTY, None, None, _EMPTY, None, "none", self.checksum_on,
                         None, None, None), t_last)
            return
        self.owed = None
        with_sum = self.checksum_on
        if o is not None and o.checksum_after is not None:
            with_sum = o.checksum_after  # the answer to %+ already carries one
        cache = self._unit_cache[with_sum]
        u = cache.get(raw)
        if u is None:
            if len(cache) >= CACHE_LINES:  # answers repeat ("0"); keep the cache bounded
                cache.clear()
            u = cache[raw] = self._decode_answer(raw, with_sum)
        packet = role = None
        if o is not None:
            if u.code == 0 and u.is_answer:
                if o.checksum_after is not None:
                    self.checksum_on = o.checksum_after
                    self.mode_known = True
                if o.resets:
                    self.checksum_on = False
                    self.mode_known = True
            if o.packet is not None:
                packet, role = o.packet, "answer"
        self._frame(("unit", u.kind, u.text, offset, length, t_first, t_last, None, None,
                     _EMPTY, u.code, u.inta, u.fields, u.checksum, u.status, with_sum, packet,
                     role, u.error), t_last)
        if o is None:
            self._exchange(("unsolicited", None, u.text, None, t_first, None, None, offset,
                            None, u.code, u.inta, None, None), t_last)
        else:
            self._exchange(("answered", o.text, u.text, o.t_last, t_first, t_first - o.t_last,
                            o.offset, offset, o.name, u.code, u.inta, o.packet,
                            o.packet_commands), t_last)


class PacketLines(HostLines):
    """The sniffer's merge (``conform.capture.merge``) counting GVE's owed answers: a
    packet's ``*S`` and members owe none, its ``*E`` one (GVE64 §13.3.3)."""

    def __init__(self) -> None:
        super().__init__()
        self.in_packet = False

    def owes(self, line: bytes) -> int:
        if _PACKET_START.match(line):
            self.in_packet = True
            return 0
        if self.in_packet:
            if _PACKET_END.match(line):
                self.in_packet = False
                return 1
            return 0
        return 1


def make_decoder(variant: str | Variant, *, baud: int | None = None,
                 dialect: Dialect | None = None) -> FrameDecoder:
    """A decoder for a variant id such as ``"gve64-v19"`` (``UserError`` if unknown)."""
    v = load_spec().variant(variant) if isinstance(variant, str) else variant
    return FrameDecoder(v, dialect)
