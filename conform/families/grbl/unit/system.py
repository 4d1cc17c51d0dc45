"""The '$' system commands of grbl 1.1f (gnea/grbl grbl/system.c ``system_execute_line``):
which state each is allowed in, what it prints before its ``ok``, and its error codes."""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING

from conform.families.grbl.protocol.gcode import GcodeError, read_float
from conform.families.grbl.unit import replies as rp

if TYPE_CHECKING:
    from conform.families.grbl.unit.model import GrblUnit

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
        try:      # gc_execute_line reads the words after "$J=" (system.c case 'J')
            block = u.parse(body, jog=True)
        except GcodeError as exc:
            return exc.code
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
            u._say(t, f"[GC:{u.modal.gc_line(bool(u.settings[13]))}]")
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
    if head == "H":     # system.c: homing enabled (5), then the rest of the line (3)
        if not u.settings[22]:
            return 5
        if rest[1:] and not (u.v.option("HOMING_SINGLE_AXIS_COMMANDS") and rest[1:] in "XYZ"):
            return 3
        return _home(u, t)
    if head == "S":
        if rest != "SLP":
            return 3
        u._answer(t, 0)
        u._hard_stop(t)
        u.state = "Sleep"
        u.modal.spindle, u.modal.coolant = 5, frozenset()   # protocol.c sleep: both off,
        u._spindle_sync()                                     # Ov: forced (spindle_set_state)
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
        if u.state != "Idle":   # system.c: storing a startup line needs Idle (Alarm is not)
            return 8
        got = read_float(rest, 1)
        if got is None:
            return 2
        number, end = got
        if rest[end:end + 1] != "=":
            return 3
        line = rest[end + 1:]
        try:      # gc_execute_line checks the block (and grbl runs it: its modes stay)
            block = u.parse(line)
        except GcodeError as exc:
            return exc.code
        u.modal = block.modal
        n = int(number)
        if 0 <= n < len(u.startup):   # settings_store_startup_line has no bounds check
            u.startup[n] = line
        return 0
    return _setting(u, rest)


def _setting(u: GrblUnit, rest: str) -> int:
    """``$x=value``: system.c reads the number (2), '=' (3), the value (2), nothing after it
    and x <= 255 (3); then settings.c settings_store_global_setting checks in its order."""
    got = read_float(rest, 0)
    if got is None:
        return 2
    parameter, end = got
    if rest[end:end + 1] != "=":
        return 3
    got = read_float(rest, end + 1)
    if got is None:
        return 2
    value, end = got
    if end != len(rest) or parameter > 255:
        return 3
    return store_setting(u, int(parameter) & 0xFF, value)


def store_setting(u: GrblUnit, number: int, value: float) -> int:
    """settings.c settings_store_global_setting: negative 4; an axis setting (100 and up) is
    100 + 10 * kind + axis, anything else there 3; $0 below 3 is 6 (on the truncated uint8
    value); $20 without homing 10; an unknown number 3; $22=0 turns $20 off too."""
    if value < 0:
        return 4
    setting = u.spec.settings.get(number)
    if setting is None:
        return 3
    step_rate = u.v.option("MAX_STEP_RATE_HZ")
    if step_rate and number >= 100 and number < 120:
        other = u.settings[number + 10] if number < 110 else u.settings[number - 10]
        if value * other > step_rate * 60.0:
            return 12
    if setting.type != "float":
        as_uint8 = int(math.trunc(value)) & 0xFF
        if as_uint8 < setting.lo:
            return setting.below            # $0: int_value < 3 is 6 (settings.c case 0)
        if as_uint8 and any(not u.settings[k] for k in setting.needs):
            return 10                       # $20 without homing (settings.c case 20)
    u.settings[number] = setting.coerce(value)
    if not u.settings[number]:
        for other in setting.clears:        # settings.c case 22: homing off, soft limits off
            u.settings[other] = 0
    if number == 13:                        # settings.c case 13: system_flag_wco_change
        u._wco_counter = 0
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
    if not u.switches:
        return _seek_without_switch(u, t)
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


HOMING_CYCLE_0 = (2,)   # config.h HOMING_CYCLE_0: Z first (then X and Y, cycle 1)
SEARCH_SCALAR = 1.5     # config.h HOMING_AXIS_SEARCH_SCALAR


def _seek_without_switch(u: GrblUnit, t: float) -> None:
    """A unit whose limit switches never close (``switches=False``): limits.c limits_go_home
    zeroes the first cycle's axes and seeks 1.5 times their travel toward the switch at the
    seek rate; the switch is not found, so the seek's end is ALARM:9 (homing fail, approach).
    A reset on the way is ALARM:6; either way the ``$H`` line is answered ok before the
    banner, as a reset during homing is (protocol.c)."""
    pos = list(u.planner.where(t)[0])
    target = list(pos)
    for axis in HOMING_CYCLE_0:
        pos[axis] = 0.0
        travel = SEARCH_SCALAR * u.settings[130 + axis]
        target[axis] = -travel if int(u.settings[23]) & (1 << axis) else travel
    u.planner.clear(pos)
    move = u.planner.make(pos, target, max(u.settings[25], 1e-6) / 60.0, "homeseek")
    u.state = "Home"
    u._busy = ("home",)
    if move is None:
        u._homing_failed(t, 9)
        return None
    u.planner.push(move)
    u.planner.start_head(t, 0.0)
    return None
