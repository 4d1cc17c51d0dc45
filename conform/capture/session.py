"""The sans-I/O heart of a recording: chunks and events in, MCAP-ready records out.

``CaptureSession`` keeps the running byte offsets, estimates first-byte times from the baud
rate, runs the frame decoder and builds the JSON payload of every message. It never touches
a file, a clock or a thread; ``Recorder`` feeds it and writes what it returns, and tests
drive it directly with made-up times.
"""

from __future__ import annotations

import base64
import math
import re
from dataclasses import dataclass
from typing import Protocol

from conform.capture.schemas import (
    DIRECTION_TOPIC,
    DIRECTIONS,
    LINK_KINDS,
    LOG_LEVELS,
    TOPIC_LINK,
    TOPIC_LOG,
)

BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop


@dataclass(frozen=True)
class Record:
    """One MCAP message to write: topic, log time in ns, JSON-able payload."""

    topic: str
    log_time: int
    payload: dict[str, object]


class Decoder(Protocol):
    """What ``CaptureSession`` needs from a frame decoder (a family's ``live_decoder``).

    A decoder may also have ``fields``: the ``conform.capture.schemas.CaptureFields`` its
    frames and exchanges carry besides the neutral ones (recorded as columns of their own);
    without it only the neutral fields are recorded."""

    def feed(
        self, direction: str, data: bytes, offset: int, t_read: float, t_first: float
    ) -> list[Record]: ...

    def finish(self, t: float) -> list[Record]: ...


def to_ns(t: float) -> int:
    """Seconds to integer nanoseconds for ``log_time`` (0 for a time that is not finite)."""
    ns = t * 1e9
    return max(0, min(round(ns), 2**63 - 1)) if math.isfinite(ns) else 0


_ESCAPES = {0x0D: "\\r", 0x0A: "\\n", 0x09: "\\t", 0x5C: "\\\\"}
_ESCAPED = [_ESCAPES.get(b) or (chr(b) if 0x20 <= b < 0x7F else f"\\x{b:02x}") for b in range(256)]
_NEEDS_ESCAPE = re.compile(rb"[^\x20-\x5b\x5d-\x7e]")


def escape_bytes(data: bytes) -> str:
    """Printable ASCII as is, CR/LF/TAB/backslash as C escapes, everything else ``\\xNN``."""
    if _NEEDS_ESCAPE.search(data) is None:
        return data.decode("ascii")
    return "".join([_ESCAPED[b] for b in data])


def unescape_text(text: str) -> bytes:
    """Inverse of ``escape_bytes``."""
    return text.encode("latin-1").decode("unicode_escape").encode("latin-1")


def wire_time(n_bytes: int, baud: int | None) -> float:
    """Seconds ``n_bytes`` take on an 8N1 line at ``baud`` (0 without a baud)."""
    return n_bytes * BITS_PER_BYTE / baud if baud else 0.0


def log_payload(level: str | int, message: str, t: float, name: str, file: str = "",
                line: int = 0) -> dict[str, object]:
    """A ``foxglove.Log`` message."""
    ns = to_ns(t)
    if isinstance(level, str):
        lvl = LOG_LEVELS.get(level.lower(), 0)
    else:
        lvl = int(level) if 0 <= int(level) <= 5 else 0
    return {
        "timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
        "level": lvl,
        "message": message,
        "name": name,
        "file": file,
        "line": max(0, int(line)),
    }


class CaptureSession:
    """Turns what a recorder sees into records for every topic of a capture."""

    def __init__(
        self, *, baud: int | None = None, decoder: Decoder | None = None, name: str = "conform"
    ) -> None:
        self.baud = baud
        self.decoder = decoder
        self.name = name
        self.offsets = dict.fromkeys(DIRECTIONS, 0)
        self.seq = dict.fromkeys(DIRECTIONS, 0)
        self._last_read = dict.fromkeys(DIRECTIONS, float("-inf"))

    def estimate_first(self, direction: str, n_bytes: int, t_read: float) -> float:
        """First-byte time: ``len*10/baud`` before the read, never before the previous read."""
        t_first = t_read - wire_time(n_bytes, self.baud)
        return max(t_first, min(self._last_read[direction], t_read))

    def advance(self, direction: str, n_bytes: int, t_read: float, t_first: float | None
                ) -> tuple[int, float]:
        """Count one read of ``n_bytes``: its stream offset and first-byte time."""
        if direction not in DIRECTION_TOPIC:
            raise ValueError(f"direction must be 'host' or 'unit', not {direction!r}")
        if t_first is None:
            t_first = self.estimate_first(direction, n_bytes, t_read)
        offset = self.offsets[direction]
        self.offsets[direction] = offset + n_bytes
        self.seq[direction] += 1
        self._last_read[direction] = max(self._last_read[direction], t_read)
        return offset, t_first

    def chunk(
        self, direction: str, data: bytes, t_read: float, t_first: float | None = None
    ) -> list[Record]:
        if direction not in DIRECTION_TOPIC:
            raise ValueError(f"direction must be 'host' or 'unit', not {direction!r}")
        if not data:
            return []
        offset, t_first = self.advance(direction, len(data), t_read, t_first)
        payload = {
            "direction": direction,
            "data": base64.b64encode(data).decode("ascii"),
            "hex": data.hex(" ").upper(),
            "text": escape_bytes(data),
            "length": len(data),
            "offset": offset,
            "t_read": t_read,
            "t_first": t_first,
            "seq": self.seq[direction],
        }
        records = [Record(DIRECTION_TOPIC[direction], to_ns(t_read), payload)]
        if self.decoder is not None:
            records.extend(self.decoder.feed(direction, data, offset, t_read, t_first))
        return records

    def link_event(self, kind: str, side: str, detail: str, t: float) -> list[Record]:
        if kind not in LINK_KINDS:
            raise ValueError(f"link event kind must be one of {LINK_KINDS}, not {kind!r}")
        level = "info" if kind in ("open", "close", "reconnect", "baud") else "warning"
        return [
            Record(TOPIC_LINK, to_ns(t), {"kind": kind, "side": side, "detail": detail, "t": t}),
            Record(TOPIC_LOG, to_ns(t), log_payload(level, f"{side}: {kind}: {detail}", t,
                                                     self.name)),
        ]

    def log(self, level: str | int, text: str, t: float, *, name: str | None = None,
            file: str = "", line: int = 0) -> list[Record]:
        return [Record(TOPIC_LOG, to_ns(t),
                       log_payload(level, text, t, name or self.name, file, line))]

    def finish(self, t: float) -> list[Record]:
        """Whatever the decoder still holds (a command never answered, a partial line)."""
        return self.decoder.finish(t) if self.decoder is not None else []
