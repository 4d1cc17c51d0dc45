"""Judging grbl senders: a careful character-counting sender passes; one that sends lines
outside its count overflows the receive buffer and fails; one that goes on after an alarm
fails that rule. Programs run on a real pty against the reference unit."""

from __future__ import annotations

import sys

import pytest

from conform.conformance.results import Grade
from conform.families.grbl.sendercheck import check_sender

SENDER = r"""
import os, sys, time, serial
careless = sys.argv[1] == "careless"
s = serial.Serial(os.environ["CONFORM_PORT"], 115200, timeout=0.02)
s.write(b"\x18")
buf, end = b"", time.monotonic() + 3
while b"for help]" not in buf and time.monotonic() < end:
    buf += s.read(256)
lines = [x.strip() + "\n" for x in open(os.environ["CONFORM_JOB"]) if x.strip()]
counted, buf, i, stop = [], b"", 0, False
last_poll = time.monotonic()
end = time.monotonic() + 25
while (i < len(lines) or counted) and time.monotonic() < end and not stop:
    if time.monotonic() - last_poll > 0.2:
        s.write(b"?")                   # realtime: alone, outside the count
        last_poll = time.monotonic()
    if i < len(lines) and sum(counted) + len(lines[i]) <= 127:
        if careless and i % 10 == 5:
            s.write(b"$G\n")            # a line the count forgets
        s.write(lines[i].encode()); counted.append(len(lines[i])); i += 1
        continue
    buf += s.read(256)
    while b"\n" in buf:
        line, _, buf = buf.partition(b"\n")
        line = line.strip()
        if line == b"ok" or line.startswith(b"error:"):
            if counted:
                counted.pop(0)
            if line.startswith(b"error:") and not careless:
                stop = True
        elif line.startswith(b"ALARM:") and not careless:
            stop = True
"""


def grades(run):
    return {c.id.split("/", 2)[2]: c.grade for c in run.checks}


@pytest.mark.slow
def test_a_careful_sender_passes(tmp_path):
    script = tmp_path / "sender.py"
    script.write_text(SENDER)
    run = check_sender([sys.executable, str(script), "careful"])
    g = grades(run)
    assert g["stream/terminates"] is Grade.PASS
    assert g["stream/within-buffer"] is Grade.PASS and g["stream/nothing-lost"] is Grade.PASS
    assert g["stream/realtime-out-of-band"] is Grade.PASS and g["stream/job-in-order"] is Grade.PASS
    assert g["error/error-recovery"] is Grade.PASS
    assert g["alarm/alarm-stops"] is Grade.PASS
    assert g["stream/error-recovery"] is Grade.NOT_APPLICABLE
    assert not any(c.grade is Grade.FAIL for c in run.checks)


def test_a_sender_that_overflows_the_buffer_fails(tmp_path):
    """Through the command a user types: conform check-sender --variant grbl-1.1f -- ..."""
    import json
    import subprocess

    script = tmp_path / "sender.py"
    script.write_text(SENDER)
    p = subprocess.run([sys.executable, "-m", "conform", "check-sender", "--variant", "grbl-1.1f",
                        "--scenario", "stream", "--scenario", "alarm", "--report",
                        str(tmp_path / "rep"), "--", sys.executable, str(script), "careless"],
                       capture_output=True, text=True, timeout=180)
    assert p.returncode == 1, p.stdout + p.stderr
    results = json.loads((tmp_path / "rep" / "results.json").read_text())
    g = {c["id"].split("/", 2)[2]: c["grade"] for c in results["checks"]}
    assert g["stream/within-buffer"] == "FAIL" and g["alarm/alarm-stops"] == "FAIL"
    failed = next(c for c in results["checks"] if c["id"].endswith("stream/within-buffer"))
    assert "bytes in flight" in failed["actual"] and failed["clause"]
    assert "FAIL" in p.stdout and "report:" in p.stdout


@pytest.mark.parametrize("sent,scenario,grade", [
    (["G90", "G1X-1F100", "G0X0"], "stream", "PASS"),
    (["G90", "$G", "G1 X-1 F100", "G0X0"], "stream", "PASS"),      # polls are not the job's
    (["G90", "G0X0"], "stream", "FAIL"),                             # a line skipped
    (["G90", "G1X-1F100", "G1X-1F100", "G0X0"], "stream", "FAIL"),   # a line sent twice
    (["G90"], "error", "PASS"),                                      # stopped early: a prefix
    (["G1X-1F100"], "error", "FAIL"),
])
def test_job_in_order_rule(sent, scenario, grade):
    from conform.families.grbl.analysis import Exchange, GrblAnalysis
    from conform.families.grbl.sendercheck import SCENARIOS, SenderRun, _in_order

    a = GrblAnalysis("", "grbl", "grbl-1.1f", "",
                     [Exchange(i, t, len(t) + 1, 0.0) for i, t in enumerate(sent)], [], {})
    run = SenderRun(SCENARIOS[scenario], ["G90", "G1X-1F100", "G0X0"], a, 0, 0, False, "")
    assert _in_order(run)[0] == grade
