"""Read a grbl's state back over its own commands (``?``, ``$G``, ``$#``, and ``$$``, ``$N``,
``$I`` when they may have changed), so the reference unit can start from it
(:func:`conform.families.grbl.unit.adopt.start_from`).

Settings, startup lines and build info change only by writes, so a caller keeps the last
reading (``known``) and asks again only after a write; position, offsets and the modal state
are read every time (grbl keeps its position across a soft reset).
"""

from __future__ import annotations

import re
from typing import Any

from conform.conformance.target import HarnessError
from conform.families.grbl.protocol.gcode import MM_PER_INCH
from conform.families.grbl.unit.adopt import UnitState

_PARAM = re.compile(r"^\[(G5[4-9]|G28|G30|G92|TLO|PRB):([^\]]*)\]$")
_SETTING = re.compile(r"^\$(\d+)=(.*)$")
_STARTUP = re.compile(r"^\$N(\d+)=(.*)$")
READBACK_TIMEOUT = 6.0  # seconds for one read-back answer (real grbl answers in milliseconds)


def _numbers(text: str, scale: float) -> list[float]:
    return [float(x) * scale for x in text.split(",")]


def read_eeprom(session: Any) -> UnitState:
    """Settings (``$$``), startup lines (``$N``) and build info (``$I``)."""
    s = UnitState()
    for x in session.talk(b"$$\n", timeout=READBACK_TIMEOUT).lines:
        m = _SETTING.match(x)
        if m:
            try:
                s.settings[int(m.group(1))] = float(m.group(2))
            except ValueError:
                raise HarnessError(f"unreadable setting line {x!r}") from None
    lines = {}
    for x in session.talk(b"$N\n", timeout=READBACK_TIMEOUT).lines:
        m = _STARTUP.match(x)
        if m:
            lines[int(m.group(1))] = m.group(2)
    s.startup = [lines.get(i, "") for i in range(max(lines, default=-1) + 1)]
    for x in session.talk(b"$I\n", timeout=READBACK_TIMEOUT).lines:
        if x.startswith("[VER:") and x.endswith("]"):
            s.build_info = x[5:-1].split(":", 1)[1] if x.count(":") >= 2 else ""
    return s


def read_state(session: Any, known: UnitState
               ) -> tuple[UnitState, list[tuple[bytes, list[str]]]]:
    """The target's position, state, modal state and offsets, over ``known``'s EEPROM part;
    and each question with its answer lines."""
    s = UnitState(settings=dict(known.settings), startup=list(known.startup),
                  build_info=known.build_info)
    scale = MM_PER_INCH if known.settings.get(13) else 1.0
    said: list[tuple[bytes, list[str]]] = []

    def ask(data: bytes) -> list[str]:
        # a read-back is no timing check: a unit (or an emulator on a loaded machine) may take
        # seconds to answer, and only an answer that never comes is the harness's error
        lines = session.talk(data, status=data.count(b"?"), timeout=READBACK_TIMEOUT).lines
        said.append((data, lines))
        return lines

    for x in ask(b"$#\n"):
        m = _PARAM.match(x)
        if not m:
            continue
        name, body = m.groups()
        if name == "TLO":
            s.tlo = float(body) * scale
        elif name == "PRB":
            where, _, ok = body.rpartition(":")
            s.prb, s.prb_ok = _numbers(where, scale), ok == "1"
        elif name.startswith("G5"):
            s.coords[int(name[1:]) - 54] = _numbers(body, scale)
        else:
            setattr(s, name.lower(), _numbers(body, scale))
    gc = [x for x in ask(b"$G\n") if x.startswith("[GC:") and x.endswith("]")]
    if not gc:
        raise HarnessError("no [GC:...] answer to $G")
    s.modal = gc[0][4:-1]
    report = [x for x in ask(b"?") if x.startswith("<")]
    if not report:
        raise HarnessError("no status report answer to ?")
    fields = dict(f.split(":", 1) if ":" in f else (f, "") for f in report[0][1:-1].split("|"))
    s.state = report[0][1:-1].split("|", 1)[0].split(":", 1)[0]
    if "MPos" in fields:
        s.position = _numbers(fields["MPos"], scale)
    elif "WPos" in fields:
        coord = next((int(w[1:]) - 54 for w in s.modal.split() if w in
                      ("G54", "G55", "G56", "G57", "G58", "G59")), 0)
        wco = [c + g for c, g in zip(s.coords[coord], s.g92, strict=True)]
        wco[2] += s.tlo
        if "WCO" in fields:
            wco = _numbers(fields["WCO"], scale)
        s.position = [w + o for w, o in zip(_numbers(fields["WPos"], scale), wco, strict=True)]
    else:
        raise HarnessError(f"no position in the status report {report[0]!r}")
    return s, said
