"""The '$' system commands of grbl 1.1f (gnea/grbl grbl/system.c ``system_execute_line``):
which state each is allowed in, what it prints before its ``ok``, and its error codes."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from conform.families.grbl.protocol.gcode import GcodeError, parse
from conform.families.grbl.unit import replies as rp

if TYPE_CHECKING:
    from conform.families.grbl.unit.model import GrblUnit

_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)")
IDLE_OR_ALARM = ("Idle", "Alarm")


def system_command(u: GrblUnit, text: str, t: float) -> None:
    """Run one '$' line (already stripped and upper-cased) and answer it."""
    code = _run(u, text, t)
    if code is not None:
        u._answer(t, code)


def _run(u: GrblUnit, text: str, t: float) -> int | None:
    rest = text[1:]
    if rest == "":
        u._say(t, rp.HELP)
        return 0
    head = rest[0]
    if head == "J":
        if u.state not in ("Idle", "Jog"):
            return 8
        if rest[1:2] != "=":
            return 3
        body = rest[2:]
        try:
            block = parse(body, u.modal, u.parser_position(), jog=True,
                          tool_max=u.v.tool_max) if body else None
        except GcodeError as exc:
            return exc.code
        if block is None:
            return 16
        u._execute(block, t, jog=True)
        return None
    if head in "$GCX":
        if rest[1:]:
            return 3
        if head == "$":
            if u.state in ("Run", "Hold"):
                return 8
            u._say(t, *rp.settings_lines(u.spec, u.settings))
            return 0
        if head == "G":
            u._say(t, f"[GC:{u.modal.gc_line()}]")
            return 0
        if head == "C":
            if u.state == "Check":
                u._say(t, rp.MSG["disabled"], "ok")
                u.lines_done += 1
                u._code_taken(0)
                u._reset(t)
                return None
            if u.state != "Idle":
                return 8
            u.state = "Check"
            u._check_pos = list(u.planner.position)
            u._say(t, rp.MSG["enabled"])
            return 0
        if u.state == "Alarm":  # $X
            u.state = "Idle"
            u._critical = False
            u._say(t, rp.MSG["unlocked"])
        return 0
    if u.state not in IDLE_OR_ALARM:
        return 8
    if head == "#":
        if rest[1:]:
            return 3
        u._say(t, *rp.params_lines(u.modal, u.prb, u.prb_ok, bool(u.settings[13])))
        return 0
    if head == "H":
        if rest[1:]:
            return 3
        if not u.settings[22]:
            return 5
        return _home(u, t)
    if head == "S":
        if rest != "SLP":
            return 3
        u._answer(t, 0)
        u._hard_stop(t)
        u.state = "Sleep"
        u._say(t, rp.MSG["sleep"])
        return None
    if head == "I":
        if rest == "I":
            u._say(t, *rp.build_lines(u.v, u.build_info))
            return 0
        if rest[1:2] != "=":
            return 3
        u.build_info = rest[2:]
        return 0
    if head == "R":
        m = re.fullmatch(r"RST=([$#*])", rest)
        if not m:
            return 3
        _restore(u, m.group(1))
        u._say(t, rp.MSG["restore"], "ok")
        u.lines_done += 1
        u._code_taken(0)
        u._reset(t)
        return None
    if head == "N":
        if rest == "N":
            u._say(t, *(f"$N{i}={s}" for i, s in enumerate(u.startup)))
            return 0
        m = re.fullmatch(r"N(\d+)=(.*)", rest)
        if not m:
            return 2 if not _FLOAT.match(rest, 1) else 3
        if u.state != "Idle":
            return 8
        n = int(m.group(1))
        if n >= len(u.startup):
            return 3
        line = m.group(2)
        if line:
            try:
                parse(line, u.modal.copy(), u.parser_position(), tool_max=u.v.tool_max)
            except GcodeError as exc:
                return exc.code
        u.startup[n] = line
        return 0
    return _setting(u, rest)


def _setting(u: GrblUnit, rest: str) -> int:
    m = _FLOAT.match(rest)
    if m is None:
        return 2
    if rest[m.end():m.end() + 1] != "=":
        return 3
    value_text = rest[m.end() + 1:]
    v = _FLOAT.fullmatch(value_text)
    if v is None:
        return 2
    number, value = int(float(m.group(0))), float(value_text)
    setting = u.spec.settings.get(number)
    if setting is None:
        return 3
    if value < 0:
        return 4
    if number == 0 and value < 3:
        return 6
    if number == 20 and value and not u.settings[22]:
        return 10
    u.settings[number] = setting.coerce(value)
    _apply(u)
    return 0


def _apply(u: GrblUnit) -> None:
    """Settings that shape motion take effect for blocks planned from now on."""
    pl = u.planner
    pl.axis_accel = [u.settings[120 + i] for i in range(3)]
    pl.axis_rate = [u.settings[110 + i] / 60.0 for i in range(3)]
    pl.junction_deviation = u.settings[11]


def _restore(u: GrblUnit, what: str) -> None:
    from conform.families.grbl.protocol.gcode import Modal

    if what in "$*":
        u.settings = {n: s.default for n, s in u.spec.settings.items()}
    if what in "#*":
        u.eeprom_coords = Modal()
    if what == "*":
        u.startup = [""] * len(u.startup)
        u.build_info = ""


def _home(u: GrblUnit, t: float) -> None:
    """Homing in virtual time: seek to the switches at the machine origin, pull off.

    The reference unit has switches wherever the travel says (no wiring to fail), so homing
    succeeds; the machine then stands at -pull-off on every axis (limits.c, positive homing
    direction by default).
    """
    pos = u.planner.where(t)[0]
    seek = max(u.settings[25], 1e-6) / 60.0
    locate = max(u.settings[24], 1e-6) / 60.0
    pull = u.settings[27]
    dist = max(abs(p) for p in pos)
    duration = dist / seek + 2 * pull / locate + pull / seek + 2 * u.settings[26] / 1000.0
    u.planner.clear(pos)
    u.state = "Home"
    u._busy_until = t + duration
    u._busy = ("home",)
    return None
