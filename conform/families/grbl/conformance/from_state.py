"""Checks from a non-default state: each command run where doing the wrong thing would show,
then everything it may change and everything it must not read back.

A row is a setup (a state far from the reset one: G20 G91 G55 G93 G18, a tool, a feed and a
speed, a G92 offset, a tool length offset, the overrides moved; with the EEPROM opt-in also
six distinct G54-G59 offsets and a setting off its default), the command under test, and the
reads: ``$G`` (every modal group, T, F, S), ``$#`` (G54-G59, G28, G30, G92, TLO, PRB), ``?``
(position, WCO:, Ov:, FS:, A:) and ``$$``/``$N`` where the command touches them.

The expected answers are the reference unit's (:mod:`conform.families.grbl.unit`, which
matches every recording of the real firmware), sent the same steps from the same state: an
emulated target and the reference both start at power-up; a unit behind a link is read back
first and the reference started where it stands (:class:`.machine.Pair`). Every answer of
every step is compared exactly: nothing here moves while it is read, so no tolerance applies.

Each row cites the firmware function whose effect it reads, and what the command must leave
alone. A row is flagged by what its lines do on a real unit (:func:`needs`): a move or a
spindle/coolant output needs ``--allow-motion``; G10, G28.1/G30.1, ``$x=``, ``$N``, ``$RST``
and ``$I=`` write the EEPROM and need ``--allow-eeprom``. G92, G43.1/G49, modal words,
overrides and the reads write nothing, so those rows run in a default run.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.session import GrblCheck, Outcome, Session
from conform.families.grbl.spec.load import GrblSpec

if TYPE_CHECKING:
    from conform.families.grbl.conformance.machine import Pair

READ_ALL = (b"$G\n", b"$#\n", b"?", b"?")   # Ov: comes the report after WCO:
READ_EEPROM = (b"$$\n", b"$N\n")

# a state far from the reset one, written nowhere (no EEPROM, nothing moves or turns on)
MODES = (b"G43.1Z0.5\n", b"G92X0.5Y-0.25Z1\n", b"G20G91G55G18T3F40S500\n",
         b"\x91", b"\x9a", b"\x96", b"?")   # the report takes the WCO: and Ov: owed
# six distinct work offsets and a setting off its default (EEPROM)
OFFSETS = tuple(f"G10L2P{p}X{p}Y{-p}Z{p / 2:g}\n".encode() for p in range(1, 7))
STORED = (*OFFSETS, b"$11=0.02\n", b"$N0=G18\n")
MOVED = (b"G53G0X-3Y-2Z-1\n",)         # a machine position that is not the origin
OUTPUTS = (b"M3M8\n",)                  # spindle and flood on (A:SF)

_MOTION = re.compile(rb"^(\$J=|\$H|.*G0*[0-3](?![\d.])|.*G28(?![\d.])|.*G30(?![\d.])|.*G38)"
                     rb"|M0*[3478](?!\d)", re.M)
_EEPROM = re.compile(rb"^\$(\d+|N\d+|RST|I)=|G10|G28\.1|G30\.1", re.M)


def needs(lines: Sequence[bytes]) -> tuple[bool, bool]:
    """(moves or turns an output on, writes the EEPROM) for lines sent to a real grbl."""
    gcode = [x for x in lines if x.endswith(b"\n")]
    motion = any(_MOTION.search(x.upper().replace(b" ", b"")) for x in gcode
                 if not x.startswith(b"$G") and not x.startswith(b"$#"))
    return motion, any(_EEPROM.search(x.upper()) for x in gcode)


@dataclass(frozen=True)
class Row:
    name: str
    cite: str
    title: str
    command: tuple[bytes, ...]
    setup: tuple[bytes, ...] = MODES
    reads: tuple[bytes, ...] = READ_ALL
    inert: bool = False     # the command must change nothing read back (an error, a no-op)

    @property
    def steps(self) -> tuple[bytes, ...]:
        return (*self.setup, *self.command, *self.reads)


_G = "src:gcode.c gc_execute_line"
_RPT = "report.c report_gcode_modes, report_ngc_parameters, report_realtime_status"
_RST = "src:system.c system_execute_line case 'R'; settings.c settings_restore"

ROWS: tuple[Row, ...] = (
    Row("g92", f"{_G} [19] NON_MODAL_SET_COORDINATE_OFFSET; {_RPT}",
        "G92 in G20 G91 with a TLO: the work position becomes the words (inches, absolute, "
        "less the TLO on Z); modes, TLO, G54-G59 kept", (b"G92X1Y2Z3\n",)),
    Row("g92-one-axis", f"{_G} [19] NON_MODAL_SET_COORDINATE_OFFSET; {_RPT}",
        "G92 Y only: X and Z keep their G92 offsets", (b"G92Y-1\n",)),
    Row("g92.1", f"{_G} [19] NON_MODAL_RESET_COORDINATE_OFFSET (clear_vector); "
        "protocol.c system_flag_wco_change; " + _RPT,
        "G92.1 zeroes the G92 offset (WCO: in the next report), keeps the TLO and modes",
        (b"G92.1\n",)),
    Row("g92.2", f"{_G} STEP 2 case 92 (mantissa 10 only; 1.1f has no G92.2)",
        "G92.2 is error:20 and changes nothing (the offset stays)", (b"G92.2\n",), inert=True),
    Row("g43.1", f"{_G} [14] TOOL_LENGTH_OFFSET_ENABLE_DYNAMIC; {_RPT}",
        "G43.1 Z in G20 replaces the TLO (25.4 x Z mm), not added to it; G92 kept",
        (b"G43.1Z0.2\n",)),
    Row("g49", f"{_G} TOOL_LENGTH_OFFSET_CANCEL; {_RPT}",
        "G49 clears the TLO only", (b"G49\n",)),
    Row("g90.1", f"{_G} STEP 2 case 90/91 (mantissa 10 is error:20)",
        "G90.1 is error:20 and changes nothing", (b"G90.1\n",), inert=True),
    Row("g91.1", f"{_G} STEP 2 case 91.1 (arc IJK incremental, grbl's only mode)",
        "G91.1 is ok and changes no other group (G91 stays)", (b"G91.1G90\n",)),
    Row("modal-words", f"{_G} STEP 3-4 (each word its own group); {_RPT}",
        "G93, G21, G90, G54, G94, G17, G80 each change their own group only",
        (b"G93\n", b"$G\n", b"G21\n", b"$G\n", b"G90\n", b"$G\n", b"G54\n", b"$G\n", b"G94F30\n", b"$G\n",
         b"G17\n", b"$G\n", b"G80\n", b"$G\n")),
    Row("program-end-m2", f"{_G} [21] PROGRAM_FLOW_COMPLETED; {_RPT}",
        "M2: G1 G17 G90 G94 G54, spindle and coolant off, overrides 100 % "
        "(RESTORE_OVERRIDES_AFTER_PROGRAM_END); G20, T, F, S, G92, TLO kept",
        (b"M2\n", b"?")),
    Row("program-end-m30", f"{_G} [21] PROGRAM_FLOW_COMPLETED (M30 as M2); {_RPT}",
        "M30 does all M2 does", (b"M30\n", b"?")),
    Row("soft-reset", "src:protocol.c protocol_exec_rt_system (EXEC_RESET); main.c; "
        f"gcode.c gc_init; {_RPT}",
        "a soft reset: every modal group, T, F, S, G92 and TLO back to the defaults, overrides "
        "100 %; G54-G59 kept (EEPROM)", (b"\x18",), setup=(*MODES, b"G93T7F9\n")),
    Row("override-resets", "src:protocol.c protocol_exec_rt_system (EXEC_FEED_OVR_RESET, "
        "EXEC_RAPID_OVR_RESET, EXEC_SPINDLE_OVR_RESET)",
        "0x90, 0x95, 0x99 each put only their own override back to 100 %",
        (b"\x90", b"?", b"\x91", b"\x95", b"?", b"\x96", b"\x99", b"?")),
    Row("check-mode", "src:system.c system_execute_line case 'C'; protocol.c; gcode.c gc_init",
        "$C, a line, $C again: the line changes nothing outside check mode, the reset after "
        "it clears the modes", (b"$C\n", b"G21G90G92X0\n", b"$G\n", b"$C\n")),
    Row("line-filter", "src:protocol.c protocol_main_loop (c <= ' ' dropped: spaces and "
        "control characters; '/' dropped, block delete not supported; '(' to ')' and ';' to the "
        "line end are comments); " + _RPT,
        "spaces, tabs, a form feed, '/', a ( ) comment and a ; comment are left out of the "
        "line: G2 1<TAB>G9/0(G91 T5)G<FF>54 ;G20 runs as G21 G90 G54",
        (b"G2 1\tG9/0(G91 T5)G\x0c54 ;G20\n",)),
    Row("safety-door", "src:protocol.c protocol_exec_rt_system (EXEC_SAFETY_DOOR: "
        "[MSG:Check Door], the Door state from Idle and from a hold; EXEC_CYCLE_START resumes "
        "with the door closed); report.c report_realtime_status (Door:0)",
        "0x84 from Idle and from a feed hold: [MSG:Check Door], Door:0; ~ back to Idle; "
        "modes, offsets and overrides kept",
        (b"\x84", b"?", b"~", b"?", b"!", b"?", b"\x84", b"?", b"~", b"?")),
    Row("safety-door-check-mode", "src:protocol.c protocol_exec_rt_system (hold, door and "
        "sleep requests are ignored in STATE_ALARM and STATE_CHECK_MODE)",
        "0x84 in check mode: no message, the state stays Check", (b"$C\n", b"\x84", b"?",
                                                                     b"G21\n", b"$C\n")),
    # --- with the EEPROM opt-in -------------------------------------------------------------
    Row("g10-l2-p2", f"{_G} [19] NON_MODAL_SET_COORDINATE_DATA (L2, P2 = G55); "
        "settings.c settings_write_coord_data; " + _RPT,
        "G10 L2 P2 writes G55 only (the active system: WCO: changes), in inches",
        (b"G10L2P2X1Y2Z3\n",), setup=(*STORED, *MODES)),
    Row("g10-l2-p0", f"{_G} [19] NON_MODAL_SET_COORDINATE_DATA (P0 = the active system)",
        "G10 L2 P0 writes the active system (G55), no other", (b"G10L2P0X-1Z2\n",),
        setup=(*STORED, *MODES)),
    Row("g10-l20", f"{_G} [19] NON_MODAL_SET_COORDINATE_DATA (L20: position - G92 - TLO - "
        "words); settings.c settings_write_coord_data",
        "G10 L20 P3 writes G56 so the position reads the words there, from the G92 and TLO "
        "in force", (b"G10L20P3X1Y2Z3\n", b"G56\n", b"?"), setup=(*STORED, *MODES)),
    Row("rst-hash", f"{_RST} (SETTINGS_RESTORE_PARAMETERS)",
        "$RST=# zeroes G54-G59, G28, G30 only: settings and startup lines kept",
        (b"$RST=#\n",), setup=(*STORED, *MODES), reads=(*READ_ALL, *READ_EEPROM)),
    Row("rst-dollar", f"{_RST} (SETTINGS_RESTORE_DEFAULTS)",
        "$RST=$ restores the settings only: offsets and startup lines kept",
        (b"$RST=$\n",), setup=(*STORED, *MODES), reads=(*READ_ALL, *READ_EEPROM)),
    Row("rst-star", f"{_RST} (SETTINGS_RESTORE_ALL)",
        "$RST=* restores settings, offsets, startup lines and build info",
        (b"$RST=*\n",), setup=(*STORED, b"$I=shop\n", *MODES),
        reads=(*READ_ALL, *READ_EEPROM, b"$I\n")),
    Row("startup-line-1", "src:system.c system_execute_line case 'N'; "
        "settings.c settings_store_startup_line; main.c/protocol.c system_execute_startup",
        "$N1=G20 stores line 1 only (line 0 kept), runs the block, and both run after a reset",
        (b"$N1=G20\n",), setup=STORED,
        reads=(b"$N\n", b"$G\n", b"G21G90\n", b"\x18", b"$G\n")),
    Row("status-mask", "src:settings.c ($10 BITFLAG_RT_STATUS_POSITION_TYPE, "
        "BITFLAG_RT_STATUS_BUFFER_STATE); report.c report_realtime_status",
        "$10 bit 0 picks MPos:/WPos:, bit 1 adds Bf:, each alone",
        (b"$10=0\n", b"?", b"$10=2\n", b"?", b"$10=3\n", b"?", b"$10=1\n", b"?")),
    Row("setting-writes", "src:settings.c settings_store_global_setting (axis settings "
        "100 + 10 * kind + axis; $13 system_flag_wco_change)",
        "$101, $111, $122, $132, $12 and $13 each store their own row only; $13 reads $G, $# "
        "and ? in inches",
        (b"$101=123.5\n", b"$111=432\n", b"$122=9\n", b"$132=77\n", b"$12=0.004\n",
         b"$13=1\n"), setup=(*STORED, *MODES), reads=(*READ_EEPROM, *READ_ALL)),
    # --- with the motion opt-in -------------------------------------------------------------
    Row("g28.1", f"{_G} [19] NON_MODAL_SET_HOME_0; settings.c settings_write_coord_data",
        "G28.1 stores the machine position as G28 only (G30 kept)", (b"G28.1\n",),
        setup=(*MOVED, *STORED, *MODES)),
    Row("g30.1", f"{_G} [19] NON_MODAL_SET_HOME_1; settings.c settings_write_coord_data",
        "G30.1 stores the machine position as G30 only (G28 kept)", (b"G30.1\n",),
        setup=(*MOVED, *STORED, *MODES)),
    Row("program-end-outputs", f"{_G} [21] PROGRAM_FLOW_COMPLETED; spindle_control.c "
        "spindle_set_state; coolant_control.c coolant_set_state",
        "M2 with the spindle and flood on: both off (A: gone), FS: speed 0",
        (b"M2\n", b"?"), setup=(*MODES, *OUTPUTS, b"?")),
    Row("soft-reset-outputs", "src:protocol.c (EXEC_RESET); main.c (spindle_init, "
        "coolant_init); gcode.c gc_init",
        "a soft reset with the spindle and flood on: both off, M5 M9", (b"\x18",),
        setup=(*MODES, *OUTPUTS, b"?")),
    Row("sleep-outputs", "src:system.c system_execute_line case 'S' (SLP); protocol.c "
        "protocol_exec_rt_system (EXEC_SLEEP: spindle_set_state off, coolant_set_state off)",
        "$SLP with the spindle and flood on: both off in $G and A:, Sleep; a reset wakes into "
        "Alarm with the modes reset", (b"$SLP\n", b"$G\n", b"?", b"?", b"\x18"),
        setup=(*MODES, *OUTPUTS, b"?")),
    Row("flood-toggle", "src:protocol.c protocol_exec_rt_system (EXEC_COOLANT_FLOOD_OVR_TOGGLE: "
        "coolant_set_state, report_ovr_counter = 0); report.c report_realtime_status",
        "0xA0 toggles M8 alone (M3 stays), A: in the next report", (b"\xa0", b"?", b"\xa0"),
        setup=(*MODES, *OUTPUTS, b"?", b"?")),
)


def _run(row: Row) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        from conform.families.grbl.conformance.machine import Pair
        from conform.families.grbl.unit.model import GrblUnit

        ref = EmuTarget(lambda: GrblUnit(s.v, s.spec), f"emu:{s.v.id}", baud=s.target.baud)
        try:
            r = Session(ref, s.spec, s.v)
            pair = Pair(s, r, lambda lines: lines)
            if not pair.linked:
                r.fresh()              # both at power-up
                return _compare(pair, row)
            pair.start()               # the reference where the target stands
            try:
                passed, expected, actual = _compare(pair, row)
            finally:
                left = _put_back(pair) if needs(row.steps)[1] else ""
            return passed, expected, actual + left
        finally:
            ref.close()
    return run


def _put_back(pair: Pair) -> str:
    """A unit behind a link keeps what a row wrote to its EEPROM: the settings, the G54-G59
    offsets (:meth:`.machine.Pair.put_back`), the startup lines and the build info go back
    to what they were; a changed G28/G30 is said (storing it again would move the machine)."""
    from conform.families.grbl.conformance.readback import read_eeprom

    note = pair.put_back()
    was, t = pair.known, pair.t
    if was is None:
        return note
    now = read_eeprom(t)
    for i, line in enumerate(was.startup):
        if i < len(now.startup) and now.startup[i] != line:
            t.talk(f"$N{i}={line}\n".encode())
    if now.build_info != was.build_info:
        t.talk(f"$I={was.build_info}\n".encode())
    return note


def _compare(pair: Pair, row: Row) -> Outcome:
    """Each step to both; the first step whose answers differ fails the row."""
    shown: list[str] = []
    first = len(row.setup)
    for i, data in enumerate(row.steps):
        if pair.linked:
            pair._settle()
        lines = data.count(b"\n")
        status = data.count(b"?") if not lines else 0
        got, want = (x.talk(data, answers=lines, status=status, timeout=3.0).lines
                     for x in (pair.t, pair.r))
        if got != want:
            where = "setup" if i < first else "command" if i < first + len(row.command) \
                else "read"
            return (False, f"after {data!r} ({where}): {' | '.join(want) or '-'}",
                    " | ".join(got) or "(silence)")
        if i >= first:
            shown.append(f"{data!r}: {' | '.join(got)}")
    return True, "every answer as the reference unit's", "; ".join(shown)


def generate(spec: GrblSpec, vid: str) -> list[GrblCheck]:
    """One check per row, flagged by what its lines do on a real unit."""
    out = []
    for row in ROWS:
        motion, eeprom = needs(row.steps)
        out.append(GrblCheck(f"{vid}/from_state/effect/{row.name}", row.cite, row.title,
                             _run(row), motion=motion, eeprom=eeprom))
    return out
