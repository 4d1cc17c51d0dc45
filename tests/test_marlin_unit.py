"""The Marlin reference unit against what 2.1.2.4's source does (queue.cpp, gcode.cpp,
e_parser.h): every error path with Resend: and ok, the silent repeat, the comment that eats the
checksum, the checksum without a number, M110, the queue and receive buffer, keepalives,
M112, reset; and its ground truth of which numbered line ran how often."""

from __future__ import annotations

import pytest

from conform.families.marlin.protocol.codec import checksum, detect, frame, parse_host
from conform.families.marlin.spec import load_marlin
from conform.families.marlin.unit.unit import MarlinUnit

S = load_marlin()


def unit(vid="marlin-2.1"):
    u = MarlinUnit(S.variant(vid), S)
    u.poll(1.0)          # the banner
    return u


def lines(u, data, t, until=None):
    u.receive(data, t)
    return [x.decode("latin-1").rstrip("\n") for _, x in u.poll(until if until is not None else t + 1)]


def test_checksum_and_frame():
    assert checksum(b"N1 M105") == 38
    assert frame(1, "M105") == b"N1 M105*38\n"
    h = parse_host(b"N7 G1 X10 ; comment*12\n")
    assert h.n == 7 and h.checksum is None and h.code == "G1"
    assert parse_host(b"N5 M110 N100*9\n").n == 100


def test_the_three_facts_from_the_real_firmware():
    u = unit()
    assert lines(u, frame(1, "G90"), 2) == ["ok"]
    assert lines(u, frame(1, "G90"), 3) == []                      # already processed: silence
    body = b"N2 G90 ; note"
    assert lines(u, body + b"*%d\n" % checksum(body), 4) == [
        "Error:No Checksum with line number, Last Line: 1", "Resend: 2", "ok"]
    assert lines(u, b"M114*99\n", 5)[-1] == "ok"                   # no N: not checked, run
    assert u.truth.executed == {1: 1}
    assert u.truth.log[-1][2] == "M114*99"


def test_every_error_path():
    u = unit()
    assert lines(u, frame(1, "G90"), 2) == ["ok"]
    assert lines(u, b"N2 G90*1\n", 3) == ["Error:checksum mismatch, Last Line: 1", "Resend: 2",
                                          "ok"]
    assert lines(u, b"N2 G90\n", 4) == ["Error:No Checksum with line number, Last Line: 1",
                                        "Resend: 2", "ok"]
    assert lines(u, frame(5, "G90"), 5) == [
        "Error:Line Number is not Last Line Number+1, Last Line: 1", "Resend: 2", "ok"]
    assert lines(u, frame(2, "M9999 P1"), 6) == ['echo:Unknown command: "M9999 P1"', "ok"]
    assert lines(u, frame(2, "G90"), 7) == []
    assert lines(u, frame(1, "G90"), 8) == []                       # last_N - 1: silent too
    assert lines(u, frame(0, "G90"), 9)[0].startswith("Error:Line Number")   # older: error
    assert [r[1:] for r in u.truth.resends] == [(2, "checksum"), (2, "no-checksum"),
                                                (2, "line-number"), (3, "line-number")]


def test_an_error_empties_the_receive_buffer():
    u = unit()
    bad = b"N1 G90*0\n" if checksum(b"N1 G90") else b"N1 G90*1\n"
    assert lines(u, bad + frame(2, "G90") + frame(3, "G90"), 2) == [
        "Error:checksum mismatch, Last Line: 0", "Resend: 1", "ok"]
    assert u.truth.executed == {} and u.discarded == len(frame(2, "G90") + frame(3, "G90"))


def test_m110_takes_the_last_n_on_the_line():
    u = unit()
    assert lines(u, frame(7, "M110 N20"), 2) == ["ok"]
    assert lines(u, frame(21, "G90"), 3) == ["ok"]
    assert lines(u, b"M110 N100\n", 4) == ["ok"]
    assert lines(u, frame(101, "G90"), 5) == ["ok"]


def test_lines_are_read_and_checked_while_a_dwell_blocks():
    """MarlinCore.cpp idle() -> manage_inactivity() -> queue.get_available_commands(): as
    recorded (blocking-reads.transcript), a line error is answered during the dwell, good
    lines wait in the queue (BUFSIZE 4, the dwell's own slot included), and what does not
    fit waits outside the ring on the native build: nothing is lost."""
    u = unit()
    assert lines(u, frame(1, "G4 S3"), 2.0, until=2.1) == []
    assert lines(u, b"N2 G90*1\n", 2.5, until=2.6) == [
        "Error:checksum mismatch, Last Line: 1", "Resend: 2", "ok"]      # during the dwell
    assert lines(u, frame(4, "G90"), 3.0, until=3.1) == [
        "Error:Line Number is not Last Line Number+1, Last Line: 1", "Resend: 2", "ok"]
    data = b"".join(frame(n, "G90") for n in range(2, 20))
    u.receive(data, 3.5)
    assert len(u.queue) == 3 and u.lost == 0 and u.pending
    out = [(round(t, 2), x.decode().strip()) for t, x in u.poll(10.0)]
    assert out[0] == (4.0, "echo:busy: processing") and out[1] == (5.0, "ok")
    assert [x for _, x in out[2:]] == ["ok"] * 18 and u.truth.executed[19] == 1


def test_an_avr_board_drops_what_does_not_fit():
    import dataclasses

    v = S.variant("marlin-2.1")
    u = MarlinUnit(dataclasses.replace(v, options={**v.options, "RX_WAITS_OUTSIDE": False}), S)
    u.poll(1.0)
    u.receive(frame(1, "G4 S3"), 2.0)
    data = b"".join(frame(n, "G90") for n in range(2, 30))
    u.receive(data, 2.2)
    assert u.lost == len(data) - v.rx_buffer


def test_keepalive_interval_and_m105_m114_m115():
    u = unit()
    out = lines(u, b"G4 S5\n", 2, until=8)
    assert out == ["echo:busy: processing", "echo:busy: processing", "ok"]
    assert lines(u, b"M105\n", 9)[0].startswith("ok T:25.00 /0.00 B:25.00 /0.00 @:0 B@:0")
    assert lines(u, b"M114\n", 10) == ["X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0", "ok"]
    m115 = lines(u, b"M115\n", 11)
    assert m115[0].startswith("FIRMWARE_NAME:Marlin 2.1.2.4 ") and m115[-1] == "ok"
    assert "Cap:EEPROM:1" in m115 and "Cap:EMERGENCY_PARSER:0" in m115


def test_advanced_ok_and_the_emergency_parser():
    u = unit("marlin-2.1-adv")
    assert lines(u, frame(1, "G90"), 2) == ["ok N1 P15 B3"]
    assert lines(u, b"G90\n", 3) == ["ok P15 B3"]
    u.receive(b"G4 S3\n", 4.0)
    u.receive(frame(2, "M112"), 4.5)                          # acted on as it arrives
    assert [x for _, x in u.poll(4.5)] == [b"echo:M112 Shutdown\n",
                                           b"Error:Printer halted. kill() called!\n"]
    assert lines(u, b"M105\n", 6, until=20) == []


HALT = ["echo:M112 Shutdown", "Error:Printer halted. kill() called!"]


def test_m112_plain_acts_at_once_numbered_waits_for_the_dwell():
    """queue.cpp get_serial_commands' critical commands (no emergency parser): a line that
    starts with M112 kills as it is read, during a dwell too; a numbered one starts with N
    and runs in its turn, after the dwell's ok (blocking-reads.transcript, halt.transcript)."""
    u = unit()
    u.receive(b"G4 S3\n", 2.0)
    u.receive(b"M112\n", 2.5)
    out = [(round(t, 1), x.decode().strip()) for t, x in u.poll(10)]
    assert out == [(2.5, x) for x in HALT]
    u = unit()
    u.receive(frame(1, "G4 S3"), 2.0)
    u.receive(frame(2, "M112"), 2.5)
    out = [(round(t, 1), x.decode().strip()) for t, x in u.poll(10)]
    assert out == [(4.0, "echo:busy: processing"), (5.0, "ok")] + [(5.0, x) for x in HALT]
    assert lines(u, b"M105\n", 11, until=20) == []


def test_m410_plain_stops_a_move_as_it_is_read():
    """A plain M410 one second into a 5 s move stops it there (quickstop_stepper), holds the
    loop 1 s (Planner::quick_stop), and the queued M410 takes 1 s more: ok 2 s later."""
    u = unit()
    assert lines(u, b"G1 X50 F600\n", 2.0, until=2.05) == ["ok"]
    out = lines(u, b"M410\n", 3.0, until=6.0)
    assert out == ["ok"]
    m114 = lines(u, b"M114\n", 6.0)
    x = float(m114[0].split()[0][2:])
    assert 8.0 < x < 9.0 and m114[0].endswith(f"Count X:{round(x * 80)} Y:0 Z:0")


def test_m114_counts_the_planner_and_lowercase_is_unknown():
    u = unit()
    lines(u, b"G1 X10 F600\n", 2.0, until=2.05)
    assert lines(u, b"M114\n", 2.1, until=2.15)[0] == \
        "X:10.00 Y:0.00 Z:0.00 E:0.00 Count X:800 Y:0 Z:0"
    assert lines(u, b"m105\n", 4.0) == ['echo:Unknown command: "m105"', "ok"]
    assert lines(u, b"X10\n", 5.0) == ['echo:Unknown command: "X10"', "ok"]
    assert lines(u, b"M1\x0005\n", 6.0) == ['echo:Unknown command: "M1"', "ok"]   # NUL ends it
    assert lines(u, b"M111 S1\n", 7.0) == ["echo:DEBUG:ECHO", "ok"]
    u.receive(b"M105\n", 8.0)
    assert u.poll(9.0)[0][1] == b"echo:M105\r\n"


def test_reset_banner_and_line_number_zero():
    u = unit()
    lines(u, frame(1, "G90"), 2)
    u.power_cycle(3.0)
    out = lines(u, b"", 3.0, until=4.0)
    assert out[:4] == ["x86_64 Initialized", "start", "PowerUp", "Marlin 2.1.2.4"]
    assert lines(u, frame(1, "G90"), 5) == ["ok"]
    assert u.truth.executed == {1: 2} and u.truth.resets == [3.0]


@pytest.mark.parametrize("junk", [b"\x00\xff" * 300, b"N" * 500 + b"\n", b";;;\n\r\n\x08\x08N\n",
                                  b"N99999999999999999999 G1*1\n", b"\\\\\\\n"],
                         ids=["binary", "long", "comments", "huge-number", "escapes"])
def test_never_dies_of_what_a_sender_sends(junk):
    u = unit("marlin-2.1-adv")
    u.receive(junk, 2.0)
    u.poll(5.0)
    u.receive(b"\n", 5.5)                       # ends whatever line the junk left open
    u.poll(6.0)
    assert lines(u, b"M110 N0\n", 7) == ["ok P15 B3"]
    assert lines(u, frame(1, "G90"), 8) == ["ok N1 P15 B3"]


def test_detect():
    host = b"".join(frame(n, "G1 X1") for n in range(1, 6))
    assert detect(host, b"ok\n" * 5).score >= 0.8
    assert detect(b"", b"Resend: 3\nok\n").score >= 0.9
    assert detect(b"G1X1\n", b"<Idle|MPos:0,0,0>\nok\n").score < 0.5


@pytest.mark.parametrize("vid", ["marlin-2.1", "marlin-2.1-adv"])
def test_random_traffic_never_stops_the_unit(vid):
    import random

    rng = random.Random(7)
    words = [b"N", b"M110", b"M112", b"M108", b"M410", b"G4 S1", b"G1 X5", b"*", b";", b"\\",
             b"\n", b"\r", b"M105", b"M155 S1", b"G28", b"\x08", b"-", b"99", b" "]
    for _ in range(30):
        u = MarlinUnit(S.variant(vid), S)
        t = 0.0
        for _ in range(200):
            t += rng.random() * 0.5
            u.receive(b"".join(rng.choice(words) for _ in range(rng.randrange(1, 12))), t)
            u.poll(t)
        u.power_cycle(t + 10)     # (a halted unit needs the reset; a busy one is freed by it)
        u.poll(t + 60)
        assert lines(u, frame(1, "G90"), t + 61, until=t + 90)[-1].startswith("ok")


def test_the_rarely_sent_commands_answer_as_the_source_says():
    """M85, M113, M120/M121, M200, M211, M302, M303, M428, M575, M999 (commands.toml): each
    is compiled into the linux_native build, none is an Unknown command."""
    u, t = unit(), 1.0
    said = {}
    for cmd in ("M428", "M85 S0", "M120", "M121", "M113 S0", "M113", "M200 D2.85", "M200",
                "M211 S0", "M211", "M302 S0", "M302", "M303 E3", "M575 B57", "M575 B57600 P1",
                "M575 B7", "M110 N9", "M999", "M999 S1"):
        said[cmd] = lines(u, f"{cmd}\n".encode(), t)
        t += 0.5
    assert said["M428"] == ["echo:Home XYZ First", "ok"]            # not homed yet
    assert all(said[c] == ["ok"] for c in ("M85 S0", "M120", "M121", "M113 S0", "M200 D2.85",
                                            "M211 S0", "M302 S0", "M575 B57600 P1", "M999 S1"))
    assert said["M113"] == ["echo:M113 S0", "ok"]
    assert said["M200"] == ["  M200 S1 D2.85", "ok"]
    assert said["M211"][0] == "  M211 S0 ; OFF"
    assert said["M302"] == ["echo:Cold extrudes are enabled (min temp 0C)", "ok"]
    assert said["M303 E3"] == ["PID Autotune failed! Bad heater id", "ok"]
    assert said["M575 B57"] == ["echo: Serial 0 baud rate set to 57600", "ok"]
    assert said["M575 B7"] == ["echo:?(B)aud rate implausible.", "ok"]
    assert said["M999"] == ["Resend: 10", "ok", "ok"]
    # M113 S0: a dwell says no busy: at all
    assert lines(u, b"G4 S3\n", t, until=t + 4) == ["ok"]
    # after homing M428 takes the offsets from where the axes are
    lines(u, b"G28\nG1 X5 Y6 F3000\nM400\n", t + 4, until=t + 40)
    assert lines(u, b"M428\n", t + 41)[0].startswith("X:0.00 Y:0.00 Z:0.00")
    assert "M206 X-5.00 Y-6.00 Z0.00" in " ".join(lines(u, b"M503\n", t + 42))
