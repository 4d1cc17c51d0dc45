"""Marlin checks at the edges where a wrong number shows: a command's rarer forms (M203 T
alone, M204 S0, M575's shorthand rates on another port), the EEPROM read back while it holds
nothing, the temperature auto-report going on across other commands, the print timer past an
hour, move durations where the planner's formulas differ (a move too short to reach its
speed, an axis whose acceleration limits the block, a long move at a set feedrate, a full
planner), a homing from higher up, the cold-extrusion limit read against the hotend and not
the bed, and heater waits bounded by the temperatures the unit reports during them.

Expected values come from Marlin 2.1.2.4's source (cited per check) and the variant's table;
settings are put back after each check (depth.restoring). Motion and heat checks are opt-in.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from conform.families.marlin.conformance.check import MarlinCheck, Outcome
from conform.families.marlin.conformance.check import ok_kind as _ok_kind
from conform.families.marlin.conformance.depth import (
    _POS,
    State,
    _assign,
    _compare,
    _m113_restore,
    _only,
    base_state,
    put,
    read_state,
    restoring,
    set_case,
)
from conform.families.marlin.conformance.fromstate import (
    _TEMPS,
    HOMING_SLACK,
    _hot,
    _shown,
    _where,
    homing_time,
)
from conform.families.marlin.conformance.session import Session
from conform.families.marlin.spec import MarlinSpec
from conform.families.marlin.unit import settings as st

# Configuration.h DEFAULT_ACCELERATION and DEFAULT_MAX_ACCELERATION {3000, 3000, 100, 10000}:
# planner.cpp _populate_block limits a block's acceleration by each axis in it (LIMIT_ACCEL)
ACCELERATION = 3000.0
MAX_ACCELERATION = (3000.0, 3000.0, 100.0, 10000.0)
FIRST_MOVE_DELAY = 0.1      # planner.h BLOCK_DELAY_FOR_1ST_MOVE (ms 100)
TEMP_HYSTERESIS = 3.0       # Configuration.h TEMP_HYSTERESIS / TEMP_BED_HYSTERESIS
SLOPE_TIME = 60.0           # Configuration_adv.h MIN_COOLING_SLOPE_TIME (and _BED)
_MISMATCH = re.compile(r"^echo:EEPROM version mismatch \(EEPROM=.* Marlin=V\d+\)$")
_RETRIEVED = re.compile(r"^echo:V\d+ stored settings retrieved \(\d+ bytes; crc \d+\)$")


# -- settings and replies (no opt-in) ---------------------------------------------------------

def m575_other_port(s: Session) -> Outcome:
    """M575 P5 with each shorthand rate (M575.cpp: 24..1152 times 100, 250 and 500 times
    1000, 19 38 57 115 the rates they stand for) and with 1000 (no shorthand: implausible).
    Port 5 is none of the ports M575 can set (set1 P0, set2 P1, set3 P2, or P-99 for all), so
    a plausible rate is answered with a plain ok and no port is touched, in any build."""
    shorthands = (24, 96, 192, 384, 576, 1152, 250, 500, 19, 38, 57, 115)
    wrong = []
    for b in shorthands:
        got = _only(s.talk(f"M575 P5 B{b}\n".encode()), s)
        if got:
            wrong.append(f"B{b}: {' | '.join(got)}")
    got = _only(s.talk(b"M575 P5 B1000\n"), s)
    if got != ["echo:?(B)aud rate implausible."]:
        wrong.append(f"B1000: {' | '.join(got) or 'ok alone'}")
    return not wrong, "ok alone for B" + ",".join(map(str, shorthands)) + \
        "; echo:?(B)aud rate implausible. for B1000", "; ".join(wrong) or "as expected"


def m575_own_port(s: Session) -> Outcome | tuple[None, str, str]:
    """M575 B<the link's rate> without P, and with P0: ``echo: Serial 0 baud rate set to
    <rate>`` (port -99, every port, or 0). It reopens the port, so only the emulator (whose
    link keeps its rate) is asked; the shorthand 250 stands for 250000."""
    want = "echo: Serial 0 baud rate set to 250000, twice"
    if not s.target.emulated:
        return None, want, "a real port is reopened by M575: not asked"
    got = [_only(s.talk(f"{c}\n".encode()), s) for c in ("M575 B250", "M575 P0 B250000")]
    line = ["echo: Serial 0 baud rate set to 250000"]
    return got == [line, line], want, " ; ".join(" | ".join(g) or "ok alone" for g in got)


def eeprom_read_empty(code: str) -> Callable[[Session], Outcome]:
    """M504 / M501 from BASE. settings.cpp _load: a stored layout is retrieved (M501) or
    reported valid (M504); a version mismatch (nothing stored: recorded at every boot of the
    native build) makes M501 load the defaults (reset(): ``Hardcoded Default Settings
    Loaded``) while M504, validating only, changes nothing. Neither writes the EEPROM."""
    def body(s: Session) -> Outcome:
        printed = _only(s.talk(f"{code}\n".encode(), timeout=4.0), s)
        state = read_state(s)
        empty = bool(printed) and bool(_MISMATCH.match(printed[0]))
        if code == "M504":
            if not empty:
                ok = printed == ["echo:EEPROM OK"]
                return ok and _compare(base_state(), state, [], [])[0], \
                    "echo:EEPROM OK (a layout stored); the settings unchanged", \
                    " | ".join(printed) + "; " + _compare(base_state(), state, [], [])[2]
            ok, expected, actual = _compare(base_state(), state, printed[:1], printed)
            return ok, "the version mismatch alone, " + expected, actual
        if not empty:
            if printed and _RETRIEVED.match(printed[0]):
                return None, "an empty EEPROM", "the EEPROM holds settings: not applicable"
            return False, "a mismatch or the stored settings retrieved", " | ".join(printed)
        want = State(st.defaults(s.v), base_state().fr, base_state().flow)
        return _compare(want, state, [printed[0], "echo:Hardcoded Default Settings Loaded"],
                        printed)
    return restoring(body)


def reports_go_on(s: Session) -> Outcome:
    """M155 S1, then M155 without S (M155.cpp: only seenval('S') sets the interval), an
    unknown command with an S word, M115 and M110 without N: the reports go on every second
    (the auto-reporter runs in idle(), untouched by these), and each command is answered at
    once (none of them waits for the planner or stops it)."""
    problems = []
    try:
        s.talk(b"M155 S1\n")
        for command in ("M155", "M9997 S0", "M115", "M110"):
            got = s.talk(f"{command}\n".encode(), timeout=3.0)
            ok_t = next((t for t, x in zip(got.times, got.lines, strict=True)
                         if _ok_kind(s, x)), None)
            if ok_t is None or ok_t - got.t0 > 0.5:
                problems.append(f"{command}: " + ("no ok" if ok_t is None else
                                                  f"ok after {ok_t - got.t0:.2f} s"))
        later = [x for x in s.wait(3.3).lines if s.spec.classify(x)[0] == "temps"]
        if len(later) < 3:
            problems.append(f"{len(later)} reports in the 3.3 s after")
    finally:
        s.talk(b"M155 S0\n")
    return not problems, "each ok within 0.5 s; then 3 or more reports in 3.3 s", \
        "; ".join(problems) or "as expected"


def timer_hours(s: Session) -> Outcome:
    """M75, a dwell of 1 h 1 min 1 s, M31: libs/duration_t.h toString ``%ih %im %is`` with the
    minutes of the hour (m % 60). An hour of dwell is asked of the emulator only."""
    want = "echo:Print time: 1h 1m 1s"
    if not s.target.emulated:
        return None, want, "an hour's dwell: asked of the emulator only"
    was = _only(s.talk(b"M113\n"), s)
    try:
        s.talk(b"M113 S0\n")       # no busy: line every 2 s of the hour
        s.talk(b"M77\n")
        s.talk(b"M75\n")
        s.talk(b"G4 S3661\n", timeout=3700.0)
        got = s.talk(b"M31\n")
    finally:
        s.talk(b"M77\n")
        s.talk(_m113_restore(was))
    return got.lines[:1] == [want], want, got.text()


def _ok_after(s: Session, command: str, timeout: float) -> float | None:
    got = s.talk(f"{command}\n".encode(), timeout=timeout)
    ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)), None)
    return None if ok_t is None else ok_t - got.t0


def m0_timed(s: Session) -> Outcome:
    """M0_M1.cpp: P<ms> or S<s> is how long wait_for_user_response waits (no M108 sent
    here): M0 P500 ends after 0.5 s, M0 S1 after 1 s."""
    problems = []
    try:
        for command, lo, hi in (("M0 P500", 0.45, 0.8), ("M0 S1", 0.95, 1.4)):
            took = _ok_after(s, command, 3.0)
            if took is None or not lo <= took <= hi:
                problems.append(f"{command}: " + ("no ok in 3 s" if took is None else
                                                  f"ok after {took:.2f} s"))
    finally:
        s.target.send(b"M108\n")
        s.wait(0.3)
    return not problems, "M0 P500: ok after 0.45 .. 0.8 s; M0 S1: 0.95 .. 1.4 s", \
        "; ".join(problems) or "as expected"


def m0_after_moves(s: Session) -> Outcome:
    """M0_M1.cpp: planner.synchronize() first, then the wait: behind two queued 1 s moves
    (X10 and back) M0 P200 ends 0.2 s after the second move."""
    put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
    s.talk(b"G92 X0 Y0 Z0 E0\n")
    block = block_time(s.v, (10.0, 0, 0, 0), 10.0)
    want = FIRST_MOVE_DELAY + 2 * block + 0.2
    lo, hi = want - 0.1, want + 0.4
    try:
        s.talk(b"G1 X10 F600\n", linger=0.0)
        first = s.target.now()
        s.talk(b"G1 X0 F600\n", linger=0.0)
        got = s.talk(b"M0 P200\n", timeout=6.0)
        ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)),
                    None)
        took = None if ok_t is None else ok_t - first
    finally:
        s.target.send(b"M108\n")
        s.talk(b"M400\n", timeout=10.0)
    return took is not None and lo <= took <= hi, f"M0 P200's ok {lo:.2f} .. {hi:.2f} s " \
        "after the first move", "no ok" if took is None else f"after {took:.2f} s"


# -- moves (motion opt-in) --------------------------------------------------------------------

def block_time(v: object, delta: tuple[float, float, float, float], feed: float) -> float:
    """A block from rest to rest as planner.cpp plans it on the default settings: the speed
    ``feed`` (mm/s) held to each axis' max feedrate, the acceleration to each axis' maximum
    (both scaled by the axis' share of the move), a trapezoid when the move is long enough
    to reach its speed (d / v + v / a), else a triangle (2 sqrt(d / a)); times the machine's
    own pace (the variant's motion_time_pct)."""
    dist = math.sqrt(sum(d * d for d in delta[:3])) or abs(delta[3])
    speed, accel = feed, ACCELERATION
    for i in range(4):
        if delta[i]:
            speed = min(speed, v.max_feedrate[i] * dist / abs(delta[i]))   # type: ignore[attr-defined]
            accel = min(accel, MAX_ACCELERATION[i] * dist / abs(delta[i]))
    if dist > speed * speed / accel:
        t = dist / speed + speed / accel
    else:
        t = 2 * math.sqrt(dist / accel)
    return t * v.motion_time_pct / 100.0   # type: ignore[attr-defined]


def move_durations(s: Session) -> Outcome:
    """From X0 Y0 Z0 at rest, each move alone, G1 then M400 timed: a 0.1 mm move at 300 mm/s
    (a triangle: it never reaches its speed), X10 with 0.099 mm of Z (Z's 100 mm/s² would
    allow 10000 mm/s² for the block: X's 3000 limits it), and X200 at F600 (20 s: the
    feedrate is mm/min over 60). Each takes the first-move delay and its block's time."""
    put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
    s.talk(b"G92 X0 Y0 Z0 E0\n")
    problems, shown = [], []
    cases = (("G1 X0.1 F18000", (0.1, 0, 0, 0), 300.0, "G1 X0 F3000"),
             ("G1 X10 Z0.099 F600", (10.0, 0, 0.099, 0), 10.0, "G1 X0 Z0 F3000"),
             ("G1 X200 F600", (200.0, 0, 0, 0), 10.0, "G1 X0 F18000"))
    for command, delta, feed, back in cases:
        want = FIRST_MOVE_DELAY + block_time(s.v, delta, feed)
        lo, hi = want * 0.99 - 0.02, want * 1.01 + 0.05
        s.talk(f"{command}\n".encode())
        got = s.talk(b"M400\n", timeout=want + 10.0)
        took = got.t - got.t0 if got.lines else math.inf
        shown.append(f"{command}: {lo:.3f} .. {hi:.3f} s")
        if not lo <= took <= hi:
            problems.append(f"{command} took {took:.3f} s")
        s.talk(f"{back}\n".encode())
        s.talk(b"M400\n", timeout=30.0)
    return not problems, "; ".join(shown), "; ".join(problems) or "as expected"


def planner_full(s: Session) -> Outcome:
    """Moves of 1 s each, X10 and back, sent one after the other at rest: the planner takes
    BLOCK_BUFFER_SIZE - 1 of them at once (planner.h moves_free), the next one's ok waits
    until the first block is done (planner.cpp buffer_steps waits for a free block):
    first-move delay + one block after the first was sent."""
    put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
    s.talk(b"G92 X0 Y0 Z0 E0\n")
    n = s.v.planner_blocks
    block = block_time(s.v, (10.0, 0, 0, 0), 10.0)
    want = FIRST_MOVE_DELAY + block
    lo, hi = want - 0.25, want + 0.3
    first = None
    took = None
    try:
        for i in range(n + 1):
            got = s.talk(f"G1 X{10 if i % 2 == 0 else 0} F600\n".encode(), timeout=5.0,
                         linger=0.0)
            first = got.t0 if first is None else first
            if i == n:
                ok_t = next((t for t, x in zip(got.times, got.lines, strict=True)
                             if _ok_kind(s, x)), None)
                took = None if ok_t is None else ok_t - first
    finally:
        s.talk(b"M410\n", timeout=4.0)
        s.talk(b"M400\n", timeout=30.0)
    return took is not None and lo <= took <= hi, f"move {n + 1}'s ok {lo:.2f} .. {hi:.2f} s " \
        "after the first move was sent", "no ok" if took is None else f"after {took:.2f} s"


def homing_from_z5(s: Session) -> Outcome:
    """G28, G1 X10 Y10 Z5 and G4 P0 (a dwell behind a queued move waits for it: G4.cpp
    synchronize), then G28 timed: Z homes at 4 mm/s (HOMING_FEEDRATE_MM_M Z 4*60) and bumps
    back 2 mm and again at a quarter; then M410 at rest: the steppers stand at home
    (position and counts 0)."""
    put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
    s.talk(b"G28\n", timeout=60.0)
    s.talk(b"G1 X10 Y10 Z5 F3000\n", timeout=10.0)
    s.talk(b"G4 P0\n", timeout=10.0)
    lo = homing_time([10.0, 10.0, 5.0])
    got = s.talk(b"G28\n", timeout=30.0)
    ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)), None)
    took = None if ok_t is None else ok_t - got.t0
    s.talk(b"M410\n", timeout=4.0)
    pos = _where(s)
    problems = []
    if took is None or not lo <= took <= lo + HOMING_SLACK:
        problems.append("no ok" if took is None else f"G28 took {took:.3f} s")
    if pos is None or [round(x, 2) for x in pos[:3]] + pos[4:] != [0.0] * 6:
        problems.append(f"after M410 {_shown(pos)}")
    return not problems, f"G28 ok after {lo:.2f} .. {lo + HOMING_SLACK:.2f} s; after M410 " \
        "X:0.00 Y:0.00 Z:0.00, Count 0 0 0", "; ".join(problems) or "as expected"


def quickstop_no_keepalive(s: Session) -> Outcome:
    """M113 S0 (no busy: lines), G1 X50 F600 (5 s), M400 behind it, and a plain M410 1 s in:
    M410 acts as it is read (queue.cpp critical commands, or the emergency parser), the planner
    is emptied, and M400's planner.synchronize() (while has_blocks_queued() ||
    cleaning_buffer_counter) ends after the 1 s quick-stop wait (at once with the emergency
    parser), not when the move would have ended; the keepalive plays no part.
    M410's own ok follows in its turn."""
    was = _only(s.talk(b"M113\n"), s)
    put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
    try:
        s.talk(b"M113 S0\nG92 X0 Y0 Z0 E0\n")
        start = _where(s)
        s.talk(b"G1 X50 F600\n", linger=0.0)
        s.target.send(b"M400\n")
        s.wait(1.0)
        s.target.send(b"M410\n")
        t0 = s.target.now()
        got = s.collect(until=lambda ls: s.oks(ls) >= 2, timeout=8.0, linger=0.1)
        oks = [t - t0 for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)]
        pos = _where(s)
    finally:
        s.talk(b"M400\n", timeout=10.0)
        s.talk(_m113_restore(was))
    # the emergency parser's stop does not hold the loop (as in fromstate.quickstop_at_rest)
    lo, hi = (0.0, 0.6) if s.v.on("EMERGENCY_PARSER") else (0.8, 1.6)
    problems = []
    if len(oks) != 2 or not lo <= oks[0] <= hi:
        problems.append(f"oks at {', '.join(f'{x:.2f}' for x in oks) or 'none'} s after M410")
    # how far X went, from its stepper count (M114's Count, at M92's defaults): the logical X
    # M410 takes from the steppers also carries what G92 and M206 shifted
    went = None if pos is None or start is None else (pos[4] - start[4]) / s.v.steps_per_mm[0]
    if went is None or not 5.0 <= went <= 20.0:
        problems.append(f"then {_shown(pos)}" + ("" if went is None else f" ({went:.2f} mm on X)"))
    return not problems, f"M400's ok {lo:.1f} .. {hi:.1f} s after M410, then M410's; X part " \
        "way (5 .. 20 mm by its count)", "; ".join(problems) or "as expected"


# -- heat (and motion) ------------------------------------------------------------------------

def _m302_back(was: list[str]) -> bytes:
    m = re.match(r"echo:Cold extrudes are (en|dis)abled \(min temp (-?\d+)C\)", was[0]) \
        if was else None
    return f"M302 S{m.group(2)} P{int(m.group(1) == 'en')}\n".encode() if m else \
        f"M302 S{st.EXTRUDE_MINTEMP} P0\n".encode()


def _warm(s: Session, setter: str, group: int, target: int, until: float, start: float
          ) -> float:
    """``setter`` S``target`` (M104 / M140), then M105 every 0.5 s (2 min at most) until the
    heater (``group`` of _TEMPS: 1 hotend, 3 bed) reads ``until`` or more; its last reading."""
    s.talk(f"{setter} S{target}\n".encode())
    hot = start
    for _ in range(240):
        s.wait(0.5)
        m = _TEMPS.search(" ".join(s.talk(b"M105\n").lines))
        hot = float(m.group(group)) if m else hot
        if hot >= until:
            break
    return hot


def extrude_above_limit(s: Session) -> Outcome:
    """M302 S<now + 8> (the limit, cold extrusion not allowed), the hotend heated past it and
    the bed left cold: G1 E1 extrudes (temperature.h tooColdToExtrude compares the hotend's
    temperature with extrude_min_temp: < prevents, >= allows; the bed plays no part)."""
    now, why = _hot(s, "M109")
    want = "no 'cold extrusion prevented'; E:1.00"
    if now is None:
        return False, want, why
    was = _only(s.talk(b"M302\n"), s)
    limit = round(now) + 8
    try:
        s.talk(f"M302 S{limit} P0\n".encode())
        hot = _warm(s, "M104", 1, limit + 6, limit + 3, now)
        s.talk(b"G92 E0\nM82\n")
        printed = _only(s.talk(b"G1 E1 F300\n"), s)
        s.talk(b"M400\n", timeout=10.0)
        pos = next((x for x in s.talk(b"M114\n").lines if _POS.match(x)), "")
    finally:
        s.talk(b"M104 S0\n")
        s.talk(_m302_back(was))
        s.talk(b"G92 E0\n")
    ok = printed == [] and " E:1.00 " in pos and hot >= limit + 3
    return ok, want + f" (hotend {limit + 3}+ °C, limit {limit} °C)", \
        f"hotend {hot:.1f} °C; {' | '.join(printed) or 'nothing printed'}; {pos}"


SLOPE_DEG = (1.5, 1.0)     # Configuration_adv.h MIN_COOLING_SLOPE_DEG, MIN_COOLING_SLOPE_DEG_BED


def slope_checks(s: Session) -> Outcome:
    """The hotend heated 26 °C, then M109 R 15 °C below where it started (below the room:
    unreachable). temperature.cpp wait_for_hotend (wants_to_cool): the first pass of the loop
    notes the temperature, and every MIN_COOLING_SLOPE_TIME (60 s) after it the wait gives up
    when the temperature fell less than MIN_COOLING_SLOPE_DEG (1.5 °C) since the last note.
    From the wait's own reports (one a second): no ok at a check whose minute dropped more
    than 1.8 °C, and the ok by the first check whose minute dropped less than 1.2 °C."""
    now, why = _hot(s, "M109")
    want = "the ok at the first 60 s check with a drop under 1.5 °C, not at one with more"
    if now is None:
        return False, want, why
    try:
        _warm(s, "M104", 1, round(now) + 26, now + 25.5, now)
        s.target.send(f"M109 R{max(round(now) - 15, 0)}\n".encode())
        t0 = s.target.now()
        got = s.collect(until=lambda ls: s.oks(ls) >= 1, timeout=250.0, linger=0.1)
    finally:
        s.talk(b"M104 S0\n")
    ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)), None)
    readings = [(t, float(m.group(1))) for t, x in zip(got.times, got.lines, strict=True)
                if (m := _TEMPS.search(x)) and " W:" in x]
    if ok_t is None or not readings:
        return False, want, "no ok within 250 s" if ok_t is None else "no W: reports"

    def at(when: float) -> float | None:
        near = min(readings, key=lambda r: abs(r[0] - when))
        return near[1] if abs(near[0] - when) <= 0.6 else None

    first = readings[0][0]
    problems, k = [], 1
    while first + SLOPE_TIME * k <= ok_t + 2.0:
        check = first + SLOPE_TIME * k
        a, b = at(check - SLOPE_TIME), at(check)
        if a is None or b is None:
            break
        drop = a - b
        if drop > SLOPE_DEG[0] + 0.3 and abs(ok_t - check) <= 1.5:
            problems.append(f"ok at the {k}. check although {drop:.1f} °C fell")
        if drop < SLOPE_DEG[0] - 0.3:
            if ok_t > check + 1.5:
                problems.append(f"ok {ok_t - check:.1f} s after the {k}. check "
                                f"({drop:.1f} °C fell)")
            break
        k += 1
    return not problems, want, "; ".join(problems) or f"ok {ok_t - t0:.1f} s after M109 R"


def wait_bounded(code: str, cool: bool, near: bool = False) -> Callable[[Session], Outcome]:
    """M109 / M190 (S up by 12 °C, or R down by 8 °C after heating) with the temperature
    auto-report at 1 s, its phase off the wait's own reports. temperature.cpp
    wait_for_hotend / wait_for_bed: the residency timer starts when |target - temp| <
    TEMP_WINDOW (a third later on the first pass) and starts again whenever it is more than
    TEMP_HYSTERESIS away; the wait ends once the timer ran TEMP_RESIDENCY_TIME and the
    temperature is no longer heating (cooling) toward its target. So from the reports: the ok
    comes no sooner than the residency after the last report more than the hysteresis away
    (a cooling wait may give up earlier only at a slope check, 60 s on), and no later than
    4/3 of the residency after the first report inside the window (once the target is
    reached), with 1.5 s for the loop's pace. ``near``: the heater switched off 0.8 s before
    an R 2 °C below where it was, so the wait starts only a little more than the window
    above its target (on the emulator 1.2 °C: less than the slope's 1.5 °C in the minute)."""
    group, off = (1, "M104 S0") if code == "M109" else (3, "M140 S0")   # _TEMPS: T, B
    setter = "M104" if code == "M109" else "M140"

    def run(s: Session) -> Outcome:
        now, why = _hot(s, code)
        residency = float(s.v.temp_residency if code == "M109" else s.v.temp_bed_residency)
        win = float(s.v.temp_window)
        want = "ok after the residency past the last report beyond the hysteresis, and " \
            "within 4/3 residency + 1.5 s of the first report inside the window"
        if now is None:
            return False, want, why
        try:
            start = now
            if cool:
                start = _warm(s, setter, group, round(now) + 15,
                              round(now) + 14.95 if near else now + 12, now)
            target = round(start) - 8 if cool else round(now) + 12
            s.talk(b"M155 S1\n", linger=0.0)
            if near:
                target = round(start) - 2
                s.talk(f"{setter} S0\n".encode(), linger=0.0)
                s.wait(0.8)
            else:
                s.wait(0.9)    # the reports 0.1 s after each of the wait's own
            s.target.send(f"{code} {'R' if cool else 'S'}{target}\n".encode())
            t0 = s.target.now()
            got = s.collect(until=lambda ls: s.oks(ls) >= 1, timeout=90.0, linger=0.1)
        finally:
            s.talk(b"M155 S0\n")
            s.talk(f"{off}\n".encode())
        ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)),
                    None)
        if ok_t is None:
            return False, want, f"no ok within 90 s after {code} {target}"
        readings = []
        for t, x in zip(got.times, got.lines, strict=True):
            m = _TEMPS.search(x)
            if m and t <= ok_t:
                readings.append((t, float(m.group(group))))
        far = [t for t, temp in readings if abs(temp - target) > TEMP_HYSTERESIS + 0.25]
        problems = []
        lower = (far[-1] + residency) if far else None
        if lower is not None and ok_t < lower - 0.05 and not (cool and ok_t - t0 >= SLOPE_TIME - 1):
            problems.append(f"ok {lower - ok_t:.2f} s before the residency after the report "
                            f"at +{far[-1] - t0:.2f} s")
        after = [(t, temp) for t, temp in readings if not far or t > far[-1]]
        inside = next((t for t, temp in after if abs(temp - target) < win - 0.1), None)
        reached = next((t for t, temp in after
                        if (temp <= target if cool else temp >= target)), None)
        if inside is None:
            problems.append("no report inside the window before the ok")
        elif reached is not None:
            upper = max(inside + residency * 4 / 3, reached) + 1.5
            if ok_t > upper:
                problems.append(f"ok {ok_t - upper:.2f} s after the latest it may come")
        return not problems, want, "; ".join(problems) or \
            f"ok {ok_t - t0:.2f} s after {code} {'R' if cool else 'S'}{target}"
    return run


def generate(spec: MarlinSpec, vid: str, profile: str = "quick") -> list[MarlinCheck]:
    v = spec.variant(vid)
    cmd = {k: x.cite for k, x in spec.commands.items()}
    temp = v.cite
    out = [
        MarlinCheck(f"{vid}/M200-M205.cpp/settings/m203-t-alone", cmd["M203"] + " (parser.seen"
                    "(\"T\" ...): T alone is no report; nothing set)", "M203 T0: ok alone, "
                    "nothing changed", set_case("M203 T0", lambda w: None)),
        MarlinCheck(f"{vid}/M200-M205.cpp/settings/m201-t-alone", cmd["M201"],
                    "M201 T0: ok alone, nothing changed", set_case("M201 T0", lambda w: None)),
        MarlinCheck(f"{vid}/M200-M205.cpp/settings/m204-s0", cmd["M204"] + " (seenval('S'): "
                    "travel and print acceleration, 0 taken as given)", "M204 S0: P and T 0",
                    set_case("M204 S0", lambda w: (_assign("M204", 0, 0.0)(w),
                                                   _assign("M204", 2, 0.0)(w)))),
        MarlinCheck(f"{vid}/M500-M504.cpp/settings/m504-changes-nothing", cmd["M504"] +
                    "; settings.cpp _load (validating: no reset)", "M504: the EEPROM's state, "
                    "the settings as they were", eeprom_read_empty("M504")),
        MarlinCheck(f"{vid}/M500-M504.cpp/settings/m501-empty-defaults", cmd["M501"] +
                    "; settings.cpp _load (a version mismatch: reset())", "M501 with nothing "
                    "stored: the defaults loaded", eeprom_read_empty("M501")),
    ]
    if spec.command("M575", v) is not None:
        out.append(MarlinCheck(f"{vid}/M575.cpp/reply/m575-p5-shorthands", cmd["M575"] +
                               " (the shorthand switch; P5: no port's set1/2/3)",
                               "M575 P5 B<shorthand>: a plain ok each; "
                               "B1000 implausible", m575_other_port))
        out.append(MarlinCheck(f"{vid}/M575.cpp/reply/m575-port-0", cmd["M575"] + " (port "
                               "-99 or 0: set1)", "M575 B250 and M575 P0 B250000: Serial 0 "
                               "baud rate set to 250000 (the emulator only)", m575_own_port))
    if v.on("AUTO_REPORT_TEMPERATURES"):
        out.append(MarlinCheck(f"{vid}/M155.cpp/report/m155-goes-on", cmd["M155"] + "; "
                               "MarlinCore.cpp idle (auto_reporter.tick)", "M155 S1 goes on "
                               "across M155 alone, an unknown command, M115, M110; each "
                               "answered at once", reports_go_on))
    if v.on("EMERGENCY_PARSER"):      # HAS_RESUME_CONTINUE: M0 exists (see checks.m0_user_wait)
        out.append(MarlinCheck(f"{vid}/M0_M1.cpp/reply/m0-p-s-timed", cmd["M0"], "M0 P500 and "
                               "M0 S1 end by themselves after their time", m0_timed))
        out.append(MarlinCheck(f"{vid}/M0_M1.cpp/motion/m0-after-moves", cmd["M0"] + " "
                               "(planner.synchronize first)", "M0 P200 behind two moves: its "
                               "time after the last", restoring(m0_after_moves), motion=True))
    out += [
        MarlinCheck(f"{vid}/G0_G1.cpp/motion/move-durations", cmd["G1"] + "; planner.cpp "
                    "_populate_block, calculate_trapezoid_for_block; Configuration.h "
                    "DEFAULT_ACCELERATION, DEFAULT_MAX_ACCELERATION, DEFAULT_MAX_FEEDRATE",
                    "a 0.1 mm move, X with a little Z, X200 at F600: each its block's time",
                    restoring(move_durations), motion=True),
        MarlinCheck(f"{vid}/G0_G1.cpp/motion/planner-full", cmd["G1"] + "; " +
                    temp["block_buffer"], "the move after a full planner: its ok when the "
                    "first block is done", restoring(planner_full), motion=True),
        MarlinCheck(f"{vid}/G28.cpp/motion/g28-from-z5", cmd["G28"] + "; motion.cpp homeaxis; "
                    "Configuration.h HOMING_FEEDRATE_MM_M; Configuration_adv.h HOMING_BUMP_MM,"
                    " HOMING_BUMP_DIVISOR; MarlinCore.cpp quickstop_stepper", "a second G28 "
                    "from Z5: Z's homing time; M410 after it: all at 0",
                    restoring(homing_from_z5), motion=True),
        MarlinCheck(f"{vid}/M302.cpp/heat/extrude-above-limit", cmd["M302"] + "; "
                    "temperature.h tooColdToExtrude; planner.cpp _populate_block",
                    "M302 S<limit>, hotend past it, bed cold: G1 E1 extrudes",
                    extrude_above_limit, motion=True, heat=True),
        MarlinCheck(f"{vid}/M410.cpp/motion/m410-no-keepalive", cmd["M410"] + "; planner.cpp "
                    "Planner::synchronize; gcode/host/M113.cpp", "M113 S0, M400 behind a move, "
                    "M410: M400 ends after the quick stop", restoring(quickstop_no_keepalive),
                    motion=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m109-r-slope-checks", cmd["M109"] + "; "
                    "temperature.cpp wait_for_hotend (wants_to_cool: MIN_COOLING_SLOPE_DEG "
                    "1.5 per MIN_COOLING_SLOPE_TIME 60 s)", "M109 R below the room from 26 °C "
                    "up: the ok at the first slope check with under 1.5 °C",
                    slope_checks, heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m109-s-bounded", cmd["M109"] + "; " +
                    temp["temp_residency"] + "; " + temp["temp_window"], "M109 S up 12 °C: "
                    "the ok within the bounds the reports give", wait_bounded("M109", False),
                    heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m109-r-cool-bounded", cmd["M109"] + "; " +
                    temp["temp_residency"] + "; " + temp["temp_window"], "M109 R down 8 °C: "
                    "the ok within the bounds the reports give", wait_bounded("M109", True),
                    heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m109-r-near-bounded", cmd["M109"] + "; " +
                    temp["temp_residency"] + "; " + temp["temp_window"], "M109 R just past the "
                    "window below a cooling hotend: the ok within the bounds the reports give",
                    wait_bounded("M109", True, near=True), heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m190-r-cool-bounded", cmd["M190"] + "; " +
                    temp["temp_bed_residency"] + "; " + temp["temp_window"], "M190 R down "
                    "8 °C: the ok within the bounds the reports give",
                    wait_bounded("M190", True), heat=True),
    ]
    if profile == "full":
        out.append(MarlinCheck(f"{vid}/M75-M78.cpp/timer/m31-hours", cmd["M31"] + "; "
                               "libs/duration_t.h toString (%ih %im %is)", "M31 after 1 h 1 min "
                               "1 s: 1h 1m 1s (the emulator only)", timer_hours))
    return out
