"""``conform characterize`` for grbl: what this build does where builds differ.

grbl's compile-time options change what a sender must assume: the receive buffer and planner
sizes (reported by ``$I`` in ``[OPT:…,blocks,bytes]``), the version and build date, and
whether CR LF is one line end or two. The probes read them, check the line-length limit, and
write a profile: the observed value next to the table's, with the evidence. Nothing moves and
nothing is written to the EEPROM.
"""

from __future__ import annotations

from typing import Any

from conform.conformance.observed import Observation
from conform.families.grbl.conformance.session import Session
from conform.families.grbl.spec.load import load_grbl

#: what is probed, in order (a partial profile lists those it did not reach)
ITEMS = ("version", "build", "options", "planner_blocks", "rx_buffer", "crlf_is_two_lines",
         "line_max")


def characterize(target: Any, vid: str, out: list[Observation] | None = None
                 ) -> list[Observation]:
    """Probe every item of :data:`ITEMS`; ``out`` (the caller's) fills as they are found, so
    that an interrupted characterisation still has them."""
    spec = load_grbl()
    v = spec.variant(vid)
    s = Session(target, spec, v)
    s.fresh()
    out = [] if out is None else out
    got = s.talk(b"\x18")
    banner = next((x for x in got.lines if x.startswith("Grbl ")), "")
    version = banner.split()[1] if banner else None
    out.append(Observation("version", v.version, version, banner or "(no banner after Ctrl-X)"))
    info = s.talk(b"$I\n")
    ver = next((x for x in info.lines if x.startswith("[VER:")), "")
    opt = next((x for x in info.lines if x.startswith("[OPT:")), "")
    build = ver[5:-1].split(":")[0].split(".")[-1] if ver else None
    out.append(Observation("build", v.build, build, ver or "(no [VER:])"))
    fields = opt[5:-1].split(",") if opt else []
    out.append(Observation("options", v.options, fields[0] if fields else None, opt or "(no [OPT:])"))
    for name, idx in (("planner_blocks", 1), ("rx_buffer", 2)):
        value = int(fields[idx]) if len(fields) > idx and fields[idx].isdigit() else None
        out.append(Observation(name, getattr(v, name), value, opt or "(no [OPT:])"))
    crlf = s.talk(b"\r\n", answers=2, timeout=0.5, linger=0.1)
    oks = sum(1 for x in crlf.lines if x == "ok")
    out.append(Observation("crlf_is_two_lines", v.crlf_is_two_lines, oks == 2,
                           f"CR LF answered {' | '.join(crlf.lines) or '(silence)'}"))
    n = v.line_max
    longest = None
    for length in (n, n + 1):
        line = b"N" + b"0" * (length - 2) + b"1\n"
        if s.talk(line).lines == ["ok"]:
            longest = length
    out.append(Observation("line_max", n, longest,
                           f"a line of {n} characters and one of {n + 1}"))
    return out
