"""Marlin's line protocol as data, no I/O: checksums, framing a host line, reading one back
(as queue.cpp would see it), splitting what the unit writes into lines, and telling Marlin
traffic from other families'.

    frame(7, "G1 X10")        -> b"N7 G1 X10*<cs>\\n"
    parse_host(b"N7 G1 X10*85") -> HostLine(n=7, command="G1 X10", checksum=85, ...)
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from conform.families import Detection

_N = re.compile(rb"^\s*N(-?\d*)\s*")


def checksum(data: bytes) -> int:
    """XOR of every byte (queue.cpp get_serial_commands: the bytes before ``*``)."""
    c = 0
    for b in data:
        c ^= b
    return c


def frame(n: int, command: str) -> bytes:
    """A numbered, checksummed host line: ``N<n> <command>*<xor>\\n``."""
    body = f"N{n} {command}".encode("latin-1")
    return body + b"*%d\n" % checksum(body)


@dataclass(frozen=True)
class HostLine:
    """One line a host sent, read as Marlin reads it (comments cut at ``;`` first, so a
    checksum after a comment is gone with it)."""

    raw: bytes
    n: int | None              # the line number (N), None when the line has none
    command: str               # what follows N (and its spaces), up to ``*``
    checksum: int | None       # the number after ``*``
    checksum_ok: bool | None   # None: no checksum to check
    m110: bool

    @property
    def code(self) -> str:
        """``G1``, ``M105``... (empty when the command has no letter and number)."""
        m = re.match(r"\s*([GMT])0*(\d+)", self.command, re.I)
        return f"{m.group(1).upper()}{m.group(2)}" if m else ""


def strip_comment(line: bytes) -> bytes:
    """What queue.cpp process_stream_char keeps: everything before ``;``."""
    cut = line.find(b";")
    return line if cut < 0 else line[:cut]


def parse_host(line: bytes) -> HostLine:
    body = strip_comment(line.rstrip(b"\r\n")).lstrip(b" ")
    star = body.rfind(b"*")
    cs: int | None = None
    ok: bool | None = None
    text = body
    if star >= 0:
        digits = re.match(rb"\s*(-?\d+)", body[star + 1:])
        cs = int(digits.group(1)) if digits else 0
        text = body[:star]
        ok = cs == checksum(body[:star])
    n = None
    m = _N.match(text)
    if m:
        n = int(m.group(1)) if m.group(1) not in (b"", b"-") else 0
        text = text[m.end():]
    m110 = b"M110" in body
    if m110 and n is not None:
        second = re.search(rb"N(-?\d+)", body[4:star if star >= 0 else len(body)])
        if second:
            n = int(second.group(1))
    return HostLine(line, n, text.decode("latin-1").strip(), cs, ok, m110)


def split_lines(buf: bytes) -> tuple[list[bytes], bytes]:
    """Complete lines (``\\n``-ended, the ``\\r`` before it dropped) and the rest."""
    parts = buf.split(b"\n")
    return [p.rstrip(b"\r") for p in parts[:-1]], parts[-1]


_OK = re.compile(rb"^ok\b", re.M)
_MARLIN = re.compile(rb"^(Resend: ?\d+|Error:(checksum mismatch|Line Number is not|No Checksum)|"
                     rb"echo:busy: processing|FIRMWARE_NAME:Marlin|echo:Unknown command)", re.M)
_NUMBERED = re.compile(rb"^N-?\d+ [^\n]*\*\d+\r?$", re.M)
_GCODE = re.compile(rb"^(N-?\d+ )?[GMT]\d+", re.M)


def detect(host: bytes, unit: bytes) -> Detection:
    """How Marlin-like the traffic is: Marlin's own words from the unit count most, numbered
    checksummed G-code lines with ``ok`` answers next."""
    words = len(_MARLIN.findall(unit))
    oks = len(_OK.findall(unit))
    numbered = len(_NUMBERED.findall(host))
    gcode = len(_GCODE.findall(host))
    if b"FIRMWARE_NAME:Marlin" in unit:
        return Detection("marlin", 1.0, "the unit names itself Marlin (M115)")
    if words and oks:
        return Detection("marlin", 0.9, f"{words} Marlin messages (Resend:/Error:/busy:) and "
                         f"{oks} ok")
    if numbered >= 3 and oks:
        return Detection("marlin", 0.8, f"{numbered} numbered, checksummed lines answered ok")
    if gcode >= 3 and oks and b"<Idle" not in unit and b"Grbl" not in unit:
        return Detection("marlin", 0.4, "G-code lines answered ok (could be another firmware)")
    return Detection("marlin", 0.0, "no Marlin traffic")


_NUMBER = re.compile(r"-?\d+(?:\.\d+)?")
_BUILD = ("echo: Last Updated:", "echo: Compiled:", "echo: Free Memory:")


def mask_volatile(line: str) -> str:
    """An answer line with what differs between two runs of the same build masked: the
    readings in a temperature report (``T:21.50 /0.00 B:…`` from M105, M155, M109) and the
    build's date and free memory in the boot banner (MarlinCore.cpp setup)."""
    if "T:" in line:
        return _NUMBER.sub("#", line)
    for prefix in _BUILD:
        if line.startswith(prefix):
            return prefix + " #"
    return line
