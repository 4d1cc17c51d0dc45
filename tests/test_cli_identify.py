"""``conform run`` without --variant identifies the unit by ``?``: what a previous session left
behind (checksums switched on, a line half-sent, answers in flight) must not make it guess."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import serial

from conform.families.gve.conformance.target import identify, open_target
from conform.families.gve.spec import load_spec

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("left", [b"!0%+\r", b"!0%+\r!0V1"],
                         ids=["checksums-on", "and-half-a-line"])
def test_identify_sees_through_what_a_previous_session_left(left):
    spec = load_spec()
    target, _ = open_target("emu:gve124", spec)
    target.send(left)            # the previous session, which this host knows nothing of
    target.wait(0.2)
    target.checksum_on = False   # a new run believes the power-up state
    vid, how = identify(target, spec)
    assert vid == "gve124", how
    assert how == "firmware 'IP124 v7/50 2.4.2018' is gve124"


@pytest.mark.slow
def test_run_identifies_a_unit_left_with_checksums_on(tmp_path, emulate):
    _, pty = emulate("serve", "gve124", "--baud", "115200")
    with serial.Serial(pty, 115200, timeout=0.5) as port:   # a session that ended badly
        port.write(b"!0%+\r")
        assert port.read_until(b"\r") == b"0,5C\r"
    run = subprocess.run([sys.executable, "-m", "conform", "run", "--target", pty, "--check",
                          "*/V/valid", "--no-machine", "--json", "-q"], capture_output=True,
                         text=True, cwd=tmp_path, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    # the harmless probe (ports --probe's) names the unit although it answers with checksums
    assert doc["runs"][0]["variant"] == "gve124"
    assert doc["runs"][0]["counts"]["PASS"] == 1


@pytest.mark.slow
def test_run_without_variant_on_a_grbl_port_says_it_is_grbl(tmp_path, emulate):
    _, pty = emulate("serve", "grbl-1.1f", "--baud", "115200")
    run = subprocess.run([sys.executable, "-m", "conform", "run", "--target", pty, "--check",
                          "*/example/status-after-reset"],
                         capture_output=True, text=True, cwd=tmp_path, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    # asked ports --probe's harmless questions, the grbl answers and its family runs
    assert run.returncode == 0, run.stderr
    assert f"{pty}: grbl-1.1f answered" in run.stderr and "link lost" not in run.stderr
    assert f"{pty} (grbl-1.1f, quick): PASS 1" in run.stdout, run.stdout
