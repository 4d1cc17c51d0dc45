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
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from conform.capture.schemas import TOPIC_EXCHANGES, TOPIC_FRAMES
from conform.capture.session import Record, escape_bytes, to_ns
from conform.families.gve.protocol import Answer, Command, CommandParser, Garbled, Rejection, parse_answer
from conform.families.gve.protocol.checksum import split_checksum, verify
from conform.families.gve.spec import Dialect, Variant, load_spec

_PACKET_END = re.compile(rb"^!\d\*E")
Item = tuple[str, float, dict[str, Any]]  # (topic, time in seconds, payload)
MAX_LINE = 4096  # a "line" longer than this is noise: cut it so memory stays bounded


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

    def _feed_cr(self, data: bytes, offset: int, t_read: float, t_first: float) -> list[Line]:
        """CR-terminated lines, a whole run of bytes at a time (the recorder's hot path)."""
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


def _jsonable(value: Any) -> Any:
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, bytes):
        return escape_bytes(value)
    return str(value)


@dataclass
class _Pending:
    frame: dict[str, Any]
    t_last: float
    packet: int | None
    packet_commands: int | None
    checksum_after: bool | None  # the mode a '%' command switches to if accepted
    resets: bool  # J: checksums off after the answer


class FrameDecoder:
    """Feed raw chunks in capture order; get ``/frames`` and ``/exchanges`` records."""

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
        self.pending: list[_Pending] = []
        self.answer_packet: tuple[int, int] | None = None
        self._answers: dict[tuple[bytes, bool], Answer | Garbled] = {}

    # -- entry points (the session's Decoder protocol) ------------------------------------
    def feed(self, direction: str, data: bytes, offset: int, t_read: float,
             t_first: float) -> list[Record]:
        return [Record(topic, to_ns(t), payload)
                for topic, t, payload in self.feed_items(direction, data, offset, t_read, t_first)]

    def finish(self, t: float) -> list[Record]:
        return [Record(topic, to_ns(t), payload) for topic, t, payload in self.finish_items(t)]

    def feed_items(self, direction: str, data: bytes, offset: int, t_read: float,
                   t_first: float) -> list[Item]:
        """Like ``feed``, as plain (topic, time in seconds, payload) tuples (the fast path)."""
        out: list[Item] = []
        decode = self._command if direction == "host" else self._answer
        for line in self.lines[direction].feed(data, offset, t_read, t_first):
            out.extend(decode(line))
        return out

    def finish_items(self, t: float) -> list[Item]:
        out: list[Item] = []
        for tracker in self.lines.values():
            line = tracker.rest(t)
            if line is not None:
                frame = self._base(line, "garbled")
                frame["error"] = "unterminated line at the end of the capture"
                out.append((TOPIC_FRAMES, line.t_last, frame))
        while self.pending:
            out.append(self._exchange_unanswered(self.pending.pop(0)))
        return out

    # -- host side -------------------------------------------------------------------------
    def _base(self, line: Line, kind: str) -> dict[str, Any]:
        return {
            "direction": line.direction, "kind": kind, "text": escape_bytes(line.data),
            "offset": line.offset, "length": line.length, "t_first": line.t_first,
            "t_last": line.t_last, "address": None, "name": None, "args": [], "code": None,
            "inta": None, "fields": [], "checksum": None, "checksum_status": "none",
            "checksum_mode": self.checksum_on, "packet": None, "packet_role": None,
            "error": None,
        }

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

    def _command(self, line: Line) -> list[Item]:
        out: list[Item] = []
        result = self._parse_command(line.data)
        frame = self._base(line, "command" if isinstance(result, Command) else "rejection")
        frame["checksum_mode"] = self.checksum_on
        if self.checksum_on:
            _, value = split_checksum(line.data)
            frame["checksum"] = f"{value:02X}" if value is not None else None
            if isinstance(result, Rejection) and result.kind == "checksum":
                frame["checksum_status"] = "missing" if value is None else "bad"
            elif value is not None:
                frame["checksum_status"] = "ok" if verify(line.data) else "bad"
            else:
                frame["checksum_status"] = "missing"
        frame["address"] = result.address
        frame["name"] = result.name
        owed = True
        packet_commands: int | None = None
        checksum_after: bool | None = None
        resets = False
        if isinstance(result, Command):
            frame["args"] = [_jsonable(a) for a in result.args]
            if result.name == "*S":
                self.packet_id += 1
                self.in_packet, self.packet_members = True, 0
                frame["packet"], frame["packet_role"] = self.packet_id, "start"
                owed = False
            elif result.name == "*E" and self.in_packet:
                packet_commands = self._packet_end(frame)
            elif self.in_packet:
                self._packet_member(frame)
                owed = False
            elif result.name == "%":
                checksum_after = result.args[0] == "+"
            elif result.name == "J":
                resets = True
        else:
            frame["code"] = result.code
            frame["error"] = f"{result.kind}: {result.detail}"
            if self.in_packet and _PACKET_END.match(line.data):
                # a damaged *E still ends the packet; the unit answers it (with an error)
                packet_commands = self._packet_end(frame)
            elif self.in_packet:
                self._packet_member(frame)
                owed = False
            elif result.code is None:
                owed = False  # the unit stays silent (another address, not a command)
        out.append((TOPIC_FRAMES, line.t_last, frame))
        if owed:
            while self.pending:  # simplex: the sender gave up waiting for these
                out.append(self._exchange_unanswered(self.pending.pop(0)))
            self.pending.append(_Pending(frame, line.t_last, frame["packet"], packet_commands,
                                         checksum_after, resets))
        return out

    def _packet_end(self, frame: dict[str, Any]) -> int:
        """Close the open packet at this frame; the number of lines it held."""
        self.in_packet = False
        frame["packet"], frame["packet_role"] = self.packet_id, "end"
        return self.packet_members

    def _packet_member(self, frame: dict[str, Any]) -> None:
        self.packet_members += 1
        frame["packet"], frame["packet_role"] = self.packet_id, "member"

    # -- unit side -------------------------------------------------------------------------
    def _answer(self, line: Line) -> list[Item]:
        if (self.pending and self.pending[0].frame["name"] == ">" and line.data[:1] == b"!"):
            # `>` first sends the line it repeats (A9), then that line's answer
            frame = self._base(line, "echo")
            return [(TOPIC_FRAMES, line.t_last, frame)]
        pending = self.pending.pop(0) if self.pending else None
        with_sum = self.checksum_on
        if pending is not None and pending.checksum_after is not None:
            with_sum = pending.checksum_after  # the answer to %+ already carries one
        key = (line.data, with_sum)
        parsed = self._answers.get(key)
        if parsed is None:
            if len(self._answers) > 4096:  # answers repeat ("0"); keep the cache bounded
                self._answers.clear()
            parsed = self._answers[key] = parse_answer(line.data, with_sum)
        frame = self._base(line, "answer" if isinstance(parsed, Answer) else "garbled")
        frame["checksum_mode"] = with_sum
        if isinstance(parsed, Answer):
            frame["code"], frame["inta"] = parsed.code, parsed.inta
            frame["fields"] = list(parsed.fields)
            if parsed.checksum is not None:
                frame["checksum"] = f"{parsed.checksum:02X}"
            if parsed.checksum_ok is None:
                frame["checksum_status"] = "none"
            elif parsed.checksum_ok:
                frame["checksum_status"] = "ok"
            else:
                frame["checksum_status"] = "missing" if parsed.checksum is None else "bad"
            if pending is not None and parsed.code == 0:
                if pending.checksum_after is not None:
                    self.checksum_on = pending.checksum_after
                    self.mode_known = True
                if pending.resets:
                    self.checksum_on = False
                    self.mode_known = True
        else:
            frame["error"] = parsed.detail
        if pending is not None and pending.packet is not None:
            frame["packet"], frame["packet_role"] = pending.packet, "answer"
        out = [(TOPIC_FRAMES, line.t_last, frame)]
        out.append(self._exchange(pending, frame, line))
        return out

    # -- exchanges -------------------------------------------------------------------------
    def _exchange(self, pending: _Pending | None, answer: dict[str, Any], line: Line) -> Item:
        if pending is None:
            payload = {
                "status": "unsolicited", "command": None, "name": None,
                "answer": answer["text"], "code": answer["code"], "inta": answer["inta"],
                "t_command": None, "t_answer": line.t_first, "latency": None,
                "command_offset": None, "answer_offset": line.offset, "packet": None,
                "packet_commands": None,
            }
        else:
            cmd = pending.frame
            payload = {
                "status": "answered", "command": cmd["text"], "name": cmd["name"],
                "answer": answer["text"], "code": answer["code"], "inta": answer["inta"],
                "t_command": pending.t_last, "t_answer": line.t_first,
                "latency": line.t_first - pending.t_last,
                "command_offset": cmd["offset"], "answer_offset": line.offset,
                "packet": pending.packet, "packet_commands": pending.packet_commands,
            }
        return (TOPIC_EXCHANGES, line.t_last, payload)

    def _exchange_unanswered(self, pending: _Pending) -> Item:
        cmd = pending.frame
        payload = {
            "status": "unanswered", "command": cmd["text"], "name": cmd["name"],
            "answer": None, "code": None, "inta": None, "t_command": pending.t_last,
            "t_answer": None, "latency": None, "command_offset": cmd["offset"],
            "answer_offset": None, "packet": pending.packet,
            "packet_commands": pending.packet_commands,
        }
        return (TOPIC_EXCHANGES, pending.t_last, payload)


def make_decoder(variant: str | Variant, *, baud: int | None = None,
                 dialect: Dialect | None = None) -> FrameDecoder:
    """A decoder for a variant id such as ``"gve64-v19"`` (``UserError`` if unknown)."""
    v = load_spec().variant(variant) if isinstance(variant, str) else variant
    return FrameDecoder(v, dialect)
