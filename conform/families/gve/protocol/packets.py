"""Packets (GVE64 §13.3.3): ``*S``, commands without answers, ``*E<n>``; one answer ``0,n``."""

from __future__ import annotations

from collections.abc import Sequence

from conform.families.gve.protocol.checksum import append_checksum


def _line(body: bytes, checksum_on: bool, terminator: bytes) -> bytes:
    return (append_checksum(body) if checksum_on else body) + terminator


def build_packet(lines: Sequence[bytes], *, address: int = 0, checksum_on: bool = False,
                 terminator: bytes = b"\r") -> list[bytes]:
    """Wrap complete command lines (terminated, checksummed as needed) in ``*S`` … ``*E<n>``."""
    start = _line(b"!%d*S" % address, checksum_on, terminator)
    end = _line(b"!%d*E%d" % (address, len(lines)), checksum_on, terminator)
    return [start, *lines, end]
