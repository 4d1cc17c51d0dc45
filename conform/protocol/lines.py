"""Splitting a byte stream into lines (sans-I/O): CR ends a line (GVE64 §13.5, §13.7); what an
LF does is open question A1 and chosen by the dialect."""

from __future__ import annotations


class LineSplitter:
    """Feed bytes, get complete lines without their terminator.

    ``mode`` is the A1 choice: ``cr`` (CR ends a line; an LF that starts a line is dropped),
    ``cr-or-lf`` (either ends a line; empty lines are dropped), ``crlf`` (only CR LF).
    """

    __slots__ = ("mode", "_buf")

    def __init__(self, mode: str = "cr") -> None:
        if mode not in ("cr", "cr-or-lf", "crlf"):
            raise ValueError(f"unknown terminator mode {mode!r}")
        self.mode = mode
        self._buf = bytearray()

    @property
    def pending(self) -> bytes:
        """Bytes of an unfinished line."""
        return bytes(self._buf)

    def clear(self) -> bytes:
        """Drop the unfinished line (watchdog, reset) and return what was dropped."""
        dropped = bytes(self._buf)
        self._buf.clear()
        return dropped

    def feed(self, data: bytes) -> list[bytes]:
        buf = self._buf
        buf += data
        if self.mode == "crlf":
            parts = bytes(buf).split(b"\r\n")
        else:
            if self.mode == "cr-or-lf":
                parts = bytes(buf).replace(b"\n", b"\r").split(b"\r")
            else:
                parts = bytes(buf).split(b"\r")
        tail = parts.pop()
        buf.clear()
        buf += tail
        if self.mode == "crlf":
            return parts
        out = []
        for part in parts:
            if self.mode == "cr":
                part = part.lstrip(b"\n")
            if part or self.mode == "cr":
                out.append(part)
        if self.mode == "cr" and buf[:1] == b"\n":
            del buf[: len(buf) - len(bytes(buf).lstrip(b"\n"))]
        return out
