"""Checks of when grbl answers (conformance/answer_timing.py): every case passes on the
reference unit; a unit that counts 11 bits a byte, one whose dwell ends at a status report, one
that holds a line without motion behind a full planner each fail the case meant for it; the
cases without motion or EEPROM writes run in a default run."""

from __future__ import annotations

from typing import Any

from conform.conformance.target import EmuTarget
from conform.families.grbl.conformance.answer_timing import CASES, generate
from conform.families.grbl.conformance.checks import run_checks
from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


def _run(factory: Any) -> dict[str, tuple[str, str, str]]:
    target = EmuTarget(factory, "emu:grbl-1.1f")
    try:
        run = run_checks(target, "grbl-1.1f", spec=G, patterns=["*/answer_timing/*"],
                         allow_motion=True, allow_eeprom=True)
    finally:
        target.close()
    assert len(run.checks) == len(CASES)
    return {c.id.rsplit("/", 1)[-1]: (c.grade.name, c.expected, c.actual) for c in run.checks}


def test_every_case_passes_on_the_reference():
    got = _run(lambda: GrblUnit(V, G))
    assert all(g == "PASS" for g, _, _ in got.values()), got


def test_a_unit_counting_eleven_bits_a_byte_fails_one_write():
    def slow_bytes() -> GrblUnit:
        u = GrblUnit(V, G)
        u.byte_time = 11.0 / V.baud
        return u
    got = _run(slow_bytes)
    assert got["one-write"][0] == "FAIL", got["one-write"]
    assert got["dwell"][0] == "PASS"


class _ShortDwell(GrblUnit):
    """Ends a dwell at whatever event comes first (a status report)."""

    def _step(self, t: float) -> None:
        if self._busy_until is not None and self._report_at is not None:
            self._busy_until = min(self._busy_until, self._report_at)
        super()._step(t)


class _PlannerHoldsEveryLine(GrblUnit):
    def _moves_needed(self, block: Any) -> int:
        return max(1, super()._moves_needed(block))


def test_a_dwell_ended_by_a_report_fails_the_dwell():
    got = _run(lambda: _ShortDwell(V, G))
    assert got["dwell"][0] == "FAIL", got["dwell"]


def test_a_line_without_motion_held_by_a_full_planner_fails():
    got = _run(lambda: _PlannerHoldsEveryLine(V, G))
    assert got["full-planner"][0] == "FAIL", got["full-planner"]


def test_flags_follow_what_the_lines_do():
    checks = {c.id.rsplit("/", 1)[-1]: c for c in generate(G, "grbl-1.1f")}
    for name in ("one-write", "dwell", "program-pause"):
        assert not checks[name].motion and not checks[name].eeprom
    assert checks["full-planner"].motion and not checks["full-planner"].eeprom
    assert checks["homing"].motion and checks["homing"].eeprom
