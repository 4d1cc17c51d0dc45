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
        self._buf += data
        text = bytes(self._buf)
        if self.mode == "cr-or-lf":
            text = text.replace(b"\n", b"\r")
        parts = text.split(b"\r\n" if self.mode == "crlf" else b"\r")
        self._buf[:] = parts.pop()
        if self.mode == "cr":  # the LF of a CR LF starts the next line: it is not part of it
            self._buf[:] = self._buf.lstrip(b"\n")
            return [p.lstrip(b"\n") for p in parts]
        if self.mode == "cr-or-lf":
            return [p for p in parts if p]
        return parts
