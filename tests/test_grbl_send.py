"""`conform send` to grbl as a user runs it: over a real pty against `conform emulate serve
grbl-1.1f`, with both streaming methods, a job line grbl refuses, SIGTERM mid-job, and the
options that are not grbl's. Expected values come from the job text and grbl's tables (the
128-byte receive buffer, the 79-character line), never from the streamer itself."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial
from conftest import stop_emulator

from conform.families.grbl.spec.load import load_grbl

V = load_grbl().variant("grbl-1.1f")
STEP = 0.25


def job_file(tmp_path: Path, n: int, name: str = "job.nc", feed: int = 3000) -> Path:
    """``n`` moves of STEP mm along X (collinear, so the planner keeps the speed), with a
    comment, a ';' comment and a blank line the sender strips."""
    lines = ["(a row of short moves)", "G21 G90 ; mm, absolute", ""]
    lines += [f"G1 X{i * STEP:.3f} Y0 F{feed}" for i in range(1, n + 1)]
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def job_lines(path: Path) -> list[str]:
    """The job's lines as grbl reads them: no spaces or comments, blank lines left out."""
    out = []
    for raw in path.read_text().splitlines():
        block = re.sub(r"\s|\(.*?\)", "", raw.split(";")[0]).upper()
        if block:
            out.append(block)
    return out


def conform(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, timeout=kw.pop("timeout", 120), **kw)


def ask(path: str, query: bytes, until: bytes) -> str:
    """What the emulator answers to ``query`` on its pty (after the sender is done)."""
    with serial.Serial(path, 115200, timeout=0.1) as port:
        port.write(query)
        buf = b""
        end = time.monotonic() + 5
        while until not in buf and time.monotonic() < end:
            buf += port.read(4096)
    return buf.decode("latin-1")


@pytest.fixture
def grbl(emulate, tmp_path):
    """The emulator on a pty linked at tmp/g.pty, recording what reaches it, its control
    socket at tmp/c.sock."""
    link = tmp_path / "g.pty"
    proc, path = emulate("serve", "grbl-1.1f", "--baud", "115200", "--link", str(link),
                         "--record", str(tmp_path / "emu.mcap"), "--control",
                         str(tmp_path / "c.sock"))
    assert path == str(link)
    return proc, path


def control(tmp_path: Path, *words: str) -> str:
    """``conform emulate control`` on the emulator's socket: its answer."""
    p = conform("emulate", "control", str(tmp_path / "c.sock"), *words)
    assert p.returncode == 0, p.stderr
    return p.stdout.strip()


def control_now(tmp_path: Path, *words: str) -> str:
    """The same, from this process: at once, where a command's start-up on a loaded machine
    could outlast the job it is meant to interrupt."""
    from conform.emulator.control import send_control

    return send_control(str(tmp_path / "c.sock"), " ".join(words), timeout=30)


def truth(tmp_path: Path) -> dict:
    """The emulator's own state: lines answered, position, planner and receive buffer."""
    return json.loads(control(tmp_path, "state").removeprefix("ok "))


def started(cmd: list[str]) -> tuple[subprocess.Popen, str]:
    """``conform send`` running, once its first progress line is out."""
    proc = subprocess.Popen([sys.executable, "-m", "conform", "send", *cmd],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "CONFORM_PROGRESS_SECONDS": "0.2"})
    seen = ""
    while "job lines" not in seen:
        line = proc.stderr.readline()
        assert line, "no progress line"
        seen += line
    return proc, seen


def analysed(capture: Path) -> dict:
    p = conform("analyze", str(capture), "--json")
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)["metrics"]


@pytest.mark.slow
@pytest.mark.parametrize("method,detected", [("counting", "character-counting"),
                                             ("send-response", "send-response")])
def test_a_job_streams_completely(grbl, tmp_path, method, detected):
    _, pty = grbl
    job = job_file(tmp_path, 40)
    sent = job_lines(job)
    capture = tmp_path / "send.mcap"
    p = conform("send", str(job), "--target", pty, "--allow-motion", "--method", method,
                "--record", str(capture), "-q")
    assert p.returncode == 0, p.stderr
    assert f"sent {len(sent)} of {len(sent)} job lines" in p.stdout
    assert f"{len(sent)} ok, 0 errors" in p.stdout
    end_x = 40 * STEP
    assert f"final position: MPos:{end_x:.3f},0.000,0.000 (Idle)" in p.stdout
    # the unit itself agrees: where it stands and the modal state the job left
    status = ask(pty, b"?", b">")
    assert "<Idle|" in status and f"MPos:{end_x:.3f},0.000,0.000" in status, status
    modal = ask(pty, b"$G\n", b"ok")
    assert all(w in modal for w in ("G1", "G21", "G90", "F3000")), modal
    unit = truth(tmp_path)
    # the job's lines, the probe's $I (no --variant: the unit was asked what it is), the $G
    assert unit["lines_done"] == len(sent) + 2
    assert unit["position"][:3] == [end_x, 0.0, 0.0] and unit["lost"] == 0
    # the capture, as conform analyze reads it: every line answered ok, the method, the buffer
    m = analysed(capture)
    assert (m["lines"], m["ok"], m["errors"]) == (len(sent), len(sent), 0)
    assert m["streaming_method"] == detected
    assert m["max_bytes_in_flight"] <= V.rx_buffer
    if method == "counting":   # the buffer was used: more than one line waited at a time
        assert m["max_bytes_in_flight"] > V.rx_buffer - max(len(b) + 1 for b in sent)
    else:
        assert m["max_lines_in_flight"] == 1


def _wait_idle(pty: str, bound: float = 20.0) -> None:
    """Until the unit reports Idle (``?``, a realtime byte that only reads)."""
    end = time.monotonic() + bound
    with serial.Serial(pty, 115200, timeout=0.2) as port:
        while time.monotonic() < end:
            port.write(b"?")
            if b"<Idle|" in port.read(200):
                return
    raise AssertionError(f"{pty}: not Idle within {bound:g} s")


@pytest.mark.slow
def test_an_error_stops_with_one_line_naming_the_job_line(grbl, tmp_path):
    _, pty = grbl
    job = tmp_path / "err.nc"
    job.write_text("G21 G90\nG1 X1 F1000\nG5 X3\nG1 X4\nG1 X5\n")
    p = conform("send", str(job), "--target", pty, "--allow-motion", "--method",
                "send-response", "-q")
    assert p.returncode == 1, p.stderr
    assert p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert "err.nc:3 'G5 X3': error:20" in p.stderr, p.stderr
    assert "sent 3 of 5 job lines" in p.stdout   # nothing after the refused line
    _wait_idle(pty)   # G1 X1 may still run: a job starts from Idle (the sender refuses a Run)
    p = conform("send", str(job), "--target", pty, "--allow-motion", "-q")   # counting
    assert p.returncode == 1 and p.stderr.count("\n") == 1, p.stderr
    assert "err.nc:3 'G5 X3': error:20" in p.stderr
    assert "feed hold and soft reset" in p.stderr   # G1 X4, G1 X5 were in grbl's buffers


def test_sigterm_mid_job_halts_the_unit(grbl, tmp_path):
    proc, pty = grbl
    job = job_file(tmp_path, 200, feed=600)   # 50 mm at 10 mm/s: a while of motion
    send, _ = started([str(job), "--target", pty, "--allow-motion"])
    end = time.monotonic() + 30        # mid-job: once the unit has moved (no fixed sleep)
    while json.loads(control_now(tmp_path, "state").removeprefix("ok "))["position"][0] <= 0:
        assert time.monotonic() < end, "the unit never moved"
        time.sleep(0.05)
    send.send_signal(signal.SIGTERM)
    _, err = send.communicate(timeout=60)
    assert send.returncode == 143, err
    assert "interrupted (SIGTERM)" in err and "feed hold and soft reset" in err, err
    status = ask(pty, b"?", b">")
    x = float(re.search(r"MPos:([-\d.]+),", status).group(1))
    assert "<Idle|" in status and 0 < x < 200 * STEP, status   # stopped on the way, standing
    unit = truth(tmp_path)
    assert unit["state"] == "Idle" and unit["planner_free"] == V.planner_blocks
    stop_emulator(proc, signal.SIGTERM)
    from conform.capture.reader import open_capture

    host = open_capture(tmp_path / "emu.mcap").stream("host")
    last_job_line = host.rfind(b"F600\n")
    tail = host[last_job_line:]
    assert b"!" in tail and b"\x18" in tail[tail.index(b"!"):], tail   # hold, then reset


def test_an_alarm_stops_the_send(grbl, tmp_path):
    _, pty = grbl
    job = job_file(tmp_path, 200, feed=600)   # far longer than a loaded machine's delays
    job.write_text("$21=1\n" + job.read_text())   # hard limits on (the emulator's EEPROM)
    send, _ = started([str(job), "--target", pty, "--allow-motion"])
    assert control_now(tmp_path, "press", "limit-x").startswith("ok")
    _, err = send.communicate(timeout=60)
    assert send.returncode == 1, err
    last = err.strip().splitlines()[-1]   # after the progress lines, one line says why
    assert "Traceback" not in err and "ALARM:1 (hard limit) after" in last and "$X" in last, err


def test_a_pulled_cable_ends_the_send_in_bounded_time(grbl, tmp_path):
    _, pty = grbl
    send, _ = started([str(job_file(tmp_path, 200, feed=600)), "--target", pty,
                       "--allow-motion"])
    t = time.monotonic()
    assert control_now(tmp_path, "fault", "unplug", "3").startswith("ok")
    _, err = send.communicate(timeout=60)
    assert send.returncode == 1 and "Traceback" not in err, err
    assert "link lost" in err.strip().splitlines()[-1], err
    assert time.monotonic() - t < 15


def test_record_onto_an_existing_file_is_refused(grbl, tmp_path):
    _, pty = grbl
    job = job_file(tmp_path, 3)
    kept = tmp_path / "kept.mcap"
    kept.write_bytes(b"a recorded session")
    p = conform("send", str(job), "--target", pty, "--allow-motion", "--record", str(kept))
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "--force" in p.stderr, p.stderr
    assert kept.read_bytes() == b"a recorded session"
    p = conform("send", str(job), "--target", pty, "--allow-motion", "--record", str(kept),
                "--force", "-q")
    assert p.returncode == 0, p.stderr
    assert kept.read_bytes()[:5] == b"\x89MCAP"


@pytest.mark.parametrize("option", [["--checksums"], ["--packet", "20"], ["--policy", "blind"]])
def test_a_gve_option_to_a_grbl_unit_is_one_line(grbl, tmp_path, option):
    _, pty = grbl
    job = job_file(tmp_path, 3)
    p = conform("send", str(job), "--target", pty, "--allow-motion", *option)
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert f"{option[0]} is an option of gve units" in p.stderr and "grbl" in p.stderr


def test_what_grbl_cannot_take_is_refused_before_sending(tmp_path):
    long = tmp_path / "long.nc"
    long.write_text("G1 X1\nG1 " + "X1.000 " * 20 + "\n")
    assert len(job_lines(long)[1]) > V.line_max
    realtime = tmp_path / "rt.nc"
    realtime.write_text("G1 X1\nG1 X2 ! \n")
    for path, says in ((long, f"long.nc:2: {len(job_lines(long)[1])} characters"),
                       (realtime, "rt.nc:2: '!'")):
        p = conform("send", str(path), "--target", "emu:grbl-1.1f")
        assert p.returncode == 2 and p.stderr.count("\n") == 1 and says in p.stderr, p.stderr
    p = conform("send", str(job_file(tmp_path, 3)), "--target", "/dev/null-no-such-port",
                "--variant", "grbl-1.1f")
    assert p.returncode == 2 and "--allow-motion" in p.stderr, p.stderr


def test_the_emulator_in_process_records_on_its_virtual_clock(tmp_path):
    """`--target emu:grbl-1.1f`: the reference unit in-process; the recording reads as a
    counting session within the buffer, dated from the fixed virtual epoch."""
    from conform.capture.reader import open_capture

    job = job_file(tmp_path, 60)
    sent = job_lines(job)
    capture = tmp_path / "emu.mcap"
    p = conform("send", str(job), "--target", "emu:grbl-1.1f", "--record", str(capture))
    assert p.returncode == 0, p.stderr
    assert f"final position: MPos:{60 * STEP:.3f},0.000,0.000 (Idle)" in p.stdout
    m = analysed(capture)
    assert (m["lines"], m["ok"], m["streaming_method"]) == (len(sent), len(sent),
                                                            "character-counting")
    assert m["max_bytes_in_flight"] <= V.rx_buffer
    meta = open_capture(capture).metadata["conform.session"]
    assert meta["variant"] == "grbl-1.1f" and "virtual clock" in meta["capture_method"]
