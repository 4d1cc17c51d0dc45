"""What the real grbl 1.1f firmware (v1.1f.20170801, default config.h) answers, fact by fact,
each expected value taken from grbl's source (gnea/grbl, file:line or function cited) and
from answers recorded from the real firmware, never from the reference unit.

The unit under test is the reference unit in virtual time; each fact is one place where it
used to answer differently from the firmware (issue: grbl judged by the real firmware)."""

from __future__ import annotations

import pytest

from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


def fresh() -> GrblUnit:
    u = GrblUnit(V, G)
    u.poll(0.0)
    return u


def say(u: GrblUnit, data: bytes, wait: float = 0.05) -> list[str]:
    t = u.now + 0.01
    u.receive(data, t)
    text = b"".join(d for _, d in u.poll(t + wait)).decode("latin-1")
    return text.split("\r\n")[:-1]


# (line, answer, where grbl decides it)
ANSWERS = [
    # gcode.c STEP 3 [20] arc offset check (35) runs before the jog check of STEP 4 (:853-857)
    (b"$J=G2X1F100\n", "error:35", "gcode.c:783 before :853"),
    (b"$J=M3X-1F100\n", "error:16", "gcode.c:853-857 (M group in a jog)"),
    # a jog keeps S and T in value_words: unused words, 36 (gcode.c:829-832)
    (b"$J=G91 X1 F100 S100\n", "error:36", "gcode.c:829-832"),
    (b"$J=G91X1F100T1\n", "error:36", "gcode.c:829-832"),
    (b"$J=\n", "error:22", "gcode.c STEP 3 [2]: a jog needs F"),
    # MAX_LINE_NUMBER 10000000 tested with '>' (gcode.c:27, :376)
    (b"N10000000 G0\n", "ok", "gcode.c:27, :376"),
    (b"N10000001 G0\n", "error:27", "gcode.c:27, :376"),
    # ENABLE_M7 is commented out in config.h: M7 is an unsupported M code
    (b"M7\n", "error:20", "gcode.c STEP 2 case 'M' (#ifdef ENABLE_M7); config.h"),
    # unsupported fractional G codes fail 20 inside the G switch, before the mantissa test (23)
    (b"G61.1\n", "error:20", "gcode.c STEP 2 case 61"),
    (b"G90.1\n", "error:20", "gcode.c STEP 2 case 90/91"),
    (b"G28.2\n", "error:20", "gcode.c STEP 2 case 28 (mantissa 0 or 10 only)"),
    (b"G38.1Z-1F10\n", "error:20", "gcode.c STEP 2 case 38"),
    (b"G43Z1\n", "error:20", "gcode.c STEP 2 case 43 (only G43.1)"),
    (b"G1.5X1\n", "error:23", "gcode.c STEP 2 mantissa > 0"),
    (b"M3.5\n", "error:23", "gcode.c STEP 2 case 'M': mantissa first"),
    # protocol.c: a '(' comment ends at the first ')'; words are checked as they are read
    (b"G21 (a (b) G5)\n", "error:20", "protocol.c protocol_main_loop; gcode.c STEP 2"),
    # the strict G80 check: axis words with G80 fail even under G92 (gcode.c [20])
    (b"G80 G92 X0\n", "error:31", "gcode.c STEP 3 [20] MOTION_MODE_NONE"),
    # G2 without axis words: 26 before the in-plane check (gcode.c [20] G2/3)
    (b"G2 F100\n", "error:26", "gcode.c STEP 3 [20] arc: no axis words"),
    # T over MAX_TOOL_NUMBER is checked as T is read, before a repeated word
    (b"T1 T300\n", "error:38", "gcode.c STEP 2 case 'T'"),
    # $x=value: read_float, '=', read_float, then the end of the line (system.c default case)
    (b"$110=5x\n", "error:3", "system.c system_execute_line: line[char_counter] != 0"),
    (b"$110=x\n", "error:2", "system.c: read_float fails"),
    (b"$256=1\n", "error:3", "system.c: parameter > 255"),
    (b"$103=1\n", "error:3", "settings.c settings_store_global_setting: no axis 3"),
    (b"$140=1\n", "error:3", "settings.c: AXIS_N_SETTINGS 4"),
    # homing is disabled by default: 5 before the line check (system.c case 'H')
    (b"$HX\n", "error:5", "system.c case 'H'; HOMING_SINGLE_AXIS_COMMANDS off (config.h)"),
    # $0 checks the truncated uint8 value: 256 is 0, below 3 (settings.c case 0)
    (b"$0=256\n", "error:6", "settings.c settings_store_global_setting case 0"),
]


@pytest.mark.parametrize(("line", "want", "where"), ANSWERS,
                         ids=[a[0].decode().strip() for a in ANSWERS])
def test_answer_as_the_firmware(line, want, where):
    assert say(fresh(), line)[-1] == want, where


def test_tool_and_feed_after_a_block_and_after_a_reset():
    """gcode.c STEP 4 [5]: gc_state.tool = gc_block.values.t (0 when the block has no T);
    gc_init memsets gc_state at a reset: T0 F0 S0 in $G afterwards."""
    u = fresh()
    assert say(u, b"T5 S100\n") == ["ok"]
    assert say(u, b"$G\n")[0].endswith("T5 F0 S100]")
    assert say(u, b"G1F300\n") == ["ok"]
    assert say(u, b"$G\n")[0].endswith("T0 F300 S100]")
    say(u, b"\x18")
    assert say(u, b"$G\n")[0].endswith("T0 F0 S0]")


def test_failed_probe_prints_prb_0_and_keeps_the_probe_position():
    """motion_control.c mc_probe_cycle: a G38.2 that ends without contact raises ALARM:5
    (report.c: 0.5 s silence after it), then [PRB:…:0] (MESSAGE_PROBE_COORDINATES, config.h)
    with sys_probe_position unchanged, then the line's ok."""
    u = fresh()
    u.receive(b"G38.2Z-1F600\n", u.now + 0.01)
    out = u.poll(u.now + 3.0)
    assert [d for _, d in out] == [b"ALARM:5\r\n", b"[PRB:0.000,0.000,0.000:0]\r\n", b"ok\r\n"]
    assert out[1][0] - out[0][0] == pytest.approx(0.5)
    assert "[PRB:0.000,0.000,0.000:0]" in say(u, b"$#\n")


def test_failed_g38_3_takes_the_position_reached():
    """mc_probe_cycle: G38.3 (no error) copies sys_position into the probe position."""
    u = fresh()
    got = say(u, b"G38.3Z-1F600\n", wait=3.0)
    assert got == ["[PRB:0.000,0.000,-1.000:0]", "ok"]


def test_message_reset_to_continue_half_a_second_after_the_alarm():
    """report.c report_alarm_message: delay_ms(500) after ALARM:N, then (critical alarm)
    protocol.c prints [MSG:Reset to continue]; at the reset the pending ok comes before the
    banner (protocol.c protocol_main_loop answers the line, then exits to main)."""
    u = fresh()
    say(u, b"$22=1\n")
    say(u, b"$20=1\n")
    assert say(u, b"G0X5\n", wait=0.45) == ["ALARM:2"]
    assert say(u, b"", wait=0.1) == ["[MSG:Reset to continue]"]
    assert say(u, b"\x18") == ["ok", "", V.banner, "[MSG:'$H'|'$X' to unlock]"]


def test_pending_line_is_answered_before_the_banner():
    """A line waiting for planner room (mc_line's loop) returns on abort and is answered ok
    before the banner (protocol.c); the reset mid-motion prints ALARM:3 first."""
    u = fresh()
    say(u, b"".join(b"G1X-%dF100\n" % (i + 1) for i in range(V.planner_blocks + 1)))
    got = say(u, b"\x18", wait=0.7)
    assert got == ["ALARM:3", "ok", "", V.banner, "[MSG:'$H'|'$X' to unlock]"]


def test_program_end_restores_the_overrides():
    """gcode.c [21] M2/M30 with RESTORE_OVERRIDES_AFTER_PROGRAM_END (config.h: on)."""
    u = fresh()
    u.receive(b"\x91", u.now + 0.01)
    assert say(u, b"M2\n") == ["[MSG:Pgm End]", "ok"]
    assert (u.ov_feed, u.ov_rapid, u.ov_spindle) == (100, 100, 100)


def test_m1_is_ignored():
    """gcode.c STEP 2 case 'M' 1: optional stop not supported, ignored (no hold)."""
    u = fresh()
    assert say(u, b"M1\n") == ["ok"]
    assert say(u, b"?")[0].startswith("<Idle|")


def test_g28_moves_only_the_named_axes_home():
    """gcode.c [19] G28 with axis words: the axes not named keep their position."""
    u = fresh()
    say(u, b"G0X-5Y-5Z-1\n", wait=2.0)
    say(u, b"G28Z-2\n", wait=3.0)
    assert say(u, b"?")[0].startswith("<Idle|MPos:-5.000,-5.000,0.000")


def test_startup_line_index_is_not_checked_and_the_block_is_run():
    """system.c case 'N': gc_execute_line runs the block (its modes stay) and
    settings_store_startup_line takes any index (no bounds check)."""
    u = fresh()
    assert say(u, b"$N5=G20\n") == ["ok"]
    assert " G20 " in say(u, b"$G\n")[0]
