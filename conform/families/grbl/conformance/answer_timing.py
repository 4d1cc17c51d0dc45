"""Checks of when a grbl answers, not only what: the time each line comes back.

A line's ``ok`` is due when grbl has read the line's end from its receive ring and executed
it: the line end arrives 10 bits a byte after the bytes before it (serial.c, 8N1 at the
baud), protocol.c protocol_main_loop reads one line and runs it before it reads the next, a
dwell holds its ``ok`` for P seconds (mc_dwell) and M0 until ``~`` (protocol_exec_rt_suspend),
a line with no motion is not held by a full planner (only mc_line waits for a free block),
and ``$H`` answers when the homing cycle ends (limits.c limits_go_home).

A case is steps sent to the unit as they are (bytes, without waiting for an answer) and pauses
(seconds); everything the unit says is kept with the time it arrived. The expected answers
are the reference unit's (:mod:`conform.families.grbl.unit`) sent the same steps, as in
:mod:`.from_state`. In-process both run on one virtual clock at the target's baud, and every
line is compared with its arrival time, exactly. Behind a link the times follow the wall
clock and the link's buffering: there the case runs as :mod:`.in_motion` runs a course (each
line's answers awaited, reports while the machine moves compared by state) and the lines are
compared, not their times.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.in_motion import Step, emulated_only
from conform.families.grbl.conformance.session import GrblCheck, Outcome, Session
from conform.families.grbl.protocol.codec import split_unit
from conform.families.grbl.spec.load import GrblSpec


@dataclass(frozen=True)
class Case:
    name: str
    cite: str
    title: str
    steps: tuple[Step, ...]


_MAIN = "src:protocol.c protocol_main_loop"
# one write of lines of odd and even lengths, a comment line among them: each line end is
# read when it arrives, or when the line before has been run, whichever is later
ONE_WRITE = b"G90G21\n(a comment line for the byte clock)\nG90\nM5\nG91\n;x\nG17\nG90\n"
# slow short moves, as many as the planner holds, then a line without motion
FILL = (b"G91\n", *(b"G1X-0.1F120\n" for _ in range(15)), b"G21\n")

CASES: tuple[Case, ...] = (
    Case("one-write", f"src:serial.c serial_rx ISR (one byte per 10 bit times, 8N1); {_MAIN} "
         "(one line read and run before the next is read)",
         "eight lines in one write: each ok comes when its line end has arrived and the line "
         "before has been run, in order", (ONE_WRITE, 0.2)),
    Case("dwell", "src:gcode.c gc_execute_line (NON_MODAL_DWELL); motion_control.c mc_dwell "
         "(delay_sec: protocol_execute_realtime serves ? meanwhile)",
         "G4 P0.4: its ok 0.4 s later; a ? during the dwell is answered at once and does not "
         "end it", (b"G4P0.4\n", 0.1, b"?", 0.5, b"?", 0.1)),
    Case("program-pause", "src:gcode.c gc_execute_line (PROGRAM_FLOW_PAUSED: a feed hold); "
         "protocol.c protocol_exec_rt_suspend (the line returns after cycle start)",
         "M0: Hold:0 and no ok until ~; then the ok at once and Idle",
         (b"M0\n", 0.3, b"?", 0.2, b"~", 0.2, b"?", 0.1)),
    Case("full-planner", "src:motion_control.c mc_line (plan_check_full_buffer: only a motion "
         "waits for a free block); gcode.c gc_execute_line; planner.h BLOCK_BUFFER_SIZE",
         "G21 sent while 15 queued moves fill the planner is answered at once; every move's "
         "ok when its block is taken", (*FILL, 0.5, b"?", 2.5, b"?", b"G90\n", 0.1)),
    Case("homing", "src:limits.c limits_go_home (seek $25, locate $24, pull-off $27, debounce "
         "$26); system.c system_execute_line case 'H'; motion_control.c mc_homing_cycle",
         "$H with $22=1 from off the origin: its ok when the cycle ends, then Idle at the "
         "pull-off", (b"$22=1\n", b"G91G0X-2Y-1\n", 1.0, b"?", 0.1, b"$H\n", 6.5, b"?",
                      b"$22=0\n", 0.1)),
)


def _timed(s: Session, steps: tuple[Step, ...]) -> list[tuple[float, str]]:
    """Send the steps as they are to an in-process target; every line the unit says with the
    time it is due on the unit's virtual clock (s from the first step)."""
    target = s.target
    unit = target.unit
    said: list[tuple[float, bytes]] = []
    poll = unit.poll

    def kept(t: float) -> list[tuple[float, bytes]]:
        due = poll(t)
        said.extend(due)
        return due

    unit.poll = kept
    t0 = target.now()
    try:
        for step in steps:
            if isinstance(step, float):
                target.wait(step)
            else:
                target.send(step)
        target.wait(0.0)
    finally:
        del unit.poll
    out: list[tuple[float, str]] = []
    buf = b""
    for at, data in said:
        buf += data
        got, buf = split_unit(buf, s.spec)
        out += [(round(at - t0, 9), g.text) for g in got]
    return out


def _shown(pair: tuple[float, str]) -> str:
    return f"{pair[1] or '(blank)'} at {pair[0] * 1000:.3f} ms"


def _compare_timed(s: Session, r: Session, steps: tuple[Step, ...]) -> Outcome:
    got, want = _timed(s, steps), _timed(r, steps)
    for i, w in enumerate(want):
        g = got[i] if i < len(got) else None
        if g != w:
            return (False, f"line {i + 1}: {_shown(w)}",
                    _shown(g) if g is not None else "(nothing more)")
    if len(got) > len(want):
        return False, f"{len(want)} lines", f"more: {_shown(got[len(want)])}"
    return True, "every line as the reference unit's, at its time", "; ".join(
        _shown(x) for x in got)


EMULATED_ONLY = {"homing": "the homing cycle's course follows the machine's switches"}
"""As system_effects' homing course: the reference's cycle stands for switches at the end of
the travel, a real cycle's length and path follow the machine's own."""


def _run(case: Case) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        from conform.families.grbl.conformance.from_state import _put_back, needs
        from conform.families.grbl.conformance.in_motion import _follow, _normalize
        from conform.families.grbl.conformance.machine import Pair
        from conform.families.grbl.unit.model import GrblUnit

        ref = EmuTarget(lambda: GrblUnit(s.v, s.spec), f"emu:{s.v.id}", baud=s.target.baud)
        try:
            r = Session(ref, s.spec, s.v)
            if s.target.emulated:
                r.fresh()              # both at power-up, on one virtual clock
                return _compare_timed(s, r, case.steps)
            pair = Pair(s, r, _normalize(True))
            pair.start()               # the reference where the target stands
            try:
                passed, expected, actual = _follow(pair, case.steps)
            finally:
                left = _put_back(pair) if needs(_sent(case))[1] else ""
            return passed, expected, actual + left
        finally:
            ref.close()
    return run


def _sent(case: Case) -> tuple[bytes, ...]:
    return tuple(x for x in case.steps if isinstance(x, bytes))


def generate(spec: GrblSpec, vid: str) -> list[GrblCheck]:
    """One check per case, flagged by what its lines do on a real unit
    (:func:`.from_state.needs`): the first three run in a default run."""
    from conform.families.grbl.conformance.from_state import needs

    out = []
    for case in CASES:
        motion, eeprom = needs(_sent(case))
        out.append(GrblCheck(f"{vid}/answer_timing/{case.name}", case.cite, case.title,
                             emulated_only(EMULATED_ONLY.get(case.name), _run(case)),
                             motion=motion, eeprom=eeprom))
    return out
