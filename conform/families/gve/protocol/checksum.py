"""The checksum of GVE64 §13.3.2: the byte sum, modulo 256, of everything from ``!`` up to and
including the comma that precedes the two hex digits."""

from __future__ import annotations

import re

_TAIL = re.compile(rb",([0-9A-Fa-f]{2})$")


def checksum(data: bytes) -> int:
    """Sum of the bytes modulo 256."""
    return sum(data) & 0xFF


def append_checksum(body: bytes) -> bytes:
    """``b"!0A100"`` → ``b"!0A100,4F"`` (no terminator)."""
    head = body + b","
    return head + b"%02X" % checksum(head)


def split_checksum(line: bytes) -> tuple[bytes, int | None]:
    """Split ``body,XX`` into (body, XX); (line, None) when there is no two-hex-digit tail."""
    m = _TAIL.search(line)
    if m is None:
        return line, None
    return line[: m.start()], int(m.group(1), 16)


def verify(line: bytes) -> bool:
    """True when ``line`` ends in ``,XX`` and XX is the checksum of what precedes it."""
    body, value = split_checksum(line)
    return value is not None and checksum(body + b",") == value
