"""``conform diagnose``: captures where the cause of trouble is known because it was injected
(tests/diag_sessions.py drives the reference units with the fault) put that cause first; the
grbl overflow's lines as the unit parsed them match what the emulator's parser really took;
the resume point of a held job matches the emulator's planner."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from diag_sessions import (
    Faults,
    drive,
    grbl_job,
    grbl_sender,
    grbl_unit,
    gve_job,
    gve_sender,
    gve_unit,
    record,
)

from conform.analysis.stream import read_raw
from conform.diagnosis import diagnose
from conform.families.grbl.analysis.analyze import is_motion
from conform.families.grbl.diagnosis.facts import reception

REPO = Path(__file__).resolve().parents[1]
GRBL, GVE = "grbl-1.1f", "gve64-v19"


def first(path: Path) -> dict:
    """The diagnosis as JSON, with ``lead``: the stop cause, or the first hazard of a session
    that completed despite the fault."""
    d = diagnose(str(path))
    doc = d.to_json()
    assert doc["causes"] or doc["hazards"], d.headline()
    doc["lead"] = (doc["causes"] or doc["hazards"])[0]
    return doc


def test_sender_killed_mid_job(tmp_path):
    ses = drive(grbl_unit(), grbl_job(80), grbl_sender(poll=(0.2, b"?")),
                Faults(kill_after=40), tail=3.0)
    doc = first(record(tmp_path / "k.mcap", ses, GRBL))
    c = doc["lead"]
    assert c["kind"] == "sender-stopped" and c["confidence"] >= 0.85
    assert any("status polls" in e for e in c["evidence"])
    assert doc["headline"].startswith("Stopped by the sender: most likely sender-stopped")
    assert doc["outcome"]["kind"] == "stopped" and doc["outcome"]["by"] == "sender"
    # the resume point: everything acknowledged ran; go on with the next line of the job
    r = doc["resume"]
    assert r["last_acknowledged"] == r["last_executed"] == 39 and r["uncertain"] == []   # 40 sent
    assert r["resume_from"] == 40 and "F3000" in r["preamble"]


def test_sender_closing_its_port_is_named(tmp_path):
    """Killed between lines with every line answered and no report of the unit's state: the
    wire cannot tell it from a job without an end word, and says so: no stop is claimed, the
    closed port is named, the resume point offered in case."""
    ses = drive(gve_unit(), gve_job(30), gve_sender(), Faults(kill_after=20), tail=2.0)
    path = record(tmp_path / "c.mcap", ses, GVE, sender_closed=ses.host[-1][0] + 0.01)
    doc = diagnose(str(path)).to_json()
    assert doc["outcome"]["kind"] == "ended" and doc["causes"] == []
    assert "closing its port" in doc["headline"] and "cannot tell" in doc["headline"]
    assert doc["resume"] is not None


def test_unit_stops_answering(tmp_path):
    ses = drive(gve_unit(), gve_job(80), gve_sender(), Faults(mute_unit_at=0.08), tail=3.0)
    c = first(record(tmp_path / "s.mcap", ses, GVE))["lead"]
    assert c["kind"] == "unit-silent" and c["confidence"] >= 0.8
    assert "never came" in c["summary"]


@pytest.mark.parametrize("events", [True, False], ids=["link-events", "sniffed"])
def test_line_cut_for_two_seconds(tmp_path, events):
    ses = drive(gve_unit(), gve_job(300), gve_sender(timeout=0.3),
                Faults(cut=(0.1, 2.1), cut_events=events), tail=1.0)
    doc = first(record(tmp_path / "cut.mcap", ses, GVE))
    c = doc["lead"]
    assert c["kind"] == "link-lost"
    assert 1.9 < c["t_end"] - c["t_start"] < 2.3      # the two dead seconds
    assert c["confidence"] >= (0.9 if events else 0.7)


def overflow_session():
    """An unbounded sender (no counting, no waiting) against a fast-accelerating grbl: the
    128-byte ring overflows again and again, each answer letting a few bytes of whatever is
    on the wire in."""
    job = [b"G21G90G54F3000\n"] + [b"G1X%gY%g\n" % ((i % 10) * 0.5, (i % 7) * 0.25)
                                   for i in range(600)]
    unit = grbl_unit(settings={120: 2000.0, 121: 2000.0, 122: 2000.0})
    return drive(unit, job, grbl_sender(window=10**9), tail=1.0)


def test_overflow_is_first_and_the_parsed_lines_are_what_grbl_took(tmp_path):
    ses = overflow_session()
    path = record(tmp_path / "o.mcap", ses, GRBL)
    doc = first(path)
    assert doc["lead"]["kind"] == "buffer-overflow"
    parsed = reception(read_raw(str(path)))
    sent = [line.decode().strip() for line in ses.sent]
    truth = ses.unit_model.taken          # [line as the parser took it, its answer code]
    assert ses.unit_model.lost > 0
    # every line the emulator's parser took that no host line is, in order, is in the list
    odd = [text for text, _code in truth if text not in sent]
    assert odd and [p.parsed for p in parsed if p.fate in
                    ("damaged", "damaged-valid", "merged")] == odd
    # the damaged-but-valid ones: grbl answered ok (executed them), next to the host lines
    codes = {text: code for text, code in truth}
    valid = [p for p in parsed if p.fate == "damaged-valid"]
    assert valid and all(codes[p.parsed] == 0 for p in valid)
    for p in valid:
        assert p.sent == " | ".join(sent[i] for i in p.host) and p.parsed not in p.sent
    assert any(p.fate == "dropped" for p in parsed)
    rec = doc["reception"]
    assert any(x["fate"] == "damaged-valid" and x["sent"] != x["parsed"] for x in rec)
    # past the first lost byte nothing acknowledged is certain: resume before it
    first_hit = min(min(p.host) for p in parsed)
    r = doc["resume"]
    assert r["resume_from"] <= first_hit and r["last_executed"] < first_hit
    assert any("do not pair" in e for e in r["evidence"])


def test_noise_burst(tmp_path):
    ses = drive(gve_unit(), gve_job(200, checksums=True), gve_sender(),
                Faults(noise=(0.3, 0.6)), tail=0.5)
    c = first(record(tmp_path / "n.mcap", ses, GVE))["lead"]
    assert c["kind"] == "noise"
    assert any("damaged on the way" in e for e in c["evidence"])


def test_starved_planner(tmp_path):
    ses = drive(grbl_unit(), grbl_job(12), grbl_sender(gap=0.6, poll=(0.2, b"?")), tail=0.5)
    c = first(record(tmp_path / "st.mcap", ses, GRBL))["lead"]
    assert c["kind"] == "starvation" and "ran dry" in c["summary"]


def test_alarm(tmp_path):
    job = grbl_job(30)
    job.insert(12, b"G38.2Z-5F100\n")      # a probe that never touches: ALARM:5
    ses = drive(grbl_unit(), job, grbl_sender(poll=(0.2, b"?"),
                                              stop_on=lambda a: a.startswith(b"error")),
                tail=3.0)
    doc = first(record(tmp_path / "a.mcap", ses, GRBL))
    c = doc["lead"]
    assert c["kind"] == "unit-alarm" and "ALARM:5" in c["summary"]
    assert any("$X" in e for e in doc["resume"]["evidence"])


def test_feed_hold_deadlock_and_resume_against_the_planner(tmp_path):
    unit = grbl_unit()
    ses = drive(unit, grbl_job(80), grbl_sender(poll=(0.2, b"?")),
                Faults(realtime={0.6: b"!"}), tail=3.0, t_max=6.0)
    doc = first(record(tmp_path / "d.mcap", ses, GRBL))
    assert doc["lead"]["kind"] == "deadlock"
    # ground truth: the motion lines grbl acknowledged, less the blocks still in its planner
    truth = [text for text, code in unit.taken if code == 0]
    motion = [i for i, line in enumerate(ses.sent) if is_motion(line.decode())
              and line.decode().strip() in truth]
    done = len(motion) - len(unit.planner.blocks)
    r = doc["resume"]
    assert r["last_executed"] == motion[done - 1] and r["resume_from"] == motion[done]
    assert r["last_acknowledged"] == motion[-1]
    assert r["uncertain"] == list(range(motion[done], motion[-1] + 1))
    assert r["state"]["distance"] == "G90" and r["state"]["feed"] == 3000
    # the text names the uncertain lines as ranges, not one number per line
    from conform.diagnosis.render import text_lines
    line = next(x for x in text_lines(diagnose(str(tmp_path / "d.mcap"))) if x.startswith("resume:"))
    assert f"uncertain {motion[done] + 1}-{motion[-1] + 1}" in line, line


def test_misuse(tmp_path):
    ses = drive(gve_unit(), gve_job(100), gve_sender(window=40), tail=1.0)
    c = first(record(tmp_path / "m.mcap", ses, GVE))["lead"]
    assert c["kind"] == "protocol-misuse" and "before the answer" in c["summary"]


@pytest.mark.slow
def test_cli_json_and_first_screen(tmp_path):
    ses = drive(gve_unit(), gve_job(80), gve_sender(), Faults(mute_unit_at=0.08), tail=3.0)
    path = record(tmp_path / "s.mcap", ses, GVE)
    run = [sys.executable, "-m", "conform", "diagnose", str(path)]
    p = subprocess.run([*run, "--json"], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert [set(c) >= {"kind", "confidence", "t_start", "t_end", "evidence", "advice"}
            for c in doc["causes"]] == [True] * len(doc["causes"])
    assert doc["outcome"]["kind"] == "stalled" and doc["causes"][0]["kind"] == "unit-silent"
    score = [c["score"] for c in doc["causes"]]
    assert score[1:] == sorted(score[1:], reverse=True)     # the outcome's cause first
    p = subprocess.run(run, capture_output=True, text=True, timeout=120, cwd=REPO)
    head = p.stdout.splitlines()[0]
    assert head.startswith("Stalled: most likely unit-silent") and head.endswith(".")
    bad = tmp_path / "not.mcap"
    bad.write_bytes(b"hello")
    p = subprocess.run([sys.executable, "-m", "conform", "diagnose", str(bad)],
                       capture_output=True, text=True, timeout=60, cwd=REPO)
    assert p.returncode != 0 and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and str(bad) in p.stderr


def test_gve_line_changed_on_the_way_shows_in_the_echo(tmp_path):
    job = [b"!0V5000\r", b"!0A50\r", b"!0C400,200,0,0\r", b"!0>\r", b"!0C-400,200,0,0\r",
           b"!0>\r"]
    unit = gve_unit()
    # no checksums: a flipped bit turns 400 into 500, still a valid vector
    ses = drive(unit, job, gve_sender(), Faults(alter={4: b"!0C-500,200,0,0\r"}), tail=1.0)
    path = record(tmp_path / "e.mcap", ses, GVE)
    rec = diagnose(str(path)).to_json()["reception"]
    assert rec == [{"fate": "damaged-valid", "host": [4], "sent": "!0C-400,200,0,0",
                    "parsed": "!0C-500,200,0,0", "t": rec[0]["t"], "why": rec[0]["why"],
                    "echo": "!0C-500,200,0,0"}]
    # the unit did move by what it received: its position once the motion ended says so
    unit.receive(b"!0P4\r", 30.0)
    assert b"".join(d for _t, d in unit.poll(31.0)) == b"0,-100,400,0,0\r"


def test_gve_line_held_back_past_the_watchdog_is_truncated(tmp_path):
    job = [b"!0V5000\r", b"!0C400,200,0,0\r", b"!0C-400,200,0,0\r"]
    ses = drive(gve_unit(), job, gve_sender(), Faults(pause={1: 0.25}), tail=1.0)
    path = record(tmp_path / "w.mcap", ses, GVE)
    rec = diagnose(str(path)).to_json()["reception"]
    assert [(r["fate"], r["host"]) for r in rec] == [("truncated", [1])]
    assert "watchdog" in rec[0]["why"]
    assert b"2\r" in b"".join(d for _t, d in ses.unit)      # the unit did answer 2


def _between(p, a, b) -> bool:
    """``p`` on the straight segment from ``a`` to ``b`` (integer pulse counters)."""
    d = [y - x for x, y in zip(a, b, strict=True)]
    q = [y - x for x, y in zip(a, p, strict=True)]
    n2 = sum(x * x for x in d)
    k = sum(x * y for x, y in zip(q, d, strict=True)) / n2 if n2 else 0.0
    return 0.0 <= k <= 1.0 and all(abs(x - k * y) <= 1.0 for x, y in zip(q, d, strict=True))


def test_gve_resume_point_against_the_unit(tmp_path):
    """The sender dies with vectors queued; the capture ends while the unit still runs them.
    The unit's own position at that moment lies on the vector after the last one the
    diagnosis calls executed."""
    unit = gve_unit()
    job = gve_job(60, size=3000)
    ses = drive(unit, job, gve_sender(), Faults(kill_after=40), tail=3.0)
    t_end = ses.links[-1][0]
    # the process died: the proxy records its pty closing
    path = record(tmp_path / "r.mcap", ses, GVE, sender_closed=ses.host[-1][0] + 0.01)
    r = diagnose(str(path)).to_json()["resume"]
    unit.receive(b"!0P4\r", t_end)
    pos = [int(x) for x in b"".join(d for _t, d in unit.poll(t_end))[2:-1].split(b",")]
    vectors = [i for i, line in enumerate(ses.sent) if line.startswith(b"!0C")]
    steps = [[int(x) for x in ses.sent[i][3:-1].split(b",")] for i in vectors]
    ends = [[sum(s[k] for s in steps[:j + 1]) for k in range(4)] for j in range(len(steps))]
    assert r["last_acknowledged"] == vectors[-1] == 39
    j = vectors.index(r["last_executed"])
    assert 0 < j < len(vectors) - 1 and r["uncertain"] == vectors[j + 1:]
    assert _between(pos, ends[j], ends[j + 1]), (pos, ends[j], ends[j + 1])
    assert r["resume_from"] == vectors[j + 1]
    assert r["preamble"] == ["!0V5000", "!0A50", "!0P4"]
    assert r["state"]["position_counters"] == ends[j]


def test_bundle_round_trips_through_analyze(tmp_path):
    import socket
    import zipfile

    from click.testing import CliRunner

    from conform.capture.reader import open_capture
    from conform.cli.main import cli

    ses = drive(gve_unit(), gve_job(80), gve_sender(), Faults(mute_unit_at=0.08), tail=3.0)
    cap = record(tmp_path / "silent.mcap", ses, GVE)
    out = tmp_path / "support.zip"
    runner = CliRunner()
    res = runner.invoke(cli, ["bundle", str(cap), "-o", str(out), "--redact"])
    assert res.exit_code == 0, res.output
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        assert {"manifest.json", "captures/silent.mcap", "diagnosis/silent.json",
                "diagnosis/silent.txt", "analysis/silent/index.html",
                "analysis/silent/findings.json", "tables/silent/exchanges.parquet"} <= names
        manifest = json.loads(z.read("manifest.json"))
        texts = b"".join(z.read(n) for n in names if not n.endswith((".mcap", ".parquet")))
        (tmp_path / "x").mkdir()
        z.extract("captures/silent.mcap", tmp_path / "x")
    assert manifest["format"] == "conform-bundle/1" and manifest["redacted"] is True
    assert manifest["python"] == sys.version.split()[0] and manifest["conform_version"]
    assert manifest["captures"][0]["headline"].startswith("Stalled: most likely unit-silent")
    host = socket.gethostname().encode()
    assert host not in texts and str(tmp_path).encode() not in texts
    packed = open_capture(tmp_path / "x" / "captures" / "silent.mcap")
    assert packed.metadata["conform.session"]["hostname"] == "<host>"
    original = open_capture(cap)
    for d in ("host", "unit"):       # the traffic is as recorded
        assert packed.stream(d) == original.stream(d)
    res = runner.invoke(cli, ["analyze", str(out)])
    assert res.exit_code == 0, res.output
    assert "bundle of 1 capture(s)" in res.output and "Stalled: most likely unit-silent" in res.output
    assert "exchanges in" in res.output            # the capture analysed again
    # the output exists: not overwritten without --force; a zip that is no bundle is named
    res = runner.invoke(cli, ["bundle", str(cap), "-o", str(out)])
    assert res.exit_code != 0 and "exists" in str(res.exception or res.output)
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as z:
        z.writestr("manifest.json", "{\"format\": \"conform-bundle/1\"}")
    p = subprocess.run([sys.executable, "-m", "conform", "analyze", str(bad)],
                       capture_output=True, text=True, timeout=120, cwd=REPO)
    assert p.returncode == 2 and p.stderr.strip() == f"conform: {bad}: the bundle holds no capture"


@pytest.mark.slow
def test_hostile_captures_are_diagnosed_or_named_never_a_traceback(tmp_path):
    from hostile_captures import corpus

    from conform.errors import UserError

    crashed = []
    for path in corpus(tmp_path / "corpus", bomb_bytes=1 << 20, count=2):
        try:
            diagnose(str(path)).to_json()
        except UserError as exc:
            assert "\n" not in str(exc)
        except Exception as exc:  # noqa: BLE001 - what the test looks for
            crashed.append(f"{path.name}: {type(exc).__name__}: {exc}")
    assert not crashed, "\n".join(crashed)


@pytest.mark.slow
def test_live_view_runs_under_a_terminal(tmp_path):
    """``conform proxy --live`` with its stderr on a real pty (a terminal): the view draws
    the lines, the bytes in flight against grbl's buffer and the diagnosis so far while a
    sender streams through it to ``conform emulate``, and the capture is whole."""
    import fcntl
    import os
    import pty
    import select
    import signal
    import struct
    import termios
    import threading
    import time

    import serial

    env = dict(os.environ, PYTHONPATH=str(REPO), TERM="xterm-256color")
    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", GRBL],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=REPO)
    proxy = None
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    screen = bytearray()
    done = threading.Event()

    def read_screen() -> None:
        while not done.is_set():
            if select.select([master], [], [], 0.1)[0]:
                try:
                    screen.extend(os.read(master, 65536))
                except OSError:
                    return

    reader = threading.Thread(target=read_screen, daemon=True)
    reader.start()
    out = tmp_path / "live.mcap"
    try:
        emu_path = emu.stdout.readline().decode().strip()
        proxy = subprocess.Popen([sys.executable, "-m", "conform", "proxy", "--unit", emu_path,
                                  "-o", str(out), "--variant", GRBL, "--live"],
                                 stdout=subprocess.PIPE, stderr=slave, env=env, cwd=REPO)
        host_path = proxy.stdout.readline().decode().strip()
        assert host_path, "the proxy printed no pty"
        with serial.serial_for_url(host_path, 115200, timeout=0.05) as port:
            got = b""
            for i in range(30):
                port.write(b"G1X%dF3000\n" % (i % 5))
                deadline = time.monotonic() + 30     # a bound for a loaded machine, not a wait
                while got.count(b"ok") <= i and time.monotonic() < deadline:
                    got += port.read(64)
            port.write(b"?")
            import re

            deadline = time.monotonic() + 60
            text = ""
            while "30 sent, 30 answered" not in text and time.monotonic() < deadline:
                time.sleep(0.25)      # the view draws four times a second
                text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen.decode("utf-8", "replace"))
        assert got.count(b"ok") == 30
        last = text[text.rfind("recording"):]
        assert "30 sent, 30 answered" in last and "/ 128 bytes" in last, last
        assert "so far" in text and "family" in text and "grbl" in text
        proxy.send_signal(signal.SIGINT)
        assert proxy.wait(20) == 0
    finally:
        done.set()
        for p in (proxy, emu):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.wait(10)
        os.close(slave)
        os.close(master)
    assert diagnose(str(out)).facts.exchanges[-1].answer == "ok"


def test_analyze_says_the_diagnosis_first_and_its_report_opens_with_it(tmp_path):
    from click.testing import CliRunner

    from conform.cli.main import cli

    ses = drive(grbl_unit(), grbl_job(80), grbl_sender(poll=(0.2, b"?")),
                Faults(kill_after=40), tail=3.0)
    path = record(tmp_path / "k.mcap", ses, GRBL)
    res = CliRunner().invoke(cli, ["analyze", str(path), "--report", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[1].startswith("diagnosis: Stopped by the sender: most likely sender-stopped")   # after the family
    html = (tmp_path / "rep" / "index.html").read_text()
    top = html[:html.index("</section>")]
    assert "<h2>Diagnosis</h2>" in top and "<code>sender-stopped</code>" in top
    gve = drive(gve_unit(), gve_job(80), gve_sender(), Faults(mute_unit_at=0.08), tail=3.0)
    path = record(tmp_path / "s.mcap", gve, GVE)
    res = CliRunner().invoke(cli, ["analyze", str(path), "--report", str(tmp_path / "r2")])
    assert res.exit_code == 0, res.output
    assert res.output.startswith("diagnosis: Stalled: most likely unit-silent")
    assert "<code>unit-silent</code>" in (tmp_path / "r2" / "index.html").read_text()


def test_grbl_echo_shows_a_line_changed_on_the_way(tmp_path):
    """A build with [echo:] (protocol.c REPORT_ECHO_LINE_RECEIVED) says what it read: noise
    turned X10 into X18 on one line; nothing overflowed, so only the echo can tell."""
    host = [(0.0, b"G21G90F600\n"), (0.1, b"G1X10Y2\n"), (0.2, b"G1X12Y2\n")]
    unit = [(0.01, b"[echo:G21G90F600]\r\nok\r\n"), (0.11, b"[echo:G1X18Y2]\r\nok\r\n"),
            (0.21, b"[echo:G1X12Y2]\r\nok\r\n")]
    from diag_sessions import Session
    path = record(tmp_path / "echo.mcap", Session(host, unit, [(2.0, "close", "session", "")],
                                                  None, []), GRBL)
    rec = diagnose(str(path)).to_json()["reception"]
    assert [(r["fate"], r["host"], r["sent"], r["parsed"]) for r in rec] == [
        ("damaged-valid", [1], "G1X10Y2", "G1X18Y2")]


def test_grbl_line_cut_while_the_sender_polls(tmp_path):
    """A counting sender that polls: the lines sent while the line was dead are never
    answered, yet the unit answers the polls again afterwards: the link, not the unit."""
    ses = drive(grbl_unit(), grbl_job(80), grbl_sender(poll=(0.2, b"?")),
                Faults(cut=(1.0, 3.0), cut_events=False), tail=3.0, t_max=8.0)
    c = first(record(tmp_path / "cut.mcap", ses, GRBL))["lead"]
    assert c["kind"] == "link-lost" and "answered other traffic again" in c["summary"]
    assert any("status polls" in e and "got no report" in e for e in c["evidence"])


SENDER = r"""
import sys, time, serial
port = serial.serial_for_url(sys.argv[1], 115200, timeout=0.01)
# as a real sender connects: a soft reset, then the banner, before the first line (a line sent
# while the unit starts up is never answered, and a counting sender would wait for it for good)
port.write(b"\x18")
buf, t_end = b"", time.monotonic() + 20.0
while b"Grbl" not in buf:
    if time.monotonic() > t_end:
        sys.exit("no banner within 20 s")
    buf += port.read(256)
inflight, i, t_poll, buf = [], 0, 0.0, buf.split(b"Grbl", 1)[1].split(b"\n", 1)[-1]
while True:
    line = b"G1X%dY%dF3000\n" % (i % 10, i % 7)
    if sum(inflight) + len(line) <= 127:
        port.write(line)
        inflight.append(len(line))
        i += 1
        if i == 30:
            print("streaming", flush=True)
    if time.monotonic() - t_poll > 0.2:
        port.write(b"?")
        t_poll = time.monotonic()
    buf += port.read(256)
    while b"\n" in buf:
        got, buf = buf.split(b"\n", 1)
        if (got.strip() == b"ok" or got.startswith(b"error")) and inflight:
            inflight.pop(0)
"""


def _conform(*args: str, **kw) -> subprocess.Popen:
    import os

    return subprocess.Popen([sys.executable, "-m", "conform", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=REPO,
                            env=dict(os.environ, PYTHONPATH=str(REPO)), **kw)


@pytest.mark.slow
def test_sender_process_killed_through_the_proxy(tmp_path):
    """Over real ptys: a counting, polling sender streams through ``conform proxy`` to
    ``conform emulate grbl-1.1f`` and is killed mid-job (SIGKILL); the capture's diagnosis
    names the sender."""
    import signal
    import time

    out = tmp_path / "killed.mcap"
    emu = _conform("emulate", GRBL)
    proxy = sender = None
    try:
        emu_path = emu.stdout.readline().decode().strip()
        proxy = _conform("proxy", "-q", "--unit", emu_path, "-o", str(out), "--variant", GRBL)
        host_path = proxy.stdout.readline().decode().strip()
        sender = subprocess.Popen([sys.executable, "-c", SENDER, host_path], cwd=REPO,
                                  stdout=subprocess.PIPE)
        # killed mid-job, once 30 lines are out (however long a loaded machine takes to get
        # there), not after a fixed while
        import selectors

        with selectors.DefaultSelector() as sel:
            sel.register(sender.stdout, selectors.EVENT_READ)
            assert sel.select(60.0), "the sender sent no 30 lines within 60 s"
        assert sender.stdout.readline() == b"streaming\n"
        sender.send_signal(signal.SIGKILL)
        sender.wait(10)
        time.sleep(4.0)             # the unit runs out its planner; nobody sends
        proxy.send_signal(signal.SIGINT)
        assert proxy.wait(20) == 0, proxy.stderr.read().decode()
    finally:
        for p in (sender, proxy, emu):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.wait(10)
    doc = first(out)
    c = doc["lead"]
    assert c["kind"] == "sender-stopped" and c["confidence"] >= 0.9, (doc["outcome"], doc["causes"])
    assert doc["resume"]["last_executed"] == doc["resume"]["last_acknowledged"]


@pytest.mark.slow
def test_emulator_link_fault_is_named(tmp_path):
    """Over a real pty: ``conform emulate --faults disconnect=…,downtime=2`` drops the line
    under a simplex sender; the emulator's own recording names the lost link."""
    import signal
    import termios
    import time

    import serial

    rec = tmp_path / "emu.mcap"
    # reopened through the stable name (--link), as a sender that reconnects must: the pty's
    # own number goes to whichever pty is opened next while the line is down, on this machine
    # another test's emulator
    link = tmp_path / "unit"
    emu = _conform("emulate", GVE, "--faults", "disconnect=0.4,downtime=2", "--seed", "3",
                   "--record", str(rec), "--link", str(link))
    try:
        emu.stdout.readline()
        path = str(link)
        port = None   # opened in the loop: on a loaded machine the line may drop (0.4 s after
        # the emulator's start) before the first open, and the pty is away for the downtime
        t_end = time.monotonic() + 7.0
        i = 0
        while time.monotonic() < t_end:
            try:
                if port is None:
                    port = serial.serial_for_url(path, 115200, timeout=0.3)
                port.write(b"!0C%d,%d,0,0\r" % (40 if i % 2 else -40, 20))
                answer = port.read_until(b"\r")
            except (serial.SerialException, termios.error):   # the line is down: reopen, as
                # senders do (a line dropped while pyserial opens it fails its flush: termios)
                if port is not None:
                    port.close()
                    port = None
                time.sleep(0.2)
                continue
            if answer[:1] == b"0":
                i += 1
        if port is not None:
            port.close()
        emu.send_signal(signal.SIGINT)
        emu.wait(20)
    finally:
        if emu.poll() is None:
            emu.send_signal(signal.SIGTERM)
            emu.wait(10)
    doc = first(rec)
    c = doc["lead"]
    assert c["kind"] == "link-lost", doc["causes"]
    assert any("fault injection: link dropped" in e for e in c["evidence"])


def test_gve_sender_that_halted_the_unit_and_waits_for_room_is_a_deadlock(tmp_path):
    """The sender halts the unit (H, a pause button) and its streaming goes on: the vectors
    queue up behind the halt (answered 8: accepted, INTA) until the queue is full, then every
    try is refused as full (9) and the sender asks again, forever: the unit waits for G, the
    sender for room."""
    job = gve_job(600, size=3000)
    job.insert(60, b"!0H\r")
    ses = drive(gve_unit(), job, gve_sender(gap=0.005), tail=1.0, t_max=8.0)
    doc = first(record(tmp_path / "dl.mcap", ses, GVE))
    c = doc["lead"]
    assert c["kind"] == "deadlock" and "refused as full" in c["evidence"][0], doc["causes"]
