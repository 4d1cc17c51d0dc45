"""Start the reference unit from a state read back from another grbl (a unit behind a link).

A real grbl is not a fresh unit at the start of a check: it keeps its machine position across a
soft reset (main.c clears ``sys`` but not ``sys_position``), its settings, startup lines, build
info and the G54-G59/G28/G30 data live in EEPROM, and its startup lines may leave a modal state
of their own. :func:`start_from` puts all of that into a :class:`GrblUnit` that has just been
made or reset, so the reference answers as the target would from where the target really is.

The values are in millimetres (the caller converts a unit that reports inches, ``$13=1``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from conform.families.grbl.protocol.gcode import MM_PER_INCH, Modal

if TYPE_CHECKING:
    from conform.families.grbl.unit.model import GrblUnit


@dataclass
class UnitState:
    """What a grbl tells of itself: ``?``, ``$G``, ``$#``, ``$$``, ``$N`` and ``$I``."""

    state: str = "Idle"                                   # the status report's state name
    position: list[float] = field(default_factory=lambda: [0.0] * 3)   # machine position, mm
    modal: str = ""                                       # the [GC:...] body
    coords: list[list[float]] = field(default_factory=lambda: [[0.0] * 3 for _ in range(6)])
    g28: list[float] = field(default_factory=lambda: [0.0] * 3)
    g30: list[float] = field(default_factory=lambda: [0.0] * 3)
    g92: list[float] = field(default_factory=lambda: [0.0] * 3)
    tlo: float = 0.0
    prb: list[float] = field(default_factory=lambda: [0.0] * 3)
    prb_ok: bool = False
    settings: dict[int, float] = field(default_factory=dict)
    startup: list[str] = field(default_factory=list)
    build_info: str = ""


def start_from(unit: GrblUnit, s: UnitState) -> None:
    """Make ``unit`` (idle, just made or reset) stand where ``s`` says, with its EEPROM."""
    from conform.families.grbl.unit.system import _apply

    for n, value in s.settings.items():
        row = unit.spec.settings.get(n)
        if row is not None:
            unit.settings[n] = row.coerce(value)
    _apply(unit)
    for i, text in enumerate(s.startup[:len(unit.startup)]):
        unit.startup[i] = text
    unit.build_info = s.build_info
    ee = unit.eeprom_coords
    ee.coords = [list(c) for c in s.coords]
    ee.g28, ee.g30 = list(s.g28), list(s.g30)
    unit.modal = _modal(s)
    # grbl counts its position in whole steps (sys_position) and, after the reset that starts
    # every check, its parser stands on them too (main.c gc_sync_position): the report's three
    # decimals are taken back to the step they print (exact below 1000 steps/mm)
    position = unit._in_steps(list(s.position))
    unit.planner.clear(position)
    unit._check_pos = list(position)
    unit.prb, unit.prb_ok = list(s.prb), s.prb_ok
    unit.state = "Alarm" if s.state == "Alarm" else "Idle"


def _modal(s: UnitState) -> Modal:
    """The parser state of a ``[GC:...]`` body (report.c report_gcode_modes), with the
    offsets of ``$#``."""
    m = Modal(coords=[list(c) for c in s.coords], g28=list(s.g28), g30=list(s.g30),
              g92=list(s.g92), tlo=s.tlo)
    feed = 0.0
    for word in s.modal.split():
        letter, value = word[0], word[1:]
        if letter == "G":
            if value in ("0", "1", "2", "3", "38.2", "38.3", "38.4", "38.5", "80"):
                m.motion = value
            elif value in ("54", "55", "56", "57", "58", "59"):
                m.coord = int(value) - 54
            elif value in ("17", "18", "19"):
                m.plane = value
            elif value in ("20", "21"):
                m.units = value
            elif value in ("90", "91"):
                m.distance = value
            elif value in ("93", "94"):
                m.feed_mode = value
        elif letter == "M":
            n = int(value)
            if n in (0, 1, 2, 30):
                m.program = n
            elif n in (3, 4, 5):
                m.spindle = n
            elif n in (7, 8):
                m.coolant = m.coolant | {n}
        elif letter == "T":
            m.tool = int(value)
        elif letter == "F":
            feed = float(value)
        elif letter == "S":
            m.speed = float(value)
    m.feed = feed * MM_PER_INCH if m.units == "20" else feed
    return m
