"""Marlin beyond the line protocol (conformance/depth.py, unit/settings.py): the reference
unit's reports are the real firmware's lines (shared/recordings/marlin-2.1.2.4, copied to
tests/data/marlin), every check passes on the reference units, a unit that keeps its state
between checks (as a real board) gets its settings back, the opt-ins hold, and every deviant
unit is caught by the check written for it."""

from __future__ import annotations

from pathlib import Path

import pytest

from conform.conformance.results import Grade
from conform.conformance.runner import RunOptions
from conform.conformance.target import EmuTarget
from conform.families import family
from conform.families.marlin.conformance.checks import MarlinRunner, generate
from conform.families.marlin.conformance.deviants import DEVIANTS
from conform.families.marlin.spec import load_marlin

RECORDED = Path(__file__).parent / "data" / "marlin" / "reports-2.1.2.4.transcript"
FAM = family("marlin")


def _exchanges(path: Path) -> list[tuple[str, list[str]]]:
    """(host line, the unit lines recorded after it, a CR the firmware printed kept) of a
    transcript, in order (the engine's reader: conform.emulator.judge)."""
    from conform.emulator.judge import read_transcript

    out: list[tuple[str, list[str]]] = []
    for e in read_transcript(path).events:
        text = e.data.decode("latin-1")
        if e.host:
            out.append((text.rstrip("\n"), []))
        elif out:
            out[-1][1].extend(x for x in text.split("\n") if x)
    return out


def _answers(unit, line: str, t: float) -> tuple[list[str], float]:
    unit.receive(line.encode() + b"\n", t)
    got: list[str] = []
    for _ in range(200):
        t += 0.05
        got += [b.decode().rstrip("\n") for _, b in unit.poll(t)]
        if got and got[-1].startswith("ok"):
            break
    return got, t


# the host lines whose answers this part of the model owns: the settings report and the
# settings, reports, tools, debug flags, messages, units, modes, unknown words
OWNED = ("M503", "M92 ", "M201 ", "M203 ", "M204 ", "M205 ", "M119", "M31", "T", "M111",
         "M117", "M118", "G21", "G20", "M149", "M82", "M83", "G90", "G91", "M9999", "G999",
         "X10")


def test_reports_are_the_recorded_firmware_lines():
    unit = FAM.make_unit("marlin-2.1")
    t = 1.0
    unit.poll(t)
    compared = 0
    for host, recorded in _exchanges(RECORDED):
        got, t = _answers(unit, host, t)
        if not host.startswith(OWNED):
            continue
        compared += 1
        # a text transcript cannot hold a CR (the recordings' README): compared without it
        assert [x.rstrip("\r") for x in got] == recorded, host
    assert compared >= 40


@pytest.mark.parametrize("vid", ["marlin-2.1", "marlin-2.1-adv"])
def test_depth_checks_pass_on_the_reference_and_full_adds_cases(vid):
    spec = load_marlin()
    quick, full = generate(spec, vid), generate(spec, vid, "full")
    assert len(quick) >= 150 and len(full) > len(quick) + 20
    assert len({c.id for c in full}) == len(full)
    assert all(c.clause and ".cpp" in c.clause for c in full)
    runner = MarlinRunner(EmuTarget(lambda: FAM.make_unit(vid), f"emu:{vid}"), vid, spec=spec,
                          options=RunOptions(profile="full"))
    run = runner.run(full)
    bad = [(c.id, c.expected, c.actual) for c in run.checks if c.grade is not Grade.PASS]
    assert bad == []


class _Board(EmuTarget):
    """The emulator taken as a real board: one unit for the whole run (no reset between
    checks), the runner's real-unit rules (M110 to begin, opt-ins)."""

    emulated = False

    def reset(self) -> None:   # a real board is not reset between checks
        return None


def _m503(unit) -> list[str]:
    got, _ = _answers(unit, "M503", unit.now + 0.01)
    return got


def test_a_board_gets_its_settings_back_and_the_opt_ins_hold():
    spec = load_marlin()
    target = _Board(lambda: FAM.make_unit("marlin-2.1"), "board")
    unit = target.unit
    _answers(unit, "M92 X100 Y101", 0.5)     # the board's own settings, not the defaults
    before = _m503(unit)
    checks = [c for c in generate(spec, "marlin-2.1") if "/halt/" not in c.id]
    run = MarlinRunner(target, "marlin-2.1", spec=spec, options=RunOptions()).run(checks)
    grades = {c.id: c.grade for c in run.checks}
    eeprom = [i for i in grades if "/eeprom/" in i]
    assert len(eeprom) >= 10 and all(grades[i] is Grade.SKIPPED for i in eeprom)
    moving = [c.id for c in checks if c.motion]
    assert moving and all(grades[i] is Grade.SKIPPED for i in moving)
    bad = [c.id for c in run.checks if c.grade not in (Grade.PASS, Grade.SKIPPED,
                                                       Grade.NOT_APPLICABLE)]
    assert bad == []
    assert _m503(unit) == before and "M92 X100.00 Y101.00" in " ".join(before)
    assert unit.eeprom == {}      # nothing stored without --allow-eeprom


def test_eeprom_checks_store_the_boards_settings_again():
    spec = load_marlin()
    target = _Board(lambda: FAM.make_unit("marlin-2.1"), "board")
    unit = target.unit
    _answers(unit, "M203 X250", 0.5)
    checks = [c for c in generate(spec, "marlin-2.1") if c.eeprom]
    run = MarlinRunner(target, "marlin-2.1", spec=spec, allow_eeprom=True,
                       options=RunOptions()).run(checks)
    assert {c.grade for c in run.checks} == {Grade.PASS}
    assert unit.eeprom["settings"]["M203"][0] == 250.0


# each deviant and the check written to catch it
INTENDED = {
    "m203-into-m201": "settings/m203-x", "m92-y-into-x": "settings/m92-y",
    "m201-resets-others": "settings/m201-x", "m204-s-retract": "settings/m204-s-legacy",
    "m205-j-unbounded": "settings/m205-j-out-of-range", "m92-e-no-scale":
    "settings/m92-e-below-20", "m206-silent": "settings/m206-x", "m301-into-m304":
    "settings/m301-p", "m220-sets-flow": "settings/m220-set", "m221-sets-feed":
    "settings/m221-set", "m503-no-headings": "report/m503-layout", "m503-m92-padded":
    "report/m503-layout", "m501-no-report": "eeprom/m501-restores", "m500-forgets-offset":
    "eeprom/m501-m206", "m502-writes-eeprom": "eeprom/m501-after-m502", "eight-tools":
    "tool/t7", "tool-off-by-one": "tool/t1", "m118-keeps-e1": "message/m118-e1",
    "m111-no-echo": "debug/m111-echo", "m75-resumes": "timer/m75-restarts", "m31-minutes":
    "report/m31", "m206-no-logical": "settings/m206-y", "m221-any-extruder":
    "settings/m221-t1", "g20-accepted": "reply/unknown-g20", "dwell-adds": "dwell/g4-s-wins",
    "extrudes-cold": "modes/m83-e-relative", "g91-leaves-e": "modes/g91-e-relative",
    "m220-no-speed": "motion/m220-speeds-up", "no-arcs": "motion/g2", "m104-sets-bed": "heat/m104-target",
    "m113-ignored": "keepalive/m113-interval", "m113-unbounded": "keepalive/m113-at-most-60",
    "m200-d-no-enable": "settings/m200-d", "m200-heading-kept": "settings/m200-d",
    "m211-ignores-s": "settings/m211-s0", "m211-native": "settings/m211-report",
    "m302-float": "settings/m302-report", "m302-p-ignored": "settings/m302-p1",
    "m303-echo": "heat/m303-bad-heater", "m575-silent": "reply/m575-implausible",
    "m85-m120-unknown": "reply/m85-s0", "m428-adds": "motion/m428-offsets",
    "m428-no-limit": "motion/m428-too-far", "m999-one-ok": "line/m999-resend",
}


@pytest.mark.slow
def test_every_deviant_is_caught_by_its_own_check(marlin_mutant_report):
    assert set(INTENDED) == set(DEVIANTS)
    assert len(FAM.mutants()) >= 30
    report = marlin_mutant_report      # the sweep of every deviant (conftest.py)
    by = {m["name"]: m["caught_by"] for m in report}
    assert [m["name"] for m in report if not m["killed"]] == []
    missed = {name: by[name][:3] for name, check in INTENDED.items()
              if not any(c.endswith(check) for c in by[name])}
    assert missed == {}
