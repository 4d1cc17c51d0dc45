"""`conform run` for Marlin: every check passes on both reference variants, every deviant unit
is caught, and over a real pty the emulator answers N1 M105 and a damaged line with Resend: and
ok, `conform run` passes against it, and a real unit is left halted when a run is interrupted."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest
import serial

from conform.conformance.results import Grade
from conform.conformance.target import EmuTarget
from conform.families.marlin import FAMILY
from conform.families.marlin.conformance.checks import run_checks
from conform.families.marlin.conformance.mutants import MUTANTS
from conform.families.marlin.protocol.codec import frame
from tests import emulated
from tests.emulated import stop


@pytest.mark.parametrize("vid", ["marlin-2.1", "marlin-2.1-adv"])
def test_reference_units_pass_every_check(vid):
    run = run_checks(EmuTarget(lambda: FAMILY.make_unit(vid), f"emu:{vid}"), vid)
    bad = [(c.id, c.expected, c.actual, c.detail) for c in run.checks if c.grade is not Grade.PASS]
    assert not bad
    assert len(run.checks) >= 23


def test_every_mutant_is_caught():
    report = FAMILY.run_mutants(["marlin-2.1-adv"])   # what `conform run --mutants` runs
    assert {m["name"] for m in report} == set(MUTANTS)
    assert [m["name"] for m in report if not m["killed"]] == []
    by = {m["name"]: m["caught_by"] for m in report}
    assert any("repeat-silent" in c for c in by["runs-duplicate"])
    assert any("comment-before-star" in c for c in by["comment-keeps-checksum"])


def test_cli_run_and_mutant_target(tmp_path):
    p = subprocess.run([sys.executable, "-m", "conform", "run", "--target",
                        "emu:marlin-2.1:answers-duplicate", "--report", str(tmp_path), "-q"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 1 and "repeat-silent" in p.stdout
    listing = subprocess.run([sys.executable, "-m", "conform", "run", "--variant", "marlin-2.1",
                              "--list"], capture_output=True, text=True, timeout=60)
    assert listing.returncode == 0 and "marlin-2.1/queue.cpp/checksum/comment-before-star" in listing.stdout


def start(variant="marlin-2.1", *args):
    return emulated.serve("serve", variant, "--baud", "250000", *args)


def read_lines(port, n, timeout=3.0):
    return emulated.read_lines(port, n, timeout)


@pytest.mark.slow
def test_serve_answers_over_a_pty():
    proc, path, control = start()
    try:
        port = serial.Serial(path, 250000, timeout=0.05)
        read_lines(port, 20, timeout=0.3)                # whatever is left of the banner
        port.write(frame(1, "M105"))
        assert read_lines(port, 1)[0].startswith("ok T:")
        port.write(b"N2 M105*1\n")
        assert read_lines(port, 3) == ["Error:checksum mismatch, Last Line: 1", "Resend: 2", "ok"]
        from conform.emulator.control import send_control

        assert send_control(control, "reset").startswith("ok")
        assert read_lines(port, 3)[:2] == ["start", "echo:Marlin 2.1.2.4"]
        truth = json.loads(send_control(control, "truth")[3:])
        assert truth["executed"] == {"1": 1} and truth["resets"]
        port.close()
    finally:
        stop(proc)


@pytest.mark.slow
def test_conform_run_over_the_pty(tmp_path):
    proc, path, _ = start()
    try:
        p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", path, "--variant",
                            "marlin-2.1", "--baud", "250000", "--report", str(tmp_path), "-q",
                            "--check", "*/checksum/*", "--check", "*/line/*",
                            "--check", "*/reply/*", "--check", "*/halt/*"],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        results = json.loads((tmp_path / "results.json").read_text())
        grades = {c["id"].split("/", 2)[2]: c["grade"] for c in results["checks"]}
        assert grades["line/repeat-silent"] == "PASS"
        assert grades["halt/m112"] == "SKIPPED"          # a real unit: needs --allow-motion
    finally:
        stop(proc)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_ctrl_c_and_signals_halt_a_real_unit(tmp_path, sig):
    proc, path, control = start()
    try:
        run = subprocess.Popen([sys.executable, "-m", "conform", "run", "--target", path,
                                "--variant", "marlin-2.1", "--baud", "250000", "--report",
                                str(tmp_path), "-q", "--check", "*/keepalive/*"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        from conform.emulator.control import send_control

        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:                # wait until the 5 s dwell runs
            running = json.loads(send_control(control, "state")[3:])["running"] or ""
            if "G4" in running:
                break
            time.sleep(0.1)
        run.send_signal(sig)
        out, err = run.communicate(timeout=30)
        assert run.returncode == 128 + sig, out + err   # conform.stops: every signal alike
        assert "interrupted" in err and "M410" in err

        state = json.loads(send_control(control, "state")[3:])
        assert state["planner"] == 0 and not state["halted"]
    finally:
        stop(proc)


def test_the_emergency_parser_checks_fail_on_a_unit_without_it():
    """marlin-2.1-adv's checks against a plain marlin-2.1 unit: M108 cannot end M109's wait and
    M112 waits for the dwell, as queue.cpp reads nothing while a command blocks."""
    from conform.conformance.target import EmuTarget
    from conform.families import family

    target = EmuTarget(lambda: family("marlin").make_unit("marlin-2.1"), "emu:plain")
    run = run_checks(target, "marlin-2.1-adv", patterns=["*/halt/*"])
    grades = {c.id.split("/", 2)[2]: c.grade for c in run.checks}
    assert grades["halt/m108-breaks-m109"] is Grade.FAIL
    assert grades["halt/m112-while-busy"] is Grade.FAIL
    assert grades["halt/m112"] is Grade.PASS
