"""Marlin checks run from a state where a wrong effect shows: a command's neighbour (M201 E
beside M92 E), a second homing (the axes' place known, the bump moves timed), a quick stop at
rest and in the middle of a move, heater waits that start inside the window, cool down, or
last longer than the cooling-slope period.

Each check reads back what the command may change and what it must not (the other axes, E,
the step counts, the other heater's target), with the expected values from the source cited.
Motion and heat checks are opt-in as everywhere; the settings and the quick stop at rest are
not (M410 at rest moves nothing).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from copy import deepcopy

from conform.families.marlin.conformance.check import MarlinCheck, Outcome
from conform.families.marlin.conformance.check import ok_kind as _ok_kind
from conform.families.marlin.conformance.depth import (
    _POS,
    NEW,
    State,
    _assign,
    base_state,
    put,
    restoring,
    set_case,
)
from conform.families.marlin.conformance.heaters import (
    _countdown,
    _residency_problems,
    _temperature,
)
from conform.families.marlin.conformance.session import Session
from conform.families.marlin.spec import MarlinSpec
from conform.families.marlin.unit import settings as st

# Configuration.h HOMING_FEEDRATE_MM_M {50*60, 50*60, 4*60} (mm/s here); Configuration_adv.h
# HOMING_BUMP_MM {5, 5, 2} and HOMING_BUMP_DIVISOR {2, 2, 4}: motion.cpp homeaxis goes to the
# switch, backs off the bump and comes back at the feedrate / divisor
HOMING_FEED = (50.0, 50.0, 4.0)
BUMP_MM = (5.0, 5.0, 2.0)
BUMP_DIVISOR = (2.0, 2.0, 4.0)
HOMING_SLACK = 1.0     # s beyond the source's distances / feedrates: ramps, planner start delays
_TEMPS = re.compile(r"T:(-?[\d.]+) /(-?[\d.]+) B:(-?[\d.]+) /(-?[\d.]+)")


def _where(s: Session) -> list[float] | None:
    """M114's X Y Z E and Count X Y Z, or None."""
    for line in s.talk(b"M114\n").lines:
        m = _POS.match(line)
        if m:
            return [float(g) for g in m.groups()]
    return None


def _shown(p: list[float] | None) -> str:
    if p is None:
        return "no position from M114"
    return (f"X:{p[0]:.2f} Y:{p[1]:.2f} Z:{p[2]:.2f} E:{p[3]:.2f} "
            f"Count X:{int(p[4])} Y:{int(p[5])} Z:{int(p[6])}")


def _defaults(s: Session) -> None:
    """The build's default settings (steps, feedrates, no M206 offset), 100 % feed and flow."""
    put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))


def homing_time(native: list[float]) -> float:
    """Seconds a homing of X, Y and Z takes from ``native`` (mm from the switches) at least:
    each axis to the switch at its homing feedrate, the bump back, and the bump again at the
    feedrate / HOMING_BUMP_DIVISOR."""
    return sum(abs(native[i]) / HOMING_FEED[i] + BUMP_MM[i] / HOMING_FEED[i]
               + BUMP_MM[i] * BUMP_DIVISOR[i] / HOMING_FEED[i] for i in range(3))


def second_homing(s: Session) -> Outcome:
    """G28 once (the place unknown), a move to X10 Y10 Z1 and G92 E7, then G28 again, timed:
    the bump moves take their source time, X Y Z home (0 with no M206 offset), E stays 7,
    the counts 0."""
    _defaults(s)
    s.talk(b"G28\n", timeout=60.0)
    s.talk(b"G1 X10 Y10 Z1 F3000\n", timeout=10.0)
    s.talk(b"G92 E7\n")
    s.talk(b"M400\n", timeout=10.0)
    lo = homing_time([10.0, 10.0, 1.0])
    got = s.talk(b"G28\n", timeout=30.0)
    ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)), None)
    took = (ok_t - got.t0) if ok_t is not None else None
    pos = _where(s)
    want = [0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0]
    problems = []
    if took is None or not lo <= took <= lo + HOMING_SLACK:
        problems.append("no ok" if took is None else f"G28 took {took:.3f} s")
    if pos is None or [round(x, 2) for x in pos] != want:
        problems.append(_shown(pos))
    return not problems, f"G28 ok after {lo:.2f} .. {lo + HOMING_SLACK:.2f} s; then " \
        f"{_shown(want)}", "; ".join(problems) or "as expected"


def quickstop_at_rest(s: Session) -> Outcome:
    """A plain M410 with nothing moving: the planner is empty, the position taken from the
    steppers is where the axes stand. A plain M410 acts as it is read (queue.cpp critical
    commands) and again in its turn, each quick stop waiting its 1 s: the ok ~2 s after
    (recorded: 2.0 s after a plain M410 in a move, 1.0 s for a numbered one). With the
    emergency parser the first stop does not hold the loop: ~1 s."""
    stops = 1 if s.v.on("EMERGENCY_PARSER") else 2
    lo, hi = stops - 0.1, stops + 0.6
    before = _where(s)
    got = s.talk(b"M410\n", timeout=4.0)
    ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)), None)
    after = _where(s)
    problems = []
    if ok_t is None or not lo <= ok_t - got.t0 <= hi:
        problems.append("no ok" if ok_t is None else f"ok after {ok_t - got.t0:.2f} s")
    if before is None or after is None or after[4:] != before[4:] or any(
            abs(a - b) > 0.011 for a, b in zip(after[:4], before[:4], strict=True)):
        problems.append(f"{_shown(before)} before, {_shown(after)} after")
    return not problems, f"ok after {lo:.1f} .. {hi:.1f} s; M114 as before (the same counts)", \
        "; ".join(problems) or "as expected"


def quickstop_in_move(s: Session) -> Outcome:
    """From X5 Y3: G1 X55 F600 (5 s), M410 1.0 s later: X stops on a whole step part way
    (recorded from X0: X:8.71, Count X:697), Y and Z where they were, and it stays there."""
    _defaults(s)
    steps = s.v.steps_per_mm
    s.talk(b"G1 X5 Y3 Z0 F3000\n", timeout=10.0)
    s.talk(b"M400\n", timeout=10.0)
    s.talk(b"G1 X55 F600\n", timeout=3.0)
    s.wait(1.0)
    s.talk(b"M410\n", timeout=5.0)
    at = _where(s)
    s.talk(b"M400\n", timeout=10.0)
    still = _where(s)
    problems = []
    if at is None:
        return False, "a position from M114", "no position from M114"
    x = at[0]
    if not 5.0 + 6.0 <= x <= 5.0 + 11.5:
        problems.append(f"X:{x:.2f} (not part way)")
    if abs(at[4] - round(x * steps[0])) > 1 or at[1:3] != [3.0, 0.0] or \
            at[5:] != [round(3.0 * steps[1]), 0.0]:
        problems.append(_shown(at))
    if still != at:
        problems.append(f"after M400 {_shown(still)}")
    return not problems, "X:11.00 .. 16.50 on a whole step (Count X = X * steps), Y:3.00 " \
        "Z:0.00, the same after M400", "; ".join(problems) or _shown(at)


def _hot(s: Session, code: str) -> tuple[float | None, str]:
    group = "t" if code == "M109" else "b"
    now = _temperature(s, group)
    if now is None:
        return None, "no sane temperature in M105's answer: nothing heated"
    return now, ""


def _wait(s: Session, command: str, timeout: float) -> tuple[list[tuple[float, str]],
                                                              float | None, float]:
    """Send ``command`` (a heater wait), collect to its ok: its W: reports, the ok's time,
    the time it was sent."""
    s.target.send(f"{command}\n".encode())
    t0 = s.target.now()
    got = s.collect(until=lambda ls: s.oks(ls) >= 1, timeout=timeout, linger=0.1)
    reports, ok_t = _countdown(s, got)
    return reports, ok_t, t0


def _temps(s: Session) -> tuple[float, float, float, float] | None:
    got = s.talk(b"M105\n")
    m = _TEMPS.search(got.lines[0]) if got.lines else None
    return tuple(float(g) for g in m.groups()) if m else None  # type: ignore[return-value]


def in_window(code: str) -> Callable[[Session], Outcome]:
    """M109 / M190 R at the temperature the heater already has: the residency timer starts
    a third of the residency late (first_loop), so the ok comes 4/3 of the residency after."""
    off = "M104 S0" if code == "M109" else "M140 S0"

    def run(s: Session) -> Outcome:
        now, why = _hot(s, code)
        residency = s.v.temp_residency if code == "M109" else s.v.temp_bed_residency
        lo, hi = residency * 4 / 3 - 0.2, residency * 4 / 3 + 1.5
        want = f"ok {lo:.1f} .. {hi:.1f} s after {code} R<now>, W: counting down to 0"
        if now is None:
            return False, want, why
        try:
            reports, ok_t, t0 = _wait(s, f"{code} R{now:.1f}", residency * 2 + 10)
        finally:
            s.talk(f"{off}\n".encode())
        took = None if ok_t is None else ok_t - t0
        problems = _residency_problems(s, code, reports, ok_t)
        if took is None or not lo <= took <= hi:
            problems.append("no ok" if took is None else f"ok after {took:.2f} s")
        return not problems, want, "; ".join(problems) or f"ok after {took:.2f} s"
    return run


def s_no_cooling_wait(s: Session) -> Outcome:
    """M109 S below the hotend's temperature: S does not wait to cool (no report, ok at
    once), the target is set, the bed's left alone."""
    now, why = _hot(s, "M109")
    want = "ok within 0.5 s, no W: report; then M105 /<lower target> and the bed's /0"
    if now is None:
        return False, want, why
    try:
        s.talk(f"M104 S{round(now) + 12}\n".encode())
        for _ in range(60):
            s.wait(0.5)
            t = _temperature(s, "t")
            if t is not None and t >= now + 8:
                break
        lower = round(now) + 2
        reports, ok_t, t0 = _wait(s, f"M109 S{lower}", 5.0)
        temps = _temps(s)
    finally:
        s.talk(b"M104 S0\n")
    problems = []
    if ok_t is None or ok_t - t0 > 0.5 or reports:
        problems.append("no ok" if ok_t is None else
                        f"ok after {ok_t - t0:.2f} s, {len(reports)} W: reports")
    if temps is None or (temps[1], temps[3]) != (float(lower), 0.0):
        problems.append(f"M105 {temps}")
    return not problems, want, "; ".join(problems) or "as expected"


def bed_cools(s: Session) -> Outcome:
    """M190 R below the bed's temperature waits for it to cool into TEMP_BED_WINDOW: right
    after the ok M105 shows the bed within the window of its target."""
    now, why = _hot(s, "M190")
    win = float(s.v.temp_window)
    want = f"after the ok: B within {win:g} °C of the R target"
    if now is None:
        return False, want, why
    try:
        s.talk(f"M140 S{round(now) + 15}\n".encode())
        hot = now
        for _ in range(120):
            s.wait(0.5)
            hot = _temperature(s, "b") or hot
            if hot >= now + 12:
                break
        target = round(hot) - 8
        _, ok_t, _ = _wait(s, f"M190 R{target}", 300.0)
        temps = _temps(s)
    finally:
        s.talk(b"M140 S0\n")
    if ok_t is None or temps is None:
        return False, want, "no ok" if ok_t is None else "no temperatures from M105"
    ok = temps[3] == float(target) and abs(temps[2] - target) <= win + 0.5
    return ok, want, f"B:{temps[2]:.2f} /{temps[3]:.2f}"


def bed_long_heat(s: Session) -> Outcome:
    """M190 S to a target the bed needs more than the cooling-slope period (60 s) to reach:
    the slope rule is for cooling only, so the wait runs its whole residency (W: down to 0)
    and the bed is in the window at the ok."""
    now, why = _hot(s, "M190")
    win = float(s.v.temp_window)
    want = "W: counting down to 0, then ok; B within the window of the target"
    if now is None:
        return False, want, why
    target = round(now) + 80
    try:
        reports, ok_t, _ = _wait(s, f"M190 S{target}", 900.0)
        temps = _temps(s)
    finally:
        s.talk(b"M140 S0\n")
    problems = _residency_problems(s, "M190", reports, ok_t)
    if temps is None or abs(temps[2] - target) > win + 0.5:
        problems.append(f"M105 {temps}")
    return not problems, want, "; ".join(problems) or "as expected"


def timer_running(seconds: int, want: str) -> Callable[[Session], Outcome]:
    """M77, M75 (the timer from 0), G4 S<seconds>, M31 while the timer runs: the time so far
    (libs/stopwatch.cpp Stopwatch::duration adds the running part; libs/duration_t.h
    toString: ``<m>m <s>s`` from a minute on)."""
    def run(s: Session) -> Outcome:
        try:
            s.talk(b"M77\n")
            s.talk(b"M75\n")
            s.talk(f"G4 S{seconds}\n".encode(), timeout=seconds + 5.0)
            got = s.talk(b"M31\n")
        finally:
            s.talk(b"M77\n")
        return got.lines[:1] == [want], f"{want} (the timer still running)", got.text()
    return run


_CRC = re.compile(r"crc (\d+)\)")


def crc_agrees(s: Session) -> Outcome:
    """M500 then M501, from two different settings: each time the crc M501 computes over
    what it reads is the one M500 printed for what it wrote (settings.cpp save / _load, both
    over the same bytes), a uint16_t; different settings give different crcs."""
    crcs = []
    for state in (base_state(), State(deepcopy(NEW), "FR:100%", "echo:E0 Flow: 100%")):
        put(s, state)
        saved = _CRC.findall(" ".join(s.talk(b"M500\n").lines))
        loaded = _CRC.findall(" ".join(s.talk(b"M501\n", timeout=4.0).lines))
        crcs.append((saved, loaded))
    ok = all(len(a) == 1 and b[:1] == a and 0 <= int(a[0]) <= 0xFFFF for a, b in crcs) and \
        crcs[0][0] != crcs[1][0]
    return ok, "M500's crc again in M501's line (0 .. 65535); another for other settings", \
        "; ".join(f"M500 crc {a}, M501 crc {b}" for a, b in crcs)


def timer_edges(s: Session) -> Outcome:
    """duration_t::toString on either side of a minute."""
    got = []
    for seconds, want in ((59, "59s"), (60, "1m 0s")):
        ok, _, text = timer_running(seconds, f"echo:Print time: {want}")(s)
        got.append((ok, text.split(" | ")[0]))
    return all(ok for ok, _ in got), "59s | 1m 0s", \
        " | ".join(text for _, text in got)


def r_below_reach(s: Session, code: str = "M109") -> Outcome:
    """M109 (M190) R 15 °C below the hotend's (bed's) temperature at rest (it cannot cool
    below the room): the wait gives up when the temperature fell less than
    MIN_COOLING_SLOPE_DEG(_BED) in MIN_COOLING_SLOPE_TIME(_BED) (60 s), so the ok comes ~60 s
    after."""
    now, why = _hot(s, code)
    want = f"ok 59 .. 62 s after {code} R<now - 15> (the cooling-slope cut-off)"
    if now is None:
        return False, want, why
    try:
        _, ok_t, t0 = _wait(s, f"{code} R{max(round(now) - 15, 0)}", 90.0)
    finally:
        s.talk(b"M104 S0\n" if code == "M109" else b"M140 S0\n")
    took = None if ok_t is None else ok_t - t0
    return took is not None and 59.0 <= took <= 62.0, want, \
        "no ok" if took is None else f"ok after {took:.2f} s"


def generate(spec: MarlinSpec, vid: str, profile: str = "quick") -> list[MarlinCheck]:
    cmd = {k: x.cite for k, x in spec.commands.items()}
    temp = spec.variant(vid).cite
    out = [
        MarlinCheck(f"{vid}/M200-M205.cpp/settings/m201-e-small", cmd["M201"] + "; "
                    "gcode/config/M92.cpp (the E max feedrate scaled for a small E steps value "
                    "is M92's alone)", "M201 E5: only M201's E changes, M203's E does not",
                    set_case("M201 E5", _assign("M201", 3, 5.0))),
        MarlinCheck(f"{vid}/M410.cpp/quickstop/m410-at-rest", cmd["M410"] + "; MarlinCore.cpp "
                    "quickstop_stepper (set_current_from_steppers_for_axis); recorded "
                    "blocking-reads.transcript (each quick stop takes ~1 s)",
                    "M410 at rest: ok after the quick stop(s), the position and counts unchanged",
                    quickstop_at_rest),
        MarlinCheck(f"{vid}/M410.cpp/motion/m410-in-move", cmd["M410"] + "; MarlinCore.cpp "
                    "quickstop_stepper; recorded blocking-reads.transcript (1.0 s into G1 X50 "
                    "F600: X:8.71 Count X:697)", "M410 1 s into a move from X5 Y3: X part way "
                    "on a whole step, Y Z kept", restoring(quickstop_in_move), motion=True),
        MarlinCheck(f"{vid}/G28.cpp/motion/g28-second", cmd["G28"] + "; motion.cpp homeaxis; "
                    "Configuration.h HOMING_FEEDRATE_MM_M; Configuration_adv.h HOMING_BUMP_MM, "
                    "HOMING_BUMP_DIVISOR", "a second G28 from X10 Y10 Z1 E7: the bump moves' "
                    "time, XYZ home, E kept", restoring(second_homing), motion=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m109-r-in-window", cmd["M109"] + "; " +
                    temp["temp_residency"], "M109 R at the hotend's temperature: ok 4/3 of the "
                    "residency later (first_loop)", in_window("M109"), heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m190-r-in-window", cmd["M190"] + "; " +
                    temp["temp_bed_residency"], "M190 R at the bed's temperature: ok 4/3 of the "
                    "residency later (first_loop)", in_window("M190"), heat=True),
        MarlinCheck(f"{vid}/M104_M109.cpp/heat/m109-s-no-cooling-wait", cmd["M109"],
                    "M109 S below the temperature: ok at once, the target set",
                    s_no_cooling_wait, heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m190-r-cools", cmd["M190"] + "; " +
                    temp["temp_bed_residency"], "M190 R below the bed's temperature: the ok "
                    "once the bed is in the window", bed_cools, heat=True),
        MarlinCheck(f"{vid}/M75-M78.cpp/timer/m31-running", cmd["M31"] + "; " + cmd["M75"],
                    "M31 while the print timer runs: the time so far",
                    timer_running(2, "echo:Print time: 2s")),
        MarlinCheck(f"{vid}/M500-M504.cpp/eeprom/crc-agrees", cmd["M500"] + "; " +
                    cmd["M501"], "M500 then M501 from two states: one crc each, 16 bits, "
                    "not the same",
                    restoring(crc_agrees, store=True), eeprom=True),
    ]
    if profile == "full":
        out.append(MarlinCheck(f"{vid}/M75-M78.cpp/timer/m31-minutes", cmd["M31"] + "; "
                               "libs/duration_t.h toString", "M31 after 61 s: 1m 1s",
                               timer_running(61, "echo:Print time: 1m 1s")))
        out.append(MarlinCheck(f"{vid}/temperature.cpp/heat/m109-r-slope", cmd["M109"] + "; "
                               "temperature.cpp wait_for_hotend (wants_to_cool: break when "
                               "old_temp - temp < MIN_COOLING_SLOPE_DEG 1.5 after "
                               "MIN_COOLING_SLOPE_TIME 60 s)", "M109 R below what the hotend "
                               "can reach: ok after the 60 s slope period", r_below_reach,
                               heat=True))
        out.append(MarlinCheck(f"{vid}/M75-M78.cpp/timer/m31-edges", cmd["M31"] + "; "
                               "libs/duration_t.h toString (%is, %im %is)",
                               "M31 at 59 s and at 60 s", timer_edges))
        out.append(MarlinCheck(f"{vid}/temperature.cpp/heat/m190-s-long", cmd["M190"] + "; " +
                               temp["temp_bed_residency"] + "; MIN_COOLING_SLOPE_TIME_BED 60 "
                               "(wants_to_cool only)", "M190 S 80 °C up: no slope cut-off while "
                               "heating, the whole residency", bed_long_heat, heat=True))
    return out
