"""`conform run` for Marlin: every check passes on both reference variants, every deviant unit
is caught, and over a real pty the emulator answers N1 M105 and a damaged line with Resend: and
ok, `conform run` passes against it, and a real unit is left halted when a run is interrupted."""

from __future__ import annotations

import fnmatch
import json
import os
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


@pytest.mark.slow
@pytest.mark.long(190)
def test_every_mutant_is_caught(marlin_mutant_report):
    report = marlin_mutant_report     # what `conform run --mutants` runs (conftest.py)
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
        assert read_lines(port, 3)[:3] == ["x86_64 Initialized", "start", "PowerUp"]
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


def _run_over_a_pty(tmp_path, *opt_ins: str, least: int = 150, said: tuple[str, ...] = (
        "put back what M503, M220, M221 read before each check", "EEPROM checks end with M500",
        "motion checks home (G28)", "leave the unit halted until it is reset")
                    ) -> tuple[list[dict], str]:
    """`conform run` against `conform emulate serve marlin-2.1` on a pty at 1 000 000 Bd
    (M575's fastest rate; the runner treats the pty as a real board): its checks (none FAIL or
    ERROR, at least ``least``) and its summary, which says each of ``said``."""
    proc, path, _ = emulated.serve("serve", "marlin-2.1", "--baud", "1000000")
    try:
        p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", path, "--variant",
                            "marlin-2.1", "--baud", "1000000", "--report", str(tmp_path), "-q",
                            *opt_ins], capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stdout + p.stderr
    finally:
        stop(proc)
    checks = json.loads((tmp_path / "results.json").read_text())["checks"]
    assert len(checks) >= least
    assert [(c["id"], c["actual"]) for c in checks if c["grade"] in ("FAIL", "ERROR")] == []
    summary = (tmp_path / "summary.md").read_text()
    for sentence in said:
        assert sentence in summary, sentence
    return checks, summary


@pytest.mark.slow
@pytest.mark.long(87)
def test_the_default_run_over_a_pty_skips_only_what_needs_an_opt_in(tmp_path, monkeypatch):
    """Without opt-ins every check that moves, halts, writes the EEPROM or heats is SKIPPED
    and says which opt-in it needs; the rest PASS (about 80 s of checks)."""
    monkeypatch.delenv("CONFORM_MARLIN_ALLOW_HEATERS", raising=False)
    checks, summary = _run_over_a_pty(tmp_path)
    skipped = [c for c in checks if c["grade"] == "SKIPPED"]
    needs = ("needs --allow-motion", "needs --allow-eeprom", "needs CONFORM_MARLIN_ALLOW_HEATERS=1")
    assert skipped and all(any(n in c["detail"] for n in needs) for c in skipped)
    assert all(any(n in c["detail"] for c in skipped) for n in needs)
    # besides the banner (a reset, DTR): the checks only an emulator answers in-process (M575
    # on the port in use, M31 past an hour, M501/M504 once the EEPROM holds settings) say so
    rest = [c for c in checks if c["grade"] not in ("PASS", "SKIPPED")]
    assert 1 <= len(rest) <= 4 and all(c["grade"] == "NOT-APPLICABLE" or "/banner" in c["id"]
                                       for c in rest), [(c["id"], c["grade"]) for c in rest]
    assert "checks that move or halt the unit SKIPPED (no --allow-motion)" in summary


OPT_IN = ("--allow-motion", "--max-steps", "100000", "--allow-eeprom")
# The opt-in run's checks in parts that run side by side, each against its own emulator: the
# heater checks wait on the emulated heater's real clock (330 s of the whole run's 560 s, the
# M109 R slope alone 127 s). A check goes to the first part one of whose patterns it matches;
# every other check, the halt checks with them, to "rest".
OPT_IN_PARTS = {
    "heat-slope": ("*/heat/m109-r-slope-checks",),
    "heat-cooling": ("*/heat/m1?0-r-cool*",),
    "heat": ("*/heat/*", "*/keepalive/busy-while-heating"),
    "motion": ("*/G0_G1.cpp/*", "*/G28.cpp/*", "*/M206_M428.cpp/*", "*/M92.cpp/*",
               "*/M200-M205.cpp/*"),
}


def _opt_in_parts() -> dict[str, list[str]]:
    """Every check of the opt-in run (as `conform run --list` plans it), by part."""
    out = subprocess.run([sys.executable, "-m", "conform", "run", "--target", "emu:marlin-2.1",
                          "--variant", "marlin-2.1", *OPT_IN, "--list"], capture_output=True,
                         text=True, timeout=120, env=os.environ | {"CONFORM_MARLIN_ALLOW_HEATERS": "1"})
    assert out.returncode == 0, out.stderr
    parts: dict[str, list[str]] = {name: [] for name in [*OPT_IN_PARTS, "rest"]}
    for cid in (line.split("\t", 1)[0] for line in out.stdout.splitlines() if line.strip()):
        part = next((name for name, globs in OPT_IN_PARTS.items()
                     if any(fnmatch.fnmatchcase(cid, g) for g in globs)), "rest")
        parts[part].append(cid)
    return parts


@pytest.mark.slow
@pytest.mark.parametrize("part", [*OPT_IN_PARTS, "rest"])
@pytest.mark.long(135)
def test_the_opt_in_run_over_a_pty_passes_every_check(tmp_path, monkeypatch, part):
    """Every opt-in (--allow-motion, --allow-eeprom, the heaters), in parts (OPT_IN_PARTS)
    that together hold every check once: nothing FAILs or ERRORs; of the three halt checks
    only the last runs (the others SKIPPED naming it) and the unit is left halted; the report
    says what the run changed on the unit. Most of the wall time is the unit's own: the first
    G28 (16 s on this build), M109/M190's 10 s residency and the heater's slopes, dwells and
    moves timed on the real clock, and 0.1 s after each checked answer for a late line."""
    monkeypatch.setenv("CONFORM_MARLIN_ALLOW_HEATERS", "1")
    parts = _opt_in_parts()
    assert sum(map(len, parts.values())) >= 150 and all(parts.values()), \
        {name: len(ids) for name, ids in parts.items()}   # no part left empty by a rename
    ids = parts[part]
    selected = [a for cid in ids for a in ("--check", cid)]
    if part != "rest":
        checks, summary = _run_over_a_pty(tmp_path, *OPT_IN, *selected, least=len(ids),
                                          said=("checks that heat run",) * part.startswith("heat"))
        assert sorted(c["id"] for c in checks) == sorted(ids)
        assert [(c["id"], c["grade"]) for c in checks if c["grade"] != "PASS"] == []
        return
    checks, summary = _run_over_a_pty(tmp_path, *OPT_IN, *selected, least=len(ids))
    assert sorted(c["id"] for c in checks) == sorted(ids)
    skipped = [c for c in checks if c["grade"] == "SKIPPED"]
    assert {c["id"].rsplit("/", 1)[-1] for c in skipped} == {"m112", "m112-while-busy"}
    assert all(checks[-1]["id"] in c["detail"] for c in skipped)
    rest = [c for c in checks if c["grade"] not in ("PASS", "SKIPPED")]   # as in the default run
    assert 1 <= len(rest) <= 4 and all(c["grade"] == "NOT-APPLICABLE" or "/banner" in c["id"]
                                       for c in rest), [(c["id"], c["grade"]) for c in rest]
    assert "left halted" in checks[-1]["detail"]
    assert "checks that heat run (CONFORM_MARLIN_ALLOW_HEATERS=1)" in summary


@pytest.mark.slow
def test_a_real_unit_is_halted_once_by_the_last_halt_check(tmp_path):
    """Over a pty (not emulated for the runner) with --allow-motion: of the three checks that
    leave the unit halted only the last planned one runs, after every other check, and says
    the unit is left halted; the other two are SKIPPED naming it; nothing ERRORs."""
    proc, path, _ = start()
    try:
        p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", path, "--variant",
                            "marlin-2.1", "--baud", "250000", "--report", str(tmp_path), "-q",
                            "--allow-motion", "--check", "*/halt/*", "--check", "*/reply/*"],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        checks = json.loads((tmp_path / "results.json").read_text())["checks"]
        grades = [c["grade"] for c in checks]
        assert "ERROR" not in grades and "FAIL" not in grades
        kills = [c for c in checks if "/halt/m112" in c["id"]]
        ran = [c for c in kills if c["grade"] == "PASS"]
        assert len(kills) == 3 and len(ran) == 1 and checks[-1] is ran[0]
        assert "left halted" in ran[0]["detail"]
        assert all(ran[0]["id"] in c["detail"] for c in kills if c is not ran[0])
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
    """marlin-2.1-adv's checks against a plain marlin-2.1 unit: a NUMBERED M108 cannot end
    M109's wait and a numbered M112 waits for the dwell (queue.cpp's critical commands look
    at the line's first letters); unnumbered, both act at once on either unit, as the real
    firmware does (recordings/marlin-2.1.2.4/blocking-reads.transcript)."""
    from conform.conformance.target import EmuTarget
    from conform.families import family

    target = EmuTarget(lambda: family("marlin").make_unit("marlin-2.1"), "emu:plain")
    run = run_checks(target, "marlin-2.1-adv", patterns=["*/halt/*"])
    grades = {c.id.split("/", 2)[2]: c.grade for c in run.checks}
    assert grades["halt/m108-breaks-m109"] is Grade.FAIL
    assert grades["halt/m112-numbered-while-busy"] is Grade.FAIL
    assert grades["halt/m112-while-busy"] is Grade.PASS
    assert grades["halt/m112"] is Grade.PASS


def test_the_halt_counts_only_answers_to_its_own_lines():
    """SIGTERM's halt behind a line still in flight: that line's ok is not taken for one of
    the halt's; it is stopped only once the answer to the mark behind its four lines came
    (so after five oks here), and a dead unit is not called stopped."""
    from conform.conformance.target import EmuTarget
    from conform.families import family
    from conform.families.marlin.conformance.checks import HALT_MARK, halt

    target = EmuTarget(lambda: family("marlin").make_unit("marlin-2.1"), "emu:m")
    target.reset()
    target.begin_log()
    target.send(b"G4 P300\n")                      # in flight when the halt begins
    assert halt(target).startswith("stopped")
    rx = b"".join(e.data for e in target.log if e.dir == "rx")
    mark = rx.index(b'echo:Unknown command: "' + HALT_MARK)
    assert rx[:mark].count(b"ok\n") == 5 and rx[mark:].count(b"ok\n") == 1

    dead = EmuTarget(lambda: family("marlin").make_unit("marlin-2.1"), "emu:dead")
    dead.reset()
    dead.send(b"G4 P300\n")
    dead.send(b"M112\n")
    assert halt(dead, attempts=1).startswith("stop NOT acknowledged")


def test_heating_checks_wait_for_a_sane_temperature():
    """Right after a reset the firmware reads T:0.00 for a while (recorded on the native
    build): the heating check asks M105 again until the reading is sane and only then heats;
    a sensor that never reads sane gets no M109 at all."""
    from conform.conformance.target import EmuTarget
    from conform.families import family
    from conform.families.marlin.conformance.checks import run_checks
    from conform.families.marlin.unit.unit import MarlinUnit

    spec = family("marlin").load_tables()

    class ColdSensor(MarlinUnit):
        until = 2.0

        def _temps_line(self) -> str:
            line = super()._temps_line()
            return line.replace("T:25.00", "T:0.00") if self.now < self.until else line

    def grade(until):
        ColdSensor.until = until
        target = EmuTarget(lambda: ColdSensor(spec.variant("marlin-2.1"), spec), "emu:cold")
        run = run_checks(target, "marlin-2.1", patterns=["*/heat/m109-residency"])
        sent = b"".join(e.data for c in run.checks for e in c.log if e.dir == "tx")
        return run.checks[0], sent

    check, sent = grade(2.0)
    assert check.grade is Grade.PASS and sent.count(b"M105") >= 3
    assert sent.index(b"M109") > sent.rindex(b"M105\n", 0, sent.index(b"M109"))
    check, sent = grade(1e9)
    assert check.grade is Grade.FAIL and "no sane temperature" in check.actual
    assert b"M109" not in sent
