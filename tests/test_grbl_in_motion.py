"""Checks of a move's course (conformance/in_motion.py): every course passes on the reference
unit, a unit that accelerates otherwise fails one, behind a link a moving report is compared
by its state and one at rest exactly, and each course is flagged by what its lines do."""

from __future__ import annotations

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.checks import run_checks
from conform.families.grbl.conformance.from_state import needs
from conform.families.grbl.conformance.in_motion import COURSES, _normalize, _sent, generate
from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


def _run(factory) -> dict[str, tuple[str, str, str]]:  # noqa: ANN001
    target = EmuTarget(factory, "emu:grbl-1.1f")
    try:
        run = run_checks(target, "grbl-1.1f", spec=G, patterns=["*/in_motion/*"])
    finally:
        target.close()
    assert len(run.checks) == len(COURSES)
    return {c.id.rsplit("/", 1)[-1]: (c.grade.name, c.expected, c.actual) for c in run.checks}


def test_every_course_passes_on_the_reference():
    got = _run(lambda: GrblUnit(V, G))
    assert all(g == "PASS" for g, _, _ in got.values()), got


def test_a_unit_with_another_acceleration_fails_the_line():
    """$120 doubled: the machine stands where a unit with the default would, but the reports
    on the way differ."""
    settings = {n: s.default for n, s in G.settings.items()} | {120: 20.0}
    got = _run(lambda: GrblUnit(V, G, settings=settings))
    grade, _, actual = got["line"]
    assert grade == "FAIL" and "<Run|" in actual


def test_a_link_compares_a_moving_report_by_its_state_and_one_at_rest_exactly():
    norm = _normalize(True)
    assert norm(["<Run|MPos:1.000,0.000,0.000|FS:300,0>"]) == ["<Run>"]
    assert norm(["<Hold:1|MPos:1.000,0.000,0.000|FS:30,0>"]) == ["<Hold:1>"]
    rest = ["<Idle|MPos:1.000,0.000,0.000|FS:0,0>", "<Hold:0|MPos:2.000,0.000,0.000|FS:0,0>",
            "<Alarm|MPos:3.000,0.000,0.000|FS:0,0>", "ok"]
    assert norm(rest) == rest
    assert _normalize(False)(["<Run|MPos:1.000,0.000,0.000|FS:300,0>"]) == [
        "<Run|MPos:1.000,0.000,0.000|FS:300,0>"]


def test_every_course_needs_the_motion_opt_in_and_a_write_the_eeprom_one():
    checks = {c.id.rsplit("/", 1)[-1]: c for c in generate(G, "grbl-1.1f")}
    for course in COURSES:
        check = checks[course.name]
        assert check.motion
        assert check.eeprom == needs(_sent(course))[1]
    assert checks["startup-line-error"].eeprom and not checks["line"].eeprom


def test_a_course_stopped_by_a_realtime_byte_compares_only_states_behind_a_link():
    """Where a cancelled jog or a hold comes to rest follows when the byte arrived, which a
    link's timing decides: behind a link such a course compares report states; at rest the
    other courses and every course in-process compare the report whole."""
    from conform.families.grbl.conformance.in_motion import COURSES, INTERRUPTED, _normalize

    names = {c.name for c in COURSES}
    assert INTERRUPTED <= names
    for c in COURSES:
        if c.name in INTERRUPTED:
            assert any(x in (b"!", b"\x85", b"\x18") for x in c.steps if isinstance(x, bytes)), c.name
    rest = ["<Idle|MPos:14.084,3.000,-1.000|FS:0,0>", "ok"]
    assert _normalize(True, True)(rest) == ["<Idle>", "ok"]
    assert _normalize(True, False)(rest) == rest
    assert _normalize(False, True)(rest) == rest
