"""Splitting a byte stream into lines (sans-I/O): CR ends a line (GVE64 §13.5, §13.7); what an
LF does is open question A1 and chosen by the dialect."""

from __future__ import annotations

MAX_LINE = 4096
"""The longest line kept: a unit's receive buffer is finite, so the bytes of a line past this
length are dropped until its terminator (the line is then answered as what it holds)."""


class LineSplitter:
    """Feed bytes, get complete lines without their terminator.

    ``mode`` is the A1 choice: ``cr`` (CR ends a line; an LF that starts a line is dropped),
    ``cr-or-lf`` (either ends a line; empty lines are dropped), ``crlf`` (only CR LF).
    A line keeps at most ``max_line`` bytes (None: no limit).
    """

    __slots__ = ("mode", "max_line", "_buf")

    def __init__(self, mode: str = "cr", max_line: int | None = MAX_LINE) -> None:
        if mode not in ("cr", "cr-or-lf", "crlf"):
            raise ValueError(f"unknown terminator mode {mode!r}")
        self.mode = mode
        self.max_line = max_line
        self._buf = bytearray()

    @property
    def pending(self) -> bytes:
        """Bytes of an unfinished line."""
        return bytes(self._buf)

    @property
    def unfinished(self) -> bytearray:
        """The unfinished line itself, without a copy (read it, do not change it)."""
        return self._buf

    def clear(self) -> bytes:
        """Drop the unfinished line (watchdog, reset) and return what was dropped."""
        dropped = bytes(self._buf)
        self._buf.clear()
        return dropped

    def feed(self, data: bytes) -> list[bytes]:
        if self._buf:
            self._buf += data
            text = bytes(self._buf)
        else:
            text = bytes(data)
        if self.mode == "cr-or-lf":
            text = text.replace(b"\n", b"\r")
        parts = text.split(b"\r\n" if self.mode == "crlf" else b"\r")
        self._buf[:] = parts.pop()
        if self.mode == "cr" and b"\n" in text:  # the LF of a CR LF starts the next line
            self._buf[:] = self._buf.lstrip(b"\n")
            parts = [p.lstrip(b"\n") for p in parts]
        elif self.mode == "cr-or-lf":
            parts = [p for p in parts if p]
        limit = self.max_line
        if limit is not None and len(text) > limit:
            if len(self._buf) > limit:
                # crlf: a CR at the cut may be the first half of the terminator: keep it
                keep_cr = self.mode == "crlf" and self._buf.endswith(b"\r")
                del self._buf[limit:]
                if keep_cr:
                    self._buf += b"\r"
            parts = [p[:limit] if len(p) > limit else p for p in parts]
        return parts
