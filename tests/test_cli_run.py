"""``conform run`` against the emulator on a real pty, as a user runs it: what was not verified
(terminal and report), and a run whose link dies still writes its report, marked incomplete."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO), **extra}


@pytest.fixture
def emulator():
    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", "gve64-v19",
                            "--baud", "115200"], stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True, env=_env())
    try:
        pty = emu.stdout.readline().strip()
        assert pty.startswith("/dev/")
        yield emu, pty
    finally:
        emu.terminate()
        emu.wait(10)


def test_what_was_not_verified_is_said_and_how_to_include_it(emulator, tmp_path):
    _, pty = emulator
    run = subprocess.run([sys.executable, "-m", "conform", "run", "--target", pty, "--json",
                          "--no-machine", "--check", "*/L/position-1", "--check", "*/V/valid",
                          "--check", "*/EW/valid"],
                         capture_output=True, text=True, cwd=tmp_path, env=_env(), timeout=300)
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    grades = {c["id"].split("/", 2)[2]: c["grade"] for c in doc["checks"]}
    assert grades == {"L/position-1": "SKIPPED", "V/valid": "PASS", "EW/valid": "SKIPPED"}
    lines = run.stderr.splitlines()
    assert any(x.startswith("not verified: 1 check needs motion (axes, outputs, spindle) "
                            "(enable with --allow-motion --max-steps N") for x in lines), lines
    assert any(x.startswith("not verified: 1 check needs EEPROM writes (enable with ")
               and "--allow-eeprom" in x for x in lines), lines
    html = (tmp_path / "reports" / "latest" / "index.html").read_text()
    first = html[:html.index('id="failures"')]
    assert "1 check needs motion" in first and "--allow-eeprom" in first


def test_a_run_whose_link_dies_writes_an_incomplete_report(emulator, tmp_path):
    emu, pty = emulator
    run = subprocess.Popen([sys.executable, "-m", "conform", "run", "--target", pty,
                            "--no-machine"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, cwd=tmp_path, env=_env(CONFORM_PROGRESS_SECONDS="0.2"))
    seen = []  # the estimate may be announced first; wait for a progress line: checks are under way
    while not (seen and seen[-1].startswith("conform run: ")):
        line = run.stderr.readline()
        assert line, seen  # stderr ended with no progress line
        seen.append(line)
    emu.kill()
    out, err = run.communicate(timeout=300)
    assert run.returncode == 2, out + err
    assert "run aborted: link lost" in err
    report = tmp_path / "reports" / "latest"
    html = (report / "index.html").read_text()
    first = html[:html.index('id="failures"')]
    assert "INCOMPLETE" in first and "Incomplete run." in first and "link lost after" in first
    results = json.loads((report / "results.json").read_text())
    assert results["runs"][0]["aborted"].startswith("link lost")
    md = (report / "summary.md").read_text()
    assert md.startswith("# Conformance summary: INCOMPLETE")
