"""Before streaming to a real port: ask ``?`` to learn the variant, and clear a checksum
mode left on.

After power-up checksums are off (GVE64 §13.3.2), but a program that ran before (a crashed
sender, a characterisation) may have left them on; the unit then refuses every plain line
with ``4`` and a checksum. :func:`probe_unit` asks ``?``; an answer in the checksummed form
means the mode is on, and ``%-`` with its sum turns it off. No answer after a few tries is a
clear error, never a wait without end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from conform.errors import LinkError
from conform.families.gve.protocol import Answer, parse_answer
from conform.families.gve.protocol.checksum import append_checksum


@dataclass
class Probe:
    firmware: str
    checksum_was_on: bool


def _ask(port: Any, line: bytes, timeout: float) -> bytes | None:
    port.reset_input_buffer()
    port.write(line)
    port.timeout = timeout
    got = port.read_until(b"\r")
    return got[:-1] if got.endswith(b"\r") else None


def probe_unit(port: Any, name: str, *, address: int = 0, tries: int = 3,
               timeout: float = 0.5) -> Probe:
    """Ask ``?`` (and clear checksums if they are on); raise ``LinkError`` on silence."""
    cleared = False
    silent = 0
    for _ in range(tries * 2):
        got = _ask(port, b"!%d?\r" % address, timeout)
        if got is None:
            silent += 1
            if silent >= tries:
                break
            continue
        plain = parse_answer(got, False)
        if isinstance(plain, Answer) and plain.code & 7 == 0 and plain.fields:
            return Probe(",".join(plain.fields), cleared)
        summed = parse_answer(got, True)
        if isinstance(summed, Answer) and summed.checksum_ok:
            # the answer carries a checksum: the mode was left on; %- with its sum clears it
            off = append_checksum(b"!%d%%-" % address) + b"\r"
            ans = _ask(port, off, timeout)
            if ans is not None and ans[:1] in (b"0", b"8"):
                cleared = True
            continue
    raise LinkError(f"{name}: no answer to `?` after {tries} tries of {timeout:g} s: is the unit "
                    "connected, powered and at this baud?", exit_code=1)
