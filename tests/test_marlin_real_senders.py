"""Real senders nobody here wrote, against the Marlin reference unit: OctoPrint 1.11's serial
layer (MachineCom, driven headless by tests/senders/marlin_octoprint.py) through check-sender
and through `conform proxy` + `conform analyze`; and OctoPrint's own Marlin-like simulator
(the virtual_printer plugin, on a pty) held against Marlin's source by `conform run`.

OctoPrint's dependencies (Flask, tornado, rich < 14, click 8.2, ...) would downgrade this
project's environment, so it lives in its own interpreter: ``CONFORM_OCTOPRINT_PYTHON``
(default /work/venv-marlin-octo/bin/python, made with ``python -m venv`` and
``pip install "octoprint>=1.11,<1.12"``); without it these tests are skipped."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

SENDERS = Path(__file__).parent / "senders"
OCTO = os.environ.get("CONFORM_OCTOPRINT_PYTHON", "/work/venv-marlin-octo/bin/python")
needs_octoprint = pytest.mark.skipif(
    not Path(OCTO).exists() or subprocess.run([OCTO, "-c", "import octoprint.util.comm"],
                                              capture_output=True).returncode != 0,
    reason=f"no interpreter with OctoPrint 1.11 at {OCTO} (CONFORM_OCTOPRINT_PYTHON)")


def conform(*args, timeout=900):
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.slow
@needs_octoprint
@pytest.mark.long(77)
def test_octoprint_is_graded_as_its_source_behaves(tmp_path):
    p = conform("check-sender", "--variant", "marlin-2.1", "--report", str(tmp_path), "--json",
                "--scenario", "noisy", "--scenario", "lost-ok", "--scenario", "reset",
                "--timeout", "100", "--", OCTO, str(SENDERS / "marlin_octoprint.py"), "{port}",
                "{job}")
    assert p.returncode in (0, 1), p.stderr
    checks = {c["id"].split("/", 2)[2]: c for c in json.loads(p.stdout)["checks"]}
    assert checks["noisy/resend-exact"]["grade"] == "PASS"
    assert checks["noisy/none-twice"]["grade"] == "PASS"
    assert checks["noisy/none-skipped"]["grade"] == "PASS"
    # comm.py: "Communication timeout while printing" after serial.timeout.communication (30 s)
    # it asks M105 and goes on: the job completes (two lost oks: two 30 s waits), no line twice
    out = (tmp_path / "lost-ok" / "program.out").read_text()
    assert "Communication timeout while printing" in out
    assert checks["lost-ok/finishes"]["grade"] == "PASS"
    assert checks["lost-ok/none-skipped"]["grade"] == "PASS"
    # an unexpected `start` while printing: OctoPrint reports the firmware reset and stops
    assert checks["reset/stops-after-reset"]["grade"] == "PASS"
    assert checks["reset/none-twice"]["grade"] == "PASS"


@pytest.mark.slow
@needs_octoprint
def test_octoprint_through_the_proxy_then_analyze(tmp_path):
    serve = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", "marlin-2.1",
                              "--baud", "250000", "--faults", "host.corrupt=5e-4", "--seed", "2"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    unit = serve.stdout.readline().strip()
    try:
        proxy = subprocess.Popen([sys.executable, "-m", "conform", "proxy", "--unit", unit,
                                  "--baud", "250000", "-o", str(tmp_path / "s.mcap"),
                                  "--variant", "marlin-2.1", "--no-decode", "-q"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        host = proxy.stdout.readline().strip()
        job = tmp_path / "job.gcode"
        job.write_text("G90\n" + "".join(f"G1 X{i % 30}.{i % 10} Y{i % 7} F6000\n"
                                         for i in range(1, 200)))
        run = subprocess.run([OCTO, str(SENDERS / "marlin_octoprint.py"), host, str(job)],
                             capture_output=True, text=True, timeout=180,
                             env=dict(os.environ, CONFORM_BAUD="250000"))
        assert "print done" in run.stdout, run.stdout[-2000:]
        proxy.send_signal(signal.SIGINT)
        proxy.wait(30)
    finally:
        serve.send_signal(signal.SIGTERM)
        serve.wait(30)
    a = conform("analyze", str(tmp_path / "s.mcap"), "--report", str(tmp_path / "r"))
    assert a.returncode == 0, a.stderr
    assert "protocol family marlin" in a.stdout
    found = json.loads((tmp_path / "r" / "findings.json").read_text())
    m = found["metrics"]
    assert m["accepted"] >= 200 and m["twice_confirmed"] == 0 and m["never_confirmed"] == 0
    assert m["resends"] >= 1 and m["checksum_errors"] >= 1


@pytest.mark.slow
@needs_octoprint
def test_octoprint_virtual_printer_against_marlin_source(tmp_path):
    vp = subprocess.Popen([OCTO, str(SENDERS / "octoprint_virtual_pty.py")],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = vp.stdout.readline().strip()
        assert port.startswith("/dev/"), vp.stderr.read()
        time.sleep(1.0)
        p = conform("run", "--target", port, "--variant", "marlin-2.1", "--baud", "250000",
                    "--report", str(tmp_path), "-q", "--check", "*/checksum/*", "--check",
                    "*/line/*", "--check", "*/reply/unknown", timeout=300)
    finally:
        vp.send_signal(signal.SIGTERM)
        vp.wait(10)
    assert p.returncode == 1, p.stdout + p.stderr
    results = json.loads((tmp_path / "results.json").read_text())
    got = {c["id"].split("/", 2)[2]: c for c in results["checks"]}
    # where the simulator and Marlin 2.1.2.4's queue.cpp part (docs/marlin.md)
    assert got["line/repeat-silent"]["grade"] == "FAIL"        # it answers a repeat with an error
    assert "Resend:" in got["line/repeat-silent"]["actual"]
    assert got["checksum/without-number"]["grade"] == "FAIL"   # it checks *cs without N
    assert got["checksum/comment-before-star"]["grade"] == "FAIL"   # ';' does not cut the *cs
    assert got["line/skip-ahead"]["grade"] == "FAIL"           # its own error text, Resend:N
    assert "expected line 2 got 3" in got["line/skip-ahead"]["actual"]
