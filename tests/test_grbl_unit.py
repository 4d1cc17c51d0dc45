"""The grbl reference unit in-process, on virtual time: the documented exchanges as golden
data, every error code the tables say it produces, the receive ring, motion timing, states."""

from __future__ import annotations

import random

import pytest

from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


def fresh() -> GrblUnit:
    u = GrblUnit(V, G)
    assert u.poll(0.0) == [(0.0, b"\r\nGrbl 1.1f ['$' for help]\r\n")]
    return u


def say(u: GrblUnit, data: bytes, t: float, wait: float = 0.05) -> list[str]:
    u.receive(data, t)
    text = b"".join(d for _, d in u.poll(t + wait)).decode("latin-1")
    assert text == "" or text.endswith("\r\n")
    return text.split("\r\n")[:-1]


@pytest.mark.parametrize("ex", G.examples, ids=[e.id for e in G.examples])
def test_documented_examples(ex):
    u = fresh()
    t = 0.0
    for item in ex.setup:
        t += 0.1
        say(u, item, t)
    assert tuple(say(u, ex.send, t + 0.1)) == ex.expect


CODES = [c for c in G.errors.values() if c.send is not None]


@pytest.mark.parametrize("code", CODES, ids=[f"error:{c.number}" for c in CODES])
def test_error_codes(code):
    u = fresh()
    t = 0.0
    for item in code.setup:
        t += 0.1
        say(u, item, t)
    assert say(u, code.send, t + 0.1)[-1:] == [f"error:{code.number}"]


def test_a_rejected_line_changes_nothing():
    u = fresh()
    before = say(u, b"$G\n", 0.1)
    assert say(u, b"G91G20G1X1Y\n", 0.2) == ["error:2"]
    assert say(u, b"$G\n", 0.3) == before


def test_receive_ring_loses_what_does_not_fit():
    """During a dwell the ring fills; bytes beyond 128 are lost (serial.c), so fewer oks."""
    u = fresh()
    filler = b"G90\n" * 48                       # 192 bytes
    lines = say(u, b"G4P1\n" + filler, 0.1, wait=2.0)
    assert lines.count("ok") == 1 + 128 // 4
    assert u.lost == len(filler) - 128


def test_realtime_bytes_bypass_a_full_ring():
    u = fresh()
    u.receive(b"G4P1\n" + b"G90\n" * 40, 0.1)
    assert u.rx_free == 0
    out = say(u, b"?", 0.2, wait=0.01)
    assert len(out) == 1 and out[0].startswith("<Idle|")    # a dwell keeps grbl Idle


def test_line_limit_is_79_characters_after_stripping():
    u = fresh()
    assert say(u, b"N" + b"0" * 77 + b"1\n", 0.1) == ["ok"]
    assert say(u, b"N" + b"0" * 78 + b"1\n", 0.2) == ["error:11"]
    # spaces and comments are not counted
    assert say(u, b"G90 " + b" " * 100 + b"(" + b"x" * 100 + b")\n", 0.3) == ["ok"]


def test_crlf_is_two_lines():
    assert say(fresh(), b"G90\r\n", 0.1) == ["ok", "ok"]


def test_trapezoid_timing_from_the_settings():
    """10 mm at 500 mm/min with 10 mm/s²: 0.833 s up, 0.367 s cruise, 0.833 s down."""
    u = fresh()
    say(u, b"G1X-10F500\n", 0.0)
    assert say(u, b"?", 1.9, wait=0.01)[0].startswith("<Run|")
    report = say(u, b"?", 2.1, wait=0.01)[0]
    assert report.startswith("<Idle|MPos:-10.000,0.000,0.000")
    mid = GrblUnit(V, G)
    mid.receive(b"G1X-10F500\n", 0.0)
    assert abs(mid.planner.blocks[0].duration - (2 * 500 / 60 / 10 + (10 - (500 / 60) ** 2 / 10) / (500 / 60))) < 1e-9


def test_status_mask_and_refresh_counters():
    u = fresh()
    assert say(u, b"$10=2\n", 0.1) == ["ok"]
    first = say(u, b"?", 0.2)[0]
    assert first == "<Idle|WPos:0.000,0.000,0.000|Bf:15,128|FS:0,0|WCO:0.000,0.000,0.000>"
    assert say(u, b"?", 0.3)[0].endswith("|Ov:100,100,100>")
    for k in range(8):
        assert "WCO" not in say(u, b"?", 0.4 + k * 0.1)[0]
    assert "WCO:" in say(u, b"?", 1.3)[0]   # every 10th report when idle: the 11th


def test_repeated_queries_before_a_report_merge():
    u = fresh()
    u.receive(b"???", 0.1)
    assert len([x for _, x in u.poll(0.2)]) == 1


def test_feed_hold_and_resume():
    u = fresh()
    say(u, b"G1X-20F300\n", 0.0)
    say(u, b"!", 1.0, wait=0.0)
    assert say(u, b"?", 1.01)[0].startswith("<Hold:1|")
    held = say(u, b"?", 3.0)[0]
    assert held.startswith("<Hold:0|")
    pos = held.split("MPos:")[1].split("|")[0]
    assert say(u, b"?", 4.0)[0].split("MPos:")[1].split("|")[0] == pos   # stands still
    say(u, b"~", 4.1, wait=0.0)
    assert say(u, b"?", 4.5)[0].startswith("<Run|")
    assert say(u, b"?", 12.0)[0].startswith("<Idle|MPos:-20.000")


def test_reset_in_motion_raises_alarm_3_and_locks():
    u = fresh()
    say(u, b"G1X-20F300\n", 0.0)
    # ALARM:3, then report.c's delay_ms(500) before anything else (the banner)
    assert say(u, b"\x18", 1.0, wait=0.45) == ["ALARM:3"]
    assert say(u, b"", 1.45, wait=0.1) == ["", V.banner, "[MSG:'$H'|'$X' to unlock]"]
    assert say(u, b"G0X0\n", 1.6) == ["error:9"]
    assert say(u, b"$X\n", 1.7) == ["[MSG:Caution: Unlocked]", "ok"]
    assert say(u, b"G0X0\n", 1.8) == ["ok"]


def test_reset_at_rest_keeps_position_and_no_alarm():
    u = fresh()
    say(u, b"G0X-1\n", 0.0, wait=2.0)
    assert say(u, b"\x18", 3.0) == ["", V.banner]
    assert say(u, b"?", 3.1)[0].startswith("<Idle|MPos:-1.000")


def test_check_mode_moves_nothing():
    u = fresh()
    assert say(u, b"$C\n", 0.1) == ["[MSG:Enabled]", "ok"]
    assert say(u, b"G1X-5F100\nG2X-5R1F100\n", 0.2) == ["ok", "error:33"]
    assert say(u, b"?", 0.3)[0].startswith("<Check|MPos:0.000,0.000,0.000")
    assert say(u, b"$C\n", 0.4) == ["[MSG:Disabled]", "ok", "", V.banner]


def test_jog_and_jog_cancel():
    u = fresh()
    assert say(u, b"$J=G91X-10F600\n", 0.0) == ["ok"]
    assert say(u, b"?", 0.5)[0].startswith("<Jog|")
    assert say(u, b"$J=G91X-10F600\n", 0.6) == ["ok"]          # jogs queue while jogging
    u.receive(b"\x85", 0.7)
    report = say(u, b"?", 3.0)[0]
    assert report.startswith("<Idle|")
    assert -10.0 < float(report.split("MPos:")[1].split(",")[0]) < 0.0
    assert say(u, b"$G\n", 3.1)[0] == "[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"  # untouched


def test_soft_limit_alarm_is_critical():
    u = fresh()
    for t, line in enumerate((b"$22=1\n", b"$20=1\n")):
        assert say(u, line, 0.1 * (t + 1)) == ["ok"]
    assert say(u, b"G0X5\n", 0.5, wait=0.4) == ["ALARM:2"]     # report.c delay_ms(500)
    assert say(u, b"", 0.9, wait=0.2) == ["[MSG:Reset to continue]"]
    assert say(u, b"?", 1.2) == []                             # ignored until a reset
    assert say(u, b"$X\n", 1.3) == []
    # the G0 line grbl was inside is answered at the reset, before the banner (protocol.c)
    assert say(u, b"\x18", 1.4) == ["ok", "", V.banner, "[MSG:'$H'|'$X' to unlock]"]


def test_overrides_and_program_end():
    u = fresh()
    say(u, b"?", 0.1)
    say(u, b"?", 0.2)
    u.receive(b"\x91\x91\x93\x96\x9a", 0.3)
    assert "|Ov:121,50,110" in say(u, b"?", 0.4)[0]
    assert say(u, b"G1X-1F100M3S500\nM2\n", 0.5, wait=2.0)[-2:] == ["[MSG:Pgm End]", "ok"]
    assert say(u, b"$G\n", 3.0)[0] == "[GC:G1 G54 G17 G21 G90 G94 M5 M9 T0 F100 S500]"


def test_sleep_and_homing():
    u = fresh()
    assert say(u, b"$SLP\n", 0.1) == ["ok", "[MSG:Sleeping]"]
    assert say(u, b"G0X0\n", 0.2) == []                         # asleep: nothing is read
    assert say(u, b"\x18", 0.3)[-1] == "[MSG:'$H'|'$X' to unlock]"
    say(u, b"$22=1\n", 0.4)
    assert say(u, b"$H\n", 0.5, wait=0.1) == []                 # homing takes time
    assert say(u, b"?", 0.6) == []                             # no reports while homing
    lines = say(u, b"", 8.0)
    assert lines == ["ok"]
    assert say(u, b"?", 8.1)[0].startswith("<Idle|MPos:-1.000,-1.000,-1.000")


def test_planner_fills_and_stalls_the_parser():
    u = fresh()
    say(u, b"$10=2\n", 0.01)
    data = b"".join(b"G1X-%dF500\n" % (i + 1) for i in range(20))   # 15 fit the planner
    u.receive(data, 0.1)          # the last byte at 0.1 s; the first ~19 ms earlier
    u.poll(0.2)
    assert u.planner.free == 0 and u.lost == 0
    report = [x for x in say(u, b"?", 0.3) if x.startswith("<")][0]
    waiting = sum(len(b"G1X-%dF500\n" % (i + 1)) for i in range(16, 20))
    assert f"|Bf:0,{128 - waiting}|" in report


def test_never_dies_of_what_a_sender_sends():
    rng = random.Random(7)
    u = fresh()
    t = 0.0
    for _ in range(3000):
        t += rng.random() * 0.01
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
        if rng.random() < 0.3:
            data = rng.choice([b"G1X-3F200\n", b"$J=X-1F100\n", b"!", b"~", b"?", b"$X\n",
                               b"G2X1Y1R0.5F100\n", b"$C\n", b"\x85", b"$H\n", b"G38.2Z-1F50\n"])
        u.receive(data, t)
        for due, out in u.poll(t):
            assert due <= t + 1e-9 and out.endswith(b"\r\n")


def test_the_parser_waits_for_a_probe():
    u = fresh()
    u.receive(b"G38.3Z-1F60\nG90\n", 0.1)
    assert [d for _, d in u.poll(0.5)] == []           # neither answered while probing
    out = say(u, b"", 2.0)
    # G38.3: no alarm without contact; [PRB:…:0] first (motion_control.c mc_probe_cycle)
    assert out == ["[PRB:0.000,0.000,-1.000:0]", "ok", "ok"]
    assert say(u, b"$#\n", 2.1)[-2] == "[PRB:0.000,0.000,-1.000:0]"
