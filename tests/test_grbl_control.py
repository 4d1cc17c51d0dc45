"""The grbl emulator's control socket over a real pty at 115200 baud: a hard-limit switch
raises ALARM:1, the door holds and blocks resume until it closes, the probe ends a G38.2 with
[PRB:…:1], lost answers never arrive, and an unplugged cable closes the pty and restarts the
board. Expected texts come from the tables (specs/grbl) and interface.md, not the emulator."""

from __future__ import annotations

import os
import subprocess
import sys
import termios
import time

import serial

from conform.emulator.control import send_control
from conform.families.grbl.spec.load import load_grbl
from tests.test_grbl_emulator import read_lines, start, stop

V = load_grbl().variant("grbl-1.1f")


def reset(port):
    """Drain the power-up banner (a race with pyserial's open), then Ctrl-X."""
    read_lines(port, 2, timeout=0.3)
    port.write(b"\x18")
    assert read_lines(port, 2) == ["", V.banner]


def control(sock, *words):
    reply = send_control(sock, " ".join(words))
    assert reply.startswith("ok"), reply
    return reply


def status(port):
    port.write(b"?")
    lines = read_lines(port, 1)
    assert lines and lines[0].startswith("<"), lines
    return lines[0]


def wait_state(port, prefix, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        report = status(port)
        if report.startswith("<" + prefix):
            return report
        time.sleep(0.05)
    raise AssertionError(f"never {prefix}: last {report}")


def test_inputs_over_the_control_socket(tmp_path):
    sock = str(tmp_path / "emu.sock")
    proc, path = start("--control", sock)
    port = serial.Serial(path, 115200, timeout=0.05)
    try:
        reset(port)
        # the door: a hold that ~ cannot end while the door is open (Door:1), Pn:D
        control(sock, "press", "door")
        # protocol.c protocol_exec_rt_system EXEC_SAFETY_DOOR: report.c MESSAGE_SAFETY_DOOR_AJAR
        assert read_lines(port, 1) == ["[MSG:Check Door]"]
        report = wait_state(port, "Door")
        assert report.startswith("<Door:1|") and "|Pn:D" in report
        port.write(b"~")
        assert wait_state(port, "Door:1")
        control(sock, "release", "door")
        assert wait_state(port, "Door:0") and "Pn:" not in status(port)
        port.write(b"~")
        assert wait_state(port, "Idle")
        # the probe touches during G38.2: [PRB:...:1] then ok; the move stops there
        port.write(b"G38.2Z-50F300\n")
        wait_state(port, "Run")
        control(sock, "press", "probe")
        lines = read_lines(port, 2)
        assert lines[0].startswith("[PRB:0.000,0.000,-") and lines[0].endswith(":1]"), lines
        assert lines[1] == "ok"
        z = float(lines[0].split(",")[2].split(":")[0])
        assert -50 < z < 0
        # a probe already touching when G38.2 starts: ALARM:4 (interface.md alarm codes)
        port.write(b"G38.2Z-60F300\n")
        assert read_lines(port, 2) == ["ALARM:4", "ok"]
        control(sock, "release", "probe")
        port.write(b"$X\n")
        assert read_lines(port, 2)[-1] == "ok"
        # a limit switch with hard limits on: ALARM:1 and reset to continue
        port.write(b"$21=1\n")
        assert read_lines(port, 1) == ["ok"]
        port.write(b"G1X-100F500\n")
        assert read_lines(port, 1) == ["ok"]
        control(sock, "press", "limit-x")
        assert read_lines(port, 2) == ["ALARM:1", "[MSG:Reset to continue]"]
        port.write(b"?")
        assert read_lines(port, 1, timeout=0.3) == []        # critical: no reports
        control(sock, "release", "limit-x")
        port.write(b"\x18")
        assert read_lines(port, 3) == ["", V.banner, "[MSG:'$H'|'$X' to unlock]"]
        state = send_control(sock, "state")
        assert '"state":"Alarm"' in state
        assert send_control(sock, "press nothing").startswith("error: unknown input")
    finally:
        port.close()
        stop(proc)


def test_faults_over_the_control_socket(tmp_path):
    sock, link = str(tmp_path / "emu.sock"), str(tmp_path / "grbl")
    proc, path = start("--control", sock, "--link", link)
    assert path == link
    port = serial.Serial(link, 115200, timeout=0.05)
    try:
        reset(port)
        control(sock, "fault", "lose", "1")
        port.write(b"G91\nG90\n")
        assert read_lines(port, 2, timeout=0.5) == ["ok"]     # one answer of two arrived
        control(sock, "fault", "garble", "1")
        port.write(b"G90\n")
        damaged = read_lines(port, 1)
        assert len(damaged) == 1 and damaged[0] != "ok"
        # the cable pulled for 0.5 s: the port dies, comes back, and the board has restarted
        port.write(b"G1X-5F100\n")
        assert read_lines(port, 1) == ["ok"]
        control(sock, "fault", "unplug", "0.5")
        dead = False
        end = time.monotonic() + 3
        while time.monotonic() < end and not dead:
            try:
                port.read(64)
            except serial.SerialException:
                dead = True
        assert dead, "the pty stayed open"
        port.close()
        end = time.monotonic() + 5
        while time.monotonic() < end:
            try:
                port = serial.Serial(link, 115200, timeout=0.05)
                break
            except (serial.SerialException, OSError, termios.error):
                time.sleep(0.05)
        assert os.path.islink(link)
        assert read_lines(port, 2, timeout=3) == ["", V.banner]   # the board restarted
        port.write(b"?")
        report = read_lines(port, 1)[0]
        assert report.startswith("<Idle|MPos:0.000,0.000,0.000"), report  # counts from zero
        assert send_control(sock, "fault nonsense 1").startswith("error:")
    finally:
        port.close()
        out = stop(proc)
    assert "Traceback" not in out


def test_control_cli_reports_errors(tmp_path):
    p = subprocess.run([sys.executable, "-m", "conform", "emulate", "control",
                        str(tmp_path / "none.sock"), "state"], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 2 and p.stderr.count("\n") == 1


def test_control_requests_never_raise():
    """Whatever a control client sends is answered with ok or error, never an exception (the
    emulator thread runs these)."""
    from conform.families.grbl.unit.control import GrblControl
    from conform.families.grbl.unit.faults import GrblFaults
    from conform.families.grbl.unit.model import GrblUnit

    unit = GrblUnit(V)
    control = GrblControl(GrblFaults())
    for line in ("fault lose inf", "fault lose nan", "fault garble -1", "fault unplug 0",
                 "fault unplug inf", "fault line latency=1e400", "fault line nonsense",
                 "press", "press limit-w", "release door extra", "", "state", "help",
                 "fault lose 3", "press door"):
        reply = control(unit, line, 0.0)
        assert reply.startswith(("ok", "error:")), (line, reply)
    assert control.faults.lose_next == 3 and unit.state == "Door"
