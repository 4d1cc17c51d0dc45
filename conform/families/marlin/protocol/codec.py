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
_FIRMWARE_BUILD = re.compile(r"^(FIRMWARE_NAME:Marlin \S+) \([^)]*\)")


def mask_volatile(line: str) -> str:
    """An answer line with what differs between two runs of the same build masked, each
    named here with why:

    - the readings in a temperature report (``T:21.50 /0.00 B:…`` from M105, M155, M109):
      a heater's temperature is the room's and the heater's, not the protocol's (and the
      native build reads ``T:0.00`` for its first seconds);
    - the build's date, its author line and free memory in the boot banner (MarlinCore.cpp
      setup) and the build date after FIRMWARE_NAME (M115.cpp): they name the build, not
      its behaviour;
    - a CR before the LF: a text transcript cannot hold a CR (the few lines Marlin ends
      with CR LF, a println's, are marked by a comment there), so CR LF and LF compare
      equal; the MCAP sessions hold no CR LF line to lose."""
    if line.endswith("\r\n"):
        line = line[:-2] + "\n"
    if "T:" in line and not line.startswith("FIRMWARE_NAME"):
        return _NUMBER.sub("#", line)
    for prefix in _BUILD:
        if line.startswith(prefix):
            return prefix + " #"
    return _FIRMWARE_BUILD.sub(r"\1 (#)", line)


_POSITION = re.compile(r"^X:(-?[\d.]+) Y:(-?[\d.]+) Z:(-?[\d.]+) E:(-?[\d.]+) "
                       r"Count X:(-?\d+) Y:(-?\d+) Z:(-?\d+)\s*$")
POSITION_TOLERANCE = 0.5
"""mm: how far apart two M114 answers may be and still be the same answer. Where the axes
stop after M410 depends on the moment the stop is read (a few ms on a PC's pty, the motion
model's ramps): recorded X:8.71 against the model's 8.75 for a 10 mm/s move."""


def near_position(a: str, b: str, steps: tuple[float, ...] = (80.0, 80.0, 400.0)) -> bool:
    """Two M114 lines within POSITION_TOLERANCE on every axis (Count within as many steps)."""
    ma, mb = _POSITION.match(a), _POSITION.match(b)
    if not (ma and mb):
        return False
    xa, xb = [float(x) for x in ma.groups()], [float(x) for x in mb.groups()]
    if any(abs(p - q) > POSITION_TOLERANCE for p, q in zip(xa[:4], xb[:4], strict=True)):
        return False
    return all(abs(p - q) <= POSITION_TOLERANCE * s
               for p, q, s in zip(xa[4:], xb[4:], steps, strict=True))


def is_answer(line: str) -> bool:
    """A line that closes the answer to one host line: ``ok`` (with M105's temperatures or
    ADVANCED_OK's fields after it); what an ok-paced sender waits for."""
    return line == "ok" or line.startswith("ok ")
