"""Answers (GVE64 §13.7, GVE124 §12.6): one hex digit — bit 3 INTA, bits 2..0 the error code —
then ``,field`` as needed, then CR; with checksums on, ``,XX`` before the CR."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from conform.families.gve.protocol.checksum import append_checksum, checksum

INTA_BIT = 0x08


@dataclass(frozen=True, slots=True)
class Answer:
    code: int
    inta: bool
    fields: tuple[str, ...]
    checksum: int | None  # the received checksum, when checksums were expected
    checksum_ok: bool | None  # None when checksums were not expected
    raw: bytes

    @property
    def digit(self) -> int:
        return self.code | (INTA_BIT if self.inta else 0)


@dataclass(frozen=True, slots=True)
class Garbled:
    """A line from the unit that is not an answer (noise, a cut line, an echo)."""

    raw: bytes
    detail: str


def encode_answer(code: int, inta: bool = False, fields: Sequence[object] = (), *,
                  checksum_on: bool = False, terminator: bytes = b"\r") -> bytes:
    """``encode_answer(0, checksum_on=True)`` → ``b"0,5C\\r"`` (GVE64 §13.3.2)."""
    if not 0 <= code <= 7:
        raise ValueError(f"error code {code} is not 0..7")
    body = b"%X" % (code | (INTA_BIT if inta else 0))
    for f in fields:
        body += b"," + (f if isinstance(f, bytes) else str(f).encode("ascii"))
    if checksum_on:
        body = append_checksum(body)
    return body + terminator


def answer_digit(byte: int) -> int | None:
    """The value of an answer's first byte (an upper-case hex digit), None if it is not one."""
    if 0x30 <= byte <= 0x39:
        return byte - 0x30
    if 0x41 <= byte <= 0x46:
        return byte - 0x37
    return None


def parse_answer(line: bytes, checksum_on: bool) -> Answer | Garbled:
    """Parse one answer line (without its CR)."""
    if not line:
        return Garbled(line, "empty line")
    digit = answer_digit(line[0])
    if digit is None:
        return Garbled(line, f"first byte {line[:1]!r} is not a hex digit")
    if len(line) > 1 and line[1] != 0x2C:
        return Garbled(line, f"byte 1 {line[1:2]!r} is not ','")
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError as exc:
        return Garbled(line, f"non-ASCII byte at offset {exc.start}")
    fields = text.split(",")[1:]
    received: int | None = None
    ok: bool | None = None
    if checksum_on:
        tail = fields[-1] if fields else ""
        if len(tail) == 2 and all(c in "0123456789ABCDEFabcdef" for c in tail):
            received = int(tail, 16)
            fields = fields[:-1]
            ok = checksum(line[: -2]) == received
        else:
            ok = False
    return Answer(digit & 7, bool(digit & INTA_BIT), tuple(fields), received, ok, line)
