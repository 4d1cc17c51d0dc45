"""'$' system lines, homing and planner courses (conformance/system_effects.py): every row and
course passes on the reference unit, a unit with one wrong effect fails the check meant for
it, each is flagged by what it may do, and the homing course is left out behind a link."""

from __future__ import annotations

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.checks import Session, run_checks
from conform.families.grbl.conformance.system_effects import (
    COURSES,
    EMULATED_ONLY,
    ROWS,
    generate,
)
from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


def _run(factory) -> dict[str, tuple[str, str, str]]:  # noqa: ANN001
    """Grade, expected and actual of each system_effects check, by its last id part."""
    target = EmuTarget(factory, "emu:grbl-1.1f")
    checks = run_checks(target, "grbl-1.1f", spec=G, patterns=["*/system_effects/*"]).checks
    target.close()
    assert {c.id.rsplit("/", 1)[-1] for c in checks} == {x.name for x in (*ROWS, *COURSES)}
    return {c.id.rsplit("/", 1)[-1]: (c.grade.name, c.expected, c.actual) for c in checks}


def test_every_row_and_course_passes_on_the_reference():
    got = _run(lambda: GrblUnit(V, G))
    assert all(g == "PASS" for g, _, _ in got.values()), got


def test_the_homing_course_times_the_cycle():
    """The ok of $H comes in the 0.1 s wait holding the cycle's end, 4.43 s after it (4 mm
    at $25 = 90 mm/min, twice 1 mm at $24 = 200, 1 mm at $25, twice $26 = 250 ms), and the
    machine then stands at -$27 on every axis."""
    course = next(c for c in COURSES if c.name == "homing-cycle")
    target = EmuTarget(lambda: GrblUnit(V, G), "emu:grbl-1.1f")
    try:
        s = Session(target, G, V)
        s.fresh()
        said: list[list[str]] = []
        for step in course.steps:
            if isinstance(step, float):
                said.append(s.wait(step))
            else:
                status = step.count(b"?") if b"\n" not in step else 0
                said.append(s.talk(step, answers=step.count(b"\n"), status=status).lines)
    finally:
        target.close()
    homing = course.steps.index(b"$H\r")
    assert said[homing - 1] == ["error:3"] and said[homing] == []
    oks = [i - homing for i, lines in enumerate(said) if i > homing and "ok" in lines]
    assert oks[:1] == [44], oks   # $H answered 0.05 s into its step: 4.45 s
    assert said[-2] == ["<Idle|MPos:-1.000,-1.000,-1.000|FS:0,0>"]


def test_a_unit_with_another_pull_off_fails_the_homing_course():
    settings = {n: s.default for n, s in G.settings.items()} | {27: 2.0}
    got = _run(lambda: GrblUnit(V, G, settings=settings))
    assert got["homing-cycle"][0] == "FAIL"


class _StoresAnyBuildInfo(GrblUnit):
    """Takes ``$I`` followed by anything as a store of what follows its second character."""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        if text.upper().startswith("$I") and text[2:3] not in ("", "="):
            text = "$I=" + text[3:]
        super()._process(text, overflow, t)


def test_a_unit_storing_a_malformed_build_info_line_fails_the_row():
    got = _run(lambda: _StoresAnyBuildInfo(V, G))
    grade, expected, actual = got["malformed-system-lines"]
    assert grade == "FAIL" and "error:3" in expected, (expected, actual)


def test_flags_rows_need_the_eeprom_opt_in_courses_the_motion_one():
    checks = {c.id.rsplit("/", 1)[-1]: c for c in generate(G, "grbl-1.1f")}
    assert checks["malformed-system-lines"].eeprom and not checks["malformed-system-lines"].motion
    assert all(checks[c.name].motion for c in COURSES)
    assert checks["homing-cycle"].eeprom and checks["rapid-after-rate-change"].eeprom
    assert not checks["collinear-short-blocks"].eeprom


def test_the_emulator_only_checks_are_not_applicable_behind_a_link():
    class Linked:
        emulated = False

    class S:
        target = Linked()

    checks = {c.id.rsplit("/", 1)[-1]: c for c in generate(G, "grbl-1.1f")}
    assert set(EMULATED_ONLY) == {"homing-cycle", "startup-line-beyond-table"}
    for name in EMULATED_ONLY:
        passed, _, actual = checks[name].run(S())   # type: ignore[arg-type]
        assert passed is None and actual.startswith("not applicable:"), name
