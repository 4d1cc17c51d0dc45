"""``conform ports --probe`` for grbl: the ``?`` status query, a realtime byte that only
reads (grbl interface.md, "Real-time commands"; protocol.c acts on it without touching the
parser), then ``$I`` for the build (report.c ``report_build_info``). A grbl that resets on
the port opening prints its banner instead, which names the version too."""

from __future__ import annotations

import re
import time

from conform.errors import LinkError
from conform.families import ProbeAnswer

_STATUS = re.compile(rb"<[A-Za-z]+[|,:][^>\r\n]*>")
_VERSION = re.compile(rb"Grbl (\d+\.\d+[a-z]?)|\[VER:(\d+\.\d+[a-z]?)\.(\d+)")


def probe(device: str, *, baud: int, timeout: float) -> ProbeAnswer:
    from conform.families.grbl.spec.load import load_grbl
    from conform.link.ports import open_port

    try:
        port = open_port(device, baud)
    except LinkError as exc:
        return ProbeAnswer(None, None, str(exc))
    try:
        port.write(b"?")
        heard = _read_until(port, _STATUS, timeout)
        if not _STATUS.search(heard) and not _VERSION.search(heard):
            text = heard.decode("latin-1").strip()
            return ProbeAnswer(None, text or None,
                               "no answer to ?" if not text else f"answered {text[:40]!r} to ?")
        port.write(b"$I\n")
        heard += _read_until(port, re.compile(rb"\nok\r?\n|error:\d+"), timeout)
    finally:
        port.close()
    found = _VERSION.search(heard)
    status = _STATUS.search(heard)
    answer = (status.group(0) if status else found.group(0) if found else heard[:60]).decode("latin-1")
    version = (found.group(1) or found.group(2)).decode() if found else None
    variants = list(load_grbl().variants.values())
    for v in variants:
        if version and v.version == version:
            return ProbeAnswer(v.id, answer, f"grbl {version} answered ? and $I")
    if version is None and status and b"|" in status.group(0):
        # a 1.1 status report (fields split by '|', interface.md) from a grbl too busy to
        # answer $I (it refuses '$' while a motion runs): it is a grbl 1.1, and no other
        # family's question (GVE's '!' is feed hold here) may be sent to it
        ones = [v for v in variants if v.version.startswith("1.1")]
        if len(ones) == 1:
            return ProbeAnswer(ones[0].id, answer, "a grbl 1.1 status report answered ? "
                               "($I unanswered while it moves)")
    return ProbeAnswer(None, answer, f"a grbl answered, but version {version or '?'} is not in "
                                     "the tables")


def _read_until(port: object, pattern: re.Pattern[bytes], timeout: float) -> bytes:
    got = b""
    end = time.monotonic() + timeout
    while time.monotonic() < end and not pattern.search(got):
        got += port.read(4096, timeout=max(0.0, min(0.05, end - time.monotonic())))  # type: ignore[attr-defined]
    return got
