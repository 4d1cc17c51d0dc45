"""Checks from a non-default state (conformance/from_state.py): each row passes on the
reference unit, its command changes what it reads back (or, for an error, nothing), and it
is flagged by what its lines would do on a real unit."""

from __future__ import annotations

import pytest

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.checks import Session, generate, run_checks
from conform.families.grbl.conformance.from_state import ROWS, Row, needs
from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


def _answers(steps: tuple[bytes, ...]) -> list[list[str]]:
    target = EmuTarget(lambda: GrblUnit(V, G), "emu:grbl-1.1f")
    try:
        s = Session(target, G, V)
        s.fresh()
        return [s.talk(d, answers=d.count(b"\n"), status=0 if b"\n" in d else d.count(b"?"),
                       timeout=3.0).lines for d in steps]
    finally:
        target.close()


def test_every_row_passes_on_the_reference():
    target = EmuTarget(lambda: GrblUnit(V, G), "emu:grbl-1.1f")
    try:
        run = run_checks(target, "grbl-1.1f", spec=G, patterns=["*/from_state/*"])
    finally:
        target.close()
    assert len(run.checks) == len(ROWS)
    assert all(c.grade.name == "PASS" for c in run.checks), [
        (c.id, c.expected, c.actual) for c in run.checks if c.grade.name != "PASS"]


@pytest.mark.parametrize("row", ROWS, ids=lambda r: r.name)
def test_the_command_shows_in_what_is_read_back(row: Row):
    """With the command the reads differ from those without it; an inert row's command is
    answered with an error and the reads are the same."""
    with_it = _answers(row.steps)
    without = _answers((*row.setup, *row.reads))
    reads = len(row.reads)
    if row.inert:
        assert with_it[-reads:] == without[-reads:]
        assert all(x[-1].startswith("error:") for x in with_it[len(row.setup):-reads])
    else:
        assert with_it[-reads:] != without[-reads:]


def test_the_setup_is_off_the_defaults():
    (gc,) = [x for x in _answers(ROWS[0].setup + (b"$G\n",))[-1] if x.startswith("[GC:")]
    for word in ("G55", "G18", "G20", "G91", "S500"):
        assert word in gc


def test_flags_follow_what_the_lines_do():
    assert needs([b"G92X1\n", b"G43.1Z1\n", b"G20G91G55\n", b"\x91", b"$G\n", b"M2\n"]) == (
        False, False)
    assert needs([b"G10L2P1X1\n"]) == (False, True)
    assert needs([b"G28.1\n"]) == (False, True)
    assert needs([b"$N0=G20\n"]) == (False, True)
    assert needs([b"$RST=#\n"]) == (False, True)
    assert needs([b"$10=2\n"]) == (False, True)
    assert needs([b"G53G0X-3\n"]) == (True, False)
    assert needs([b"M3M8\n"]) == (True, False)
    checks = {c.id.rsplit("/", 1)[1]: c for c in generate(G, "grbl-1.1f")
              if "/from_state/" in c.id}
    default = {n for n, c in checks.items() if not c.motion and not c.eeprom}
    assert default == {"g92", "g92-one-axis", "g92.1", "g92.2", "g43.1", "g49", "g90.1",
                       "g91.1", "modal-words", "program-end-m2", "program-end-m30",
                       "soft-reset", "override-resets", "check-mode", "line-filter",
                       "safety-door", "safety-door-check-mode"}
    assert checks["g28.1"].motion and checks["g28.1"].eeprom


@pytest.mark.slow
@pytest.mark.long(103)
def test_over_a_pty_the_default_run_writes_nothing_and_the_opt_in_puts_back(tmp_path):
    """Against `conform emulate serve grbl-1.1f` standing off 0 with a G55 offset: a default
    run does the 17 rows that write nothing and skips the rest; with the opt-ins every row
    passes from where the machine stands, and the EEPROM a row wrote is put back."""
    import json
    import subprocess
    import sys
    import time

    import serial

    from tests import emulated

    def run(name, *opts):
        p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", path,
                            "--variant", "grbl-1.1f", "--check", "*/from_state/*", *opts,
                            "--report", str(tmp_path / name), "-q"],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
        doc = json.loads((tmp_path / name / "results.json").read_text())
        return {c["id"].rsplit("/", 1)[1]: c["grade"] for c in doc["checks"]}

    def eeprom(port):
        port.write(b"$N\n$#\n")
        time.sleep(0.5)
        return [x for x in port.read(4000).decode().split("\r\n") if x.startswith(("$N", "[G5"))]

    proc, path, _control = emulated.serve("serve", "grbl-1.1f", "--baud", "115200", "-q")
    try:
        with serial.Serial(path, 115200, timeout=0.2) as port:
            port.write(b"G91G0X-1.5Y-0.5\nG10L2P2X-2\n$N1=G20\n")
            said = [x.strip() for x in emulated.read_lines(port, 6)]
            assert said.count("ok") == 3, said
            time.sleep(1.0)
            before = eeprom(port)
        default = run("default")
        assert sorted(default.values()) == ["PASS"] * 17 + ["SKIPPED"] * (len(ROWS) - 17)
        opted = run("opt-in", "--allow-motion", "--max-steps", "100000", "--allow-eeprom")
        assert set(opted.values()) == {"PASS"}, opted
        with serial.Serial(path, 115200, timeout=0.2) as port:
            port.write(b"\x18")
            time.sleep(0.3)
            port.read(1000)
            assert eeprom(port) == before
    finally:
        emulated.stop(proc)


def test_a_reset_puts_the_parser_on_the_whole_steps_the_motors_made():
    """main.c after a reset: gc_sync_position. X0.0019 is 0.475 of a step at $100=250, so the
    motor made none: after the reset G92X0 sets the offset from X0, not from X0.0019."""
    *_, params = _answers((b"G1X0.0019F100\n", b"G4P0.2\n", b"\x18", b"G92X0\n", b"$#\n"))
    assert "[G92:0.000,0.000,0.000]" in params, params


def test_the_reference_adopts_the_position_in_whole_steps():
    """At 80 steps/mm a step is 0.0125 mm and the report's three decimals round it; the
    reference takes it back to the step (81 steps, not 1.013 mm)."""
    from conform.families.grbl.unit.adopt import UnitState, start_from

    unit = GrblUnit(V, G)
    start_from(unit, UnitState(position=[1.013, -0.988, 0.0],
                               settings={100: 80.0, 101: 80.0, 102: 250.0}))
    assert unit.parser_position() == [81 / 80, -79 / 80, 0.0]


def test_the_line_filter_and_the_door_byte_as_the_source_says():
    """protocol.c protocol_main_loop drops spaces, control characters, '/' and comments; the
    safety door byte says [MSG:Check Door] and holds in Door:0 (protocol_exec_rt_system),
    and is ignored in check mode."""
    ok, gc = _answers((b"G2 1\tG9/0(G91 T5)G\x0c54 ;G20\n", b"$G\n"))
    assert ok == ["ok"] and all(w in gc[0] for w in ("G21", "G90", "G54")), gc
    door, report = _answers((b"\x84", b"?"))
    assert door == ["[MSG:Check Door]"] and report[0].startswith("<Door:0|"), (door, report)
    _, quiet, in_check = _answers((b"$C\n", b"\x84", b"?"))
    assert quiet == [] and in_check[0].startswith("<Check|"), (quiet, in_check)
