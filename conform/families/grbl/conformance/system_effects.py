"""Checks of grbl's '$' system commands, its homing cycle, and the settings and planner rules
that shape a move, each from a state where a wrong effect shows.

Two kinds, both compared with the reference unit (:mod:`conform.families.grbl.unit`) sent the
same steps from the same state:

* rows at rest (:class:`.from_state.Row`): malformed ``$I``, ``$N`` and ``$x=`` lines whose
  error code tells which test of system.c ``system_execute_line`` refused them, read back with
  ``$$``, ``$N``, ``$I`` and the modal state so that nothing else changed;
* courses in motion (:class:`.in_motion.Course`): the homing cycle's length and where it
  leaves the machine, a rapid after its axis rate was changed, a chain of short collinear
  blocks (the exit speed of planner.c ``planner_recalculate``), and feed holds where the stop
  distance, not the block's end, decides where the machine rests.

Every row and course cites the firmware function whose effect it reads. A line that stores
nothing on a right unit may store something on a wrong one, so the malformed ``$`` lines run
with the EEPROM opt-in; the courses move the machine and need ``--allow-motion``.

Two run only on an emulated unit (:data:`EMULATED_ONLY`): the homing course (the reference's
cycle stands for switches at the end of the travel; a real cycle's length and path follow the
machine's own switches), and startup lines beyond the table (grbl writes them past the table
in its EEPROM, over what is stored there).
"""

from __future__ import annotations

from conform.families.grbl.conformance.from_state import READ_ALL, READ_EEPROM, Row, needs
from conform.families.grbl.conformance.from_state import _run as _run_row
from conform.families.grbl.conformance.in_motion import LEAD, Course, _poll, emulated_only
from conform.families.grbl.conformance.in_motion import _run as _run_followed
from conform.families.grbl.conformance.session import GrblCheck
from conform.families.grbl.spec.load import GrblSpec

_SYS = "src:system.c system_execute_line"
_SET = "settings.c settings_store_global_setting"

ROWS: tuple[Row, ...] = (
    Row("malformed-system-lines",
        f"{_SYS} (case 'I': a character after $I other than '=' is STATUS_INVALID_STATEMENT; "
        "case 'N' into default: read_float, then '=' else STATUS_INVALID_STATEMENT); "
        f"{_SET} (default: an unknown number is STATUS_INVALID_STATEMENT)",
        "$IA, $N0X, $N1A are error:3, $NX error:2, $50=1 and $255=1 error:3: nothing is "
        "stored (build info, startup lines, settings and modes read back as before)",
        (b"$IA\n", b"$I\n", b"$N0X\n", b"$N1A\n", b"$NX\n", b"$50=1\n", b"$255=1\n"),
        reads=(*READ_EEPROM, b"$I\n", *READ_ALL)),
    Row("startup-line-beyond-table",
        f"{_SYS} case 'N' (gc_execute_line runs the block; settings.c "
        "settings_store_startup_line has no bound on the number); shared recording "
        "grbl-1.1f/system.transcript ($N2=G20: ok, $N0/$N1 unchanged)",
        "$N2=G20 and $N3=G21 are ok: their blocks run (G20, then G21 in $G) and $N0/$N1 "
        "stay as they were",
        (b"$N2=G20\n", b"$G\n", b"$N3=G21\n"), setup=(b"$N0=G55\n", b"$N1=G91\n"),
        reads=(b"$N\n", b"$G\n")),
)

_PL = "src:planner.c plan_buffer_line, planner_recalculate; stepper.c st_prep_buffer"
_RT = "src:protocol.c protocol_exec_rt_system (EXEC_FEED_HOLD); planner.c plan_cycle_reinitialize"
_HOME = ("src:system.c system_execute_line case 'H'; motion_control.c mc_homing_cycle; limits.c "
         "limits_go_home (seek at $25, locate at $24, pull-off $27, debounce $26; the machine "
         "position set to -$27 toward a positive homing direction); shared recording "
         "grbl-1.1f/system.transcript: '?' during $H is not answered")

COURSES: tuple[Course, ...] = (
    Course("homing-cycle", _HOME,
           "$H from off the origin with $24 and $25 off their defaults: ok after as long as the "
           "seek, locate and pull-off take, then Idle at -$27 on every axis; $H with a letter "
           "after it is error:3 ($H ends with CR, which ends a line as LF does (protocol.c): the "
           "ok is then waited for in steps of 0.1 s, and the moment it comes is compared; "
           "limits.c limits_go_home answers no status report meanwhile)",
           (b"$22=1\n", b"$24=200\n", b"$25=90\n", b"G0X-4Y-3Z-2\n", *_poll(1.2, 0.2),
            b"$HA\n", b"$H\r", *(0.1,) * 50, b"?", b"$22=0\n")),
    Course("rapid-after-rate-change",
           f"{_SET} (settings.max_rate, read by planner.c for blocks planned after it); {_PL}",
           "$110 and $112 lowered: a G0 after them runs at the new rates (mm/min), the axis "
           "with the lowest rate for its share of the move limiting it; the same G0 again "
           "goes nowhere (planner.c plan_buffer_line: an empty block is not planned)",
           (b"$110=240\n", b"$112=120\n", b"G0X-3Z-2\n", *_poll(2.4, 0.1), b"G0X-3Z-2\n",
            b"?")),
    Course("collinear-short-blocks",
           f"{_PL} (the reverse pass: a block's entry speed at most sqrt(exit^2 + "
           "2 * acceleration * length))",
           "four short blocks in one line queued behind a slow first block: the speed through "
           "each junction is what the blocks after it can still stop from",
           (LEAD, b"G1X0.5F400\n", b"G1X1\n", b"G1X1.5\n", b"G1X2\n", *_poll(1.6, 0.04))),
    Course("hold-slow-feed", _RT,
           "! while cruising at 1.5 mm/s: the machine stops v^2 / (2 a) further on (0.11 mm), "
           "~ runs the rest",
           (b"G1X3F90\n", 0.6, b"!", *_poll(0.4, 0.05), b"~", *_poll(2.2, 0.1))),
    Course("hold-near-block-end", _RT,
           "! 1.2 mm before the end of a block whose next block goes on in the same line: the "
           "stop distance (v^2 / (2 a)) runs past the block's end into the next one",
           (LEAD, b"G1X3F400\n", b"G1X9\n", 0.75, b"!", *_poll(1.0, 0.1), b"~",
            *_poll(1.6, 0.1))),
    Course("jog-cancel-then-jog", "src:protocol.c protocol_exec_rt_system (EXEC_MOTION_CANCEL); "
           "system.c jog_execute; planner.c plan_reset",
           "0x85 in a jog's cruise and a new jog at once: the cancelled jog decelerates to a "
           "stop, and the new one starts from rest there",
           (b"$J=G91X10F400\n", 0.8, b"\x85", b"$J=G91Y-1F300\n", *_poll(1.6, 0.05))),
)

EMULATED_ONLY = {
    "homing-cycle": "the homing cycle's course follows the machine's switches",
    "startup-line-beyond-table": "a startup line beyond the table is written past it in the "
                                 "EEPROM, over what is stored there",
}
"""Checks run only on an emulated unit, and why not on a real one."""
INTERRUPTED = frozenset({"hold-slow-feed", "hold-near-block-end", "jog-cancel-then-jog"})
"""As :data:`.in_motion.INTERRUPTED`: behind a link the hold's byte arrives when the wall clock
delivers it, so these courses' reports are compared by state there; in-process exactly."""


def _sent(course: Course) -> tuple[bytes, ...]:
    return tuple(x for x in course.steps if isinstance(x, bytes))



def generate(spec: GrblSpec, vid: str) -> list[GrblCheck]:
    """The rows (with the EEPROM opt-in: a wrong unit might store what a right one refuses)
    and the courses (motion; EEPROM where they write a setting)."""
    out = [GrblCheck(f"{vid}/system_effects/effect/{row.name}", row.cite, row.title,
                     emulated_only(EMULATED_ONLY.get(row.name), _run_row(row)), motion=needs(row.steps)[0],
                     eeprom=True)
           for row in ROWS]
    out += [GrblCheck(f"{vid}/system_effects/course/{c.name}", c.cite, c.title,
                      emulated_only(EMULATED_ONLY.get(c.name), _run_followed(c, INTERRUPTED)), motion=True,
                      eeprom=needs(_sent(c))[1]) for c in COURSES]
    return out

