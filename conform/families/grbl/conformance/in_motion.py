"""Checks of what a grbl does while it moves: a move's course read back as it runs.

The other checks read the machine at rest, where every move has ended at its target whatever
way it got there. Here each row starts a move (a line, lines in a chain, an arc, a jog, a
probe) and asks ``?`` at fixed times along it, so the position and feed of every report show
the planner's acceleration, cruise and deceleration (planner.c planner_recalculate, the
junction speed of ``$11``; stepper.c st_prep_buffer), an arc's length (motion_control.c
mc_arc), the overrides, and a feed hold's and a jog cancel's stop (protocol.c
protocol_exec_rt_system, EXEC_FEED_HOLD and EXEC_MOTION_CANCEL) with what is said on resume
(protocol_exec_rt_suspend: ``[MSG:Restoring spindle]`` only after a spindle stop).

A step is bytes sent to both units (their answers compared) or a number of seconds both wait
(what each says meanwhile compared). The expected answers are the reference unit's
(:mod:`conform.families.grbl.unit`), sent the same steps from the same state, as in
:mod:`.from_state`. In-process both run on one virtual clock and every report is compared
exactly. Behind a link a report taken while the machine moves (Run, Jog, Home, Hold:1)
follows the wall clock, so only its state is compared there; a report at rest (Idle,
Hold:0, Alarm) is compared exactly, position and all, except in a course that stops a move
with a realtime byte (``INTERRUPTED``): where it comes to rest follows when the byte arrived,
so behind a link its reports are compared by state. Every row moves the machine and needs
``--allow-motion``; a row that writes a setting or a startup line needs ``--allow-eeprom``
too, and on a unit behind a link what it wrote is put back after it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.session import GrblCheck, Outcome, Session
from conform.families.grbl.spec.load import GrblSpec

if TYPE_CHECKING:
    from conform.families.grbl.conformance.machine import Pair

Step = bytes | float

MOVING = ("<Run", "<Jog", "<Home", "<Hold:1")


def _poll(seconds: float, every: float) -> tuple[Step, ...]:
    """``?`` every ``every`` seconds for ``seconds``."""
    return tuple(x for _ in range(round(seconds / every)) for x in (every, b"?"))


@dataclass(frozen=True)
class Course:
    name: str
    cite: str
    title: str
    steps: tuple[Step, ...]


# a slow first block: the blocks sent after it are queued when it ends, so the planner sees
# them all from the next block on (a corner's speed, a block's exit speed)
LEAD = b"G1Y0.2F60\n"

_PL = "src:planner.c plan_buffer_line, planner_recalculate; stepper.c st_prep_buffer"
_RT = "src:protocol.c protocol_exec_rt_system"

COURSES: tuple[Course, ...] = (
    Course("line", f"{_PL}; report.c report_realtime_status (MPos:, FS:)",
           "G1 X10 F400: accelerates at $120, cruises at F, decelerates to the target",
           (b"G1X10F400\n", *_poll(2.6, 0.1))),
    Course("line-axis-limits", f"{_PL} (limit_value_by_axis_maximum: $110-$112, $120-$122)",
           "G1 on three axes above the axes' rates: the rate and acceleration are cut to the "
           "axis that limits them", (b"G1X-6Y4Z9F900\n", *_poll(2.8, 0.1))),
    Course("short-line", f"{_PL} (a block too short to reach its feed: a triangle)",
           "G1 X0.5 F400: never reaches the feed, decelerates from the peak",
           (b"G1X0.5F400\n", *_poll(0.5, 0.04))),
    Course("chain", f"{_PL} (junction speed from $11, the exit speed carried into the next "
           "block)", "three G1 blocks queued: no stop at the corners, the speed through each",
           (LEAD, b"G1X3F400\n", b"G1X6Y2\n", b"G1X6Y5\n", b"G1X9Y5F200\n",
            *_poll(4.2, 0.1))),
    Course("reversal", f"{_PL} (a junction turning back: speed 0 at the corner)",
           "G1 out and straight back, queued behind a slow first block: the machine stops "
           "at the corner, then returns", (LEAD, b"G1X4F400\n", b"G1X1\n", b"G1X1Y3\n",
                                           *_poll(3.8, 0.1))),
    Course("hold-at-corner", f"{_RT} (EXEC_FEED_HOLD); planner.c plan_cycle_reinitialize "
           "(a hold too close to a block's end decelerates on into the next block)",
           "! 0.5 mm before the end of a block entered at speed: the stop runs into the next "
           "block", (LEAD, b"G1X3F400\n", b"G1X9\n", 0.85, b"!", *_poll(1.0, 0.1), b"~",
                     *_poll(1.6, 0.1))),
    Course("planner-full", "src:planner.c plan_check_full_buffer (BLOCK_BUFFER_SIZE 16, one "
           "slot empty); motion_control.c mc_line (waits for a free block); gcode.c "
           "gc_execute_line (G28: a move to the via point, then one to the stored position)",
           "a G28 with a via point sent while the planner is full: its ok comes when two "
           "blocks are free", (*(f"G1X{i / 2:g}F120\n".encode() for i in range(1, 19)),
                               b"G28X12\n", *_poll(1.0, 0.1))),
    Course("arc", "src:motion_control.c mc_arc; " + _PL,
           "G2 half circle: the move takes the arc's length, not the chord's",
           (b"G2X6Y0I3J0F300\n", *_poll(2.4, 0.1))),
    Course("rapid-override", f"{_RT} (EXEC_RAPID_OVR_*); {_PL}",
           "G0 at the 50 % rapid override: half the axes' rate", (b"\x96", b"G0X8Y3\n",
                                                                   *_poll(2.2, 0.1))),
    Course("inverse-time", "src:gcode.c gc_execute_line (G93: the block takes 1/F minutes); "
           + _PL, "G93 G1 F30: a 4 mm line takes two seconds",
           (b"G93G1X4F30\n", *_poll(2.4, 0.2))),
    Course("feed-hold", f"{_RT} (EXEC_FEED_HOLD, EXEC_CYCLE_START); planner.c "
           "plan_cycle_reinitialize", "! in the cruise: decelerates to Hold:0 short of the "
           "target, ~ resumes the rest", (b"G1X10F400\n", 0.9, b"?", b"!", *_poll(1.0, 0.1),
                                         b"~", *_poll(2.0, 0.1))),
    Course("hold-spindle", f"{_RT}; protocol_exec_rt_suspend (spindle stop override, "
           "MESSAGE_SPINDLE_RESTORE)", "a hold and resume with the spindle on says nothing; "
           "after 0x9E in the hold the resume says [MSG:Restoring spindle]",
           (b"M3S800\n", b"G1X10F400\n", 0.5, b"!", *_poll(1.0, 0.2), b"~", 0.3, b"?", b"!",
            *_poll(1.0, 0.2), b"\x9e", b"?", b"~", *_poll(2.0, 0.2))),
    Course("jog-cancel", f"{_RT} (EXEC_MOTION_CANCEL); system.c jog_execute; "
           "planner.c plan_reset", "0x85 in a jog: it decelerates and stops short, Idle, the "
           "stop kept as the position; a second jog runs from there",
           (b"$J=G91X10F400\n", 0.8, b"?", b"\x85", *_poll(1.0, 0.1),
            b"$J=G91Y-2F300\n", *_poll(1.2, 0.1))),
    Course("reset-in-motion", "src:protocol.c protocol_exec_rt_system (EXEC_RESET in a "
           "cycle: ALARM:3, mc_reset); report.c report_realtime_status (MPos: from "
           "sys_position, kept through the reset)",
           "a soft reset in the cruise: ALARM:3, and Alarm reports where the machine stopped",
           (b"G1X10F400\n", 0.9, b"\x18", 0.5, b"?", b"$X\n", b"?")),
    Course("soft-limits-inside", "src:limits.c limits_soft_check; system.c "
           "system_check_travel_limits (machine space -$130..0 with homing toward +)",
           "$20=1: moves inside the travel (-$130..0 from the power-up origin) run as "
           "usual, no ALARM:2; $22=0 turns $20 off too (settings.c case 22), and a setting "
           "other than $13 forces no WCO: (system_flag_wco_change)",
           (b"$22=1\n", b"$20=1\n", b"G0X-0.5Y-0.5Z-0.5\n", *_poll(0.6, 0.1), b"G0X-2Z-0.2\n",
            *_poll(0.8, 0.1), b"$22=0\n", b"$$\n", b"?", b"$12=0.004\n", b"?", b"$JX\n")),
    Course("outputs-reports", f"{_RT} (EXEC_SPINDLE_OVR_STOP only in a hold, "
           "EXEC_COOLANT_FLOOD_OVR_TOGGLE, EXEC_COOLANT_MIST_OVR_TOGGLE without ENABLE_M7); "
           "spindle_control.c spindle_set_state and coolant_control.c coolant_set_state "
           "force Ov: (report_ovr_counter = 0) only when they change",
           "M3, S, M8, M9 force Ov: into the next report, a line that changes neither does "
           "not; 0x9E while idle and 0xA1 change nothing; 0xA0 toggles flood",
           (b"?", b"?", b"M3S500\n", b"?", b"G21\n", b"?", b"?", b"S600\n", b"?",
            b"M8\n", b"?", b"G21\n", b"?", b"M9\n", b"?", b"\x9e", b"?", b"\xa1", b"?",
            b"\xa0", b"?", b"\xa0", b"?", b"M5\n", b"?")),
    Course("spindle-minimum", "src:spindle_control.c spindle_compute_pwm_value ($31: a "
           "speed at or below it runs at $31, S0 is off)",
           "$31=100: S50 runs at 100, S0 at 0, S150 at 150 (FS:)",
           (b"$31=100\n", b"M3S50\n", b"?", b"S0\n", b"?", b"S150\n", b"?", b"M5\n")),
    Course("startup-line-error", "src:system.c system_execute_startup (a line that fails "
           "prints >line:error:N and the next one still runs)",
           "$N0=G1X0 stored with a feed set fails after a reset (no feed: error:22); $N1=G20 "
           "runs after it", (b"F100\n", b"$N0=G1X0\n", b"$N1=G20\n", b"\x18", 0.3, b"$G\n")),
    Course("jog-cancel-at-corner", f"{_RT} (EXEC_MOTION_CANCEL); planner.c plan_reset",
           "0x85 too close to the end of a jog block entered at speed, a new jog at once: "
           "the new jog starts from where and how fast the cancelled one ended",
           (b"$J=G91Y0.2F60\n", b"$J=G91X3F400\n", b"$J=G91X3F400\n", 0.9, b"\x85",
            b"$J=G91Y-1F300\n", *_poll(1.2, 0.05))),
    Course("inverse-time-fraction", "src:gcode.c gc_execute_line (G93: F is 1/minutes of the "
           "block); planner.c plan_buffer_line (PL_COND_FLAG_INVERSE_TIME: rate = length x F)",
           "G93 G1 F40 over 1.8 mm: a rate that is not a whole number of mm/s, 1.5 s",
           (b"G93G1X-1.5Y1F40\n", *_poll(1.8, 0.15))),
    Course("arc-with-spindle", "src:gcode.c gc_execute_line (a spindle change syncs the "
           "planner, then the arc runs: mc_arc); spindle_control.c spindle_sync",
           "G2 with M3 S in the same block: the spindle turns on, then the arc runs",
           (b"G2X-2Y0I-1J0F300M3S1000\n", *_poll(1.0, 0.1), b"M5\n")),
    Course("probe-no-contact", "src:motion_control.c mc_probe_cycle (G38.3: no contact is no "
           "error; the position reached is kept, [PRB:...:0])",
           "G38.3 that touches nothing: no alarm, the move ends at its target, [PRB:…:0], ok",
           (b"G38.3Z-0.5F100\n", *_poll(0.6, 0.1), b"$#\n")),
    Course("step-rounding", "src:planner.c plan_buffer_line (target_steps = lround(mm x "
           "$100)); system.c system_convert_axis_steps_to_mpos (steps / $100)",
           "$100=0.8: G0 X-2 moves 2 whole steps, MPos -2.500 (not -2.000)",
           (b"$100=0.8\n", b"G53G0X-2\n", *_poll(0.6, 0.2), b"$100=250\n")),
    Course("startup-after-alarm", "src:system.c system_execute_startup (every stored line "
           "runs, whatever the state); motion_control.c mc_probe_cycle (no contact: ALARM:5); "
           "coolant_control.c coolant_set_state (report_ovr_counter = 0)",
           "startup line 0 probes and touches nothing (ALARM:5), line 1 (M8) still runs in "
           "Alarm and forces Ov: with A:F into the next report",
           (b"$N0=G38.2Z-2F100\n", b"$N1=M8\n", b"\x18", 0.2, b"?", 0.1, b"?", 0.1, b"?", 1.8,
            b"?", b"$X\n", b"$N0=\n", b"$N1=\n", b"M9\n")),
)


INTERRUPTED = frozenset({"hold-at-corner", "feed-hold", "hold-spindle", "jog-cancel",
                         "reset-in-motion", "jog-cancel-at-corner"})
"""Courses that stop a move with a realtime byte (!, 0x85, 0x18) sent at a moment of the run:
behind a link the byte reaches the unit when the wall clock and the link deliver it, so where
the machine comes to rest follows that moment, not the unit's logic. There every report of
these courses is compared by its state (Hold:0, Idle, Alarm, in their order); in-process,
on one clock, exactly."""


def _normalize(linked: bool, interrupted: bool = False) -> Callable[[list[str]], list[str]]:
    def normalize(lines: list[str]) -> list[str]:
        if not linked:
            return lines
        return [x.split("|", 1)[0] + ">" if x.startswith(MOVING) or (interrupted and x.startswith("<"))
                else x for x in lines]
    return normalize


EMULATED_ONLY = {
    "probe-no-contact": "whether the probe touches follows the machine's probe input",
}
"""Courses run only on an emulated unit (the reference's input stands for the machine's), and
why not on a real one; in-process their answers are compared exactly."""


def emulated_only(why: str | None, check: Callable[[Session], Outcome]
                  ) -> Callable[[Session], Outcome]:
    """``check`` behind a link only where ``why`` is None; else not applicable there, saying why."""
    if why is None:
        return check

    def run(s: Session) -> Outcome:
        if not s.target.emulated:
            return None, "an emulated unit", f"not applicable: {why}"
        return check(s)
    return run


def _run(course: Course, interrupted: frozenset[str] = INTERRUPTED
         ) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        from conform.families.grbl.conformance.from_state import _put_back, needs
        from conform.families.grbl.conformance.machine import Pair
        from conform.families.grbl.unit.model import GrblUnit

        ref = EmuTarget(lambda: GrblUnit(s.v, s.spec), f"emu:{s.v.id}", baud=s.target.baud)
        try:
            r = Session(ref, s.spec, s.v)
            pair = Pair(s, r, _normalize(not s.target.emulated, course.name in interrupted))
            if not pair.linked:
                r.fresh()              # both at power-up
                return _follow(pair, course.steps)
            pair.start()               # the reference where the target stands
            try:
                passed, expected, actual = _follow(pair, course.steps)
            finally:   # a unit behind a link keeps the startup lines a course wrote
                left = _put_back(pair) if needs(_sent(course))[1] else ""
            return passed, expected, actual + left
        finally:
            ref.close()
    return run


def _follow(pair: Pair, steps: Sequence[Step]) -> Outcome:
    """Each step to both; the first whose answers differ fails the course."""
    from conform.families.grbl.conformance.machine import compare_step

    shown: list[str] = []
    for data in steps:
        if isinstance(data, float):
            got, want = (pair.normalize(x.wait(data)) for x in (pair.t, pair.r))
            if pair.linked:
                pair._catch_up()
            what = f"{data:g} s later"
            if got != want:
                return (False, f"{what}: {' | '.join(want) or '-'}", " | ".join(got) or "-")
            if got:
                shown.append(f"{what}: {' | '.join(got)}")
            continue
        if pair.linked:
            pair._settle()
        why = compare_step(pair.t, pair.r, data, pair.normalize)
        if why:
            return False, "every answer as the reference unit's", why
        shown.append(repr(data))
    return True, "every answer as the reference unit's", f"{len(shown)} steps agreed"


def _sent(course: Course) -> tuple[bytes, ...]:
    return tuple(x for x in course.steps if isinstance(x, bytes))


def generate(spec: GrblSpec, vid: str) -> list[GrblCheck]:
    """One check per course; each moves the machine or turns an output on, some write the
    EEPROM (a setting, a startup line: :func:`.from_state.needs`)."""
    from conform.families.grbl.conformance.from_state import needs

    return [GrblCheck(f"{vid}/in_motion/course/{c.name}", c.cite, c.title,
                      emulated_only(EMULATED_ONLY.get(c.name), _run(c)), motion=True,
                      eeprom=needs(_sent(c))[1]) for c in COURSES]
