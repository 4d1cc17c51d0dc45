"""``conform ports --probe`` (and ``conform send`` given no variant) for Marlin: ``M115``, the
firmware's capability report (gcode/host/M115.cpp), which only reads. An empty line first ends
whatever another family's question left in Marlin's line buffer (an empty line is skipped,
queue.cpp). The variant is the one whose firmware version the report names."""

from __future__ import annotations

import re
import time

from conform.errors import LinkError
from conform.families import ProbeAnswer

_NAME = re.compile(rb"FIRMWARE_NAME:Marlin[ _]v?([\w.\-]+)")


def probe(device: str, *, baud: int, timeout: float) -> ProbeAnswer:
    from conform.families.marlin.spec import load_marlin
    from conform.link.ports import open_port

    try:
        port = open_port(device, baud)
    except LinkError as exc:
        return ProbeAnswer(None, None, str(exc))
    heard = b""
    try:
        port.write(b"\nM115\n")
        end = time.monotonic() + timeout
        while time.monotonic() < end and not (_NAME.search(heard) and b"\nok" in heard):
            heard += port.read(4096, timeout=max(0.0, min(0.05, end - time.monotonic())))
    except LinkError as exc:
        return ProbeAnswer(None, None, str(exc))
    finally:
        port.close()
    found = _NAME.search(heard)
    if not found:
        text = heard.decode("latin-1").strip()
        return ProbeAnswer(None, text[:60] or None,
                           f"answered {text[:40]!r} to M115" if text else "no answer to M115")
    version = found.group(1).decode()
    answer = found.group(0).decode("latin-1")
    for v in load_marlin().variants.values():
        if v.firmware == version or version.startswith(v.firmware):
            return ProbeAnswer(v.id, answer, f"Marlin {version} answered M115")
    return ProbeAnswer(None, answer, f"a Marlin answered, but version {version} is not in the "
                                     "tables")
