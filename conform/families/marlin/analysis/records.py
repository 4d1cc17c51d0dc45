"""What the Marlin analysis reads and reports: host lines as queue.cpp sees them, findings,
and the line splitter over timed chunks. The finding record is the engine's
(conform.analysis.result), which the other line-based families share."""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import reduce
from operator import xor

from conform.analysis.result import Finding

CLAUSE_Q = "queue.cpp get_serial_commands / gcode_line_error"
Chunk = tuple[float, bytes]
__all__ = ["CLAUSE_Q", "Chunk", "Finding", "HostLine", "iter_lines", "parse_host"]


@dataclass(slots=True)
class HostLine:
    t: float
    n: int | None
    text: str              # the command (after N, before *)
    raw_size: int
    checksum_ok: bool | None
    epoch: int = 0
    accepted: bool = False
    t_ok: float | None = None
    repeat: bool = False   # the same number sent again (a resend)
    seq: int = 0           # its place among the host lines
    done: bool = False     # its fate is known (taken and answered, or not taken)


def iter_lines(chunks: Iterable[Chunk]) -> Iterator[Chunk]:
    """Lines (ended by LF or CR, empty ones dropped) with the time of the chunk that ended
    them, one at a time."""
    rest = b""
    for t, data in chunks:
        buf = rest + data
        parts = buf.replace(b"\r", b"\n").split(b"\n")
        rest = parts.pop()
        for p in parts:
            if p:
                yield t, p


_NUMBERED = re.compile(rb"N(-?\d*)")
_SECOND_N = re.compile(rb"N(-?\d+)")


def parse_host(t: float, raw: bytes) -> HostLine:
    """What queue.cpp sees of one host line: the comment cut at ';' (a checksum after it is
    gone), N and the checksum checked."""
    cut = raw.find(b";")
    body = (raw if cut < 0 else raw[:cut]).lstrip(b" ")
    star = body.rfind(b"*")
    text = body if star < 0 else body[:star]
    if body[:1] != b"N":
        return HostLine(t, None, text.decode("latin-1").strip(), len(raw), None)
    m = _NUMBERED.match(body)
    digits = m.group(1) if m else b""
    n = int(digits) if digits not in (b"", b"-") else 0
    if b"M110" in body:
        second = _SECOND_N.search(body, 4)
        if second:
            n = int(second.group(1))
    ok = False
    if star >= 0:
        tail = body[star + 1:].strip()
        ok = tail.isdigit() and int(tail) == reduce(xor, body[:star], 0)
    return HostLine(t, n, text[m.end() if m else 1:].decode("latin-1").strip(), len(raw), ok)
