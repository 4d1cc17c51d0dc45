"""Marlin's serial-reader checks (conformance/reader.py): they pass on the reference units of
both variants, and a unit with the reader bug each is written for fails it (in-process, on
the virtual clock)."""

from __future__ import annotations

import dataclasses

import pytest

from conform.conformance.results import Grade
from conform.conformance.runner import RunOptions
from conform.conformance.target import EmuTarget
from conform.families.marlin.conformance import reader
from conform.families.marlin.conformance.checks import MarlinRunner
from conform.families.marlin.spec import load_marlin
from conform.families.marlin.unit.unit import MarlinUnit

VIDS = ["marlin-2.1", "marlin-2.1-adv"]


def _grades(vid: str, make, name: str = "*") -> dict[str, Grade]:
    spec = load_marlin()
    checks = [c for c in reader.generate(spec, vid, "full") if name == "*" or
              c.id.endswith("/" + name)]
    assert checks
    runner = MarlinRunner(EmuTarget(make, f"emu:{vid}"), vid, spec=spec,
                          options=RunOptions(profile="full"))
    return {c.id.rsplit("/", 1)[1]: c.grade for c in runner.run(checks).checks}


@pytest.mark.parametrize("vid", VIDS)
def test_reader_checks_pass_on_the_reference(vid):
    spec = load_marlin()
    grades = _grades(vid, lambda: MarlinUnit(spec.variant(vid), spec))
    assert len(grades) == 6
    assert set(grades.values()) == {Grade.PASS}


class _NoEscape(MarlinUnit):
    """A backslash is an ordinary character (no PS_ESC state)."""

    def _stream_char(self, c: int) -> None:
        if c == 0x5C and self.sis == 0:
            self.buf.append(c)
            return
        super()._stream_char(c)


class _M110Checked(MarlinUnit):
    """A numbered M110 gets the sequence check of any line (its own N, not the last one)."""

    def _line_done(self, line: bytes) -> bool:
        if line.startswith(b"N") and b" M110 " in line:
            n = int(line[1:line.index(b" ")])
            if n != self.last_n + 1:
                return self._line_error("Line Number is not Last Line Number+1", "line-number")
        return super()._line_done(line)


class _SpacedCritical(MarlinUnit):
    """The critical commands read with the spaces taken out (M11 2 taken for M112)."""

    def _line_done(self, line: bytes) -> bool:
        squeezed = line.replace(b" ", b"")
        if not self.v.on("EMERGENCY_PARSER") and squeezed[:4] == b"M112":
            self._kill(self.now)
            return True
        return super()._line_done(line)


def _variant_unit(vid: str, **changes):
    spec = load_marlin()
    v = spec.variant(vid)
    if "options" in changes:
        changes["options"] = {**v.options, **changes["options"]}
    return lambda: MarlinUnit(dataclasses.replace(v, **changes), spec)


@pytest.mark.parametrize(("make", "check"), [
    (lambda spec, v: _NoEscape(v, spec), "escaped-semicolon"),
    (lambda spec, v: _M110Checked(v, spec), "m110-then-next"),
    (lambda spec, v: _SpacedCritical(v, spec), "spaced-code-not-m112"),
])
def test_a_reader_bug_fails_its_check(make, check):
    spec = load_marlin()
    v = spec.variant("marlin-2.1")
    grades = _grades("marlin-2.1", lambda: make(spec, v), check)
    assert grades == {check: Grade.FAIL}


def test_a_deeper_queue_reads_the_damaged_line_during_the_dwell():
    # BUFSIZE 8 in the unit while the tables say 4: the fifth line is read (and refused)
    # while G4 still runs
    grades = _grades("marlin-2.1", _variant_unit("marlin-2.1", bufsize=8),
                     "queue-full-while-busy")
    assert grades == {"queue-full-while-busy": Grade.FAIL}


def test_a_receive_ring_that_drops_what_does_not_fit_loses_lines():
    # an AVR board's receive ISR (no RX_WAITS_OUTSIDE): the tail of a long write is lost
    grades = _grades("marlin-2.1", _variant_unit("marlin-2.1",
                                                 options={"RX_WAITS_OUTSIDE": False}),
                     "burst-over-ring")
    assert grades == {"burst-over-ring": Grade.FAIL}


class _PausedWhileHeating(MarlinUnit):
    """A heating wait's keepalive says M0's words (paused for user), not processing."""

    def _say(self, t: float, *lines: str) -> None:
        if self.wait is not None:
            lines = tuple("echo:busy: paused for user" if x == "echo:busy: processing" else x
                          for x in lines)
        super()._say(t, *lines)


def test_a_heating_wait_paused_for_user_fails_busy_while_heating():
    from conform.families.marlin.conformance.checks import generate

    spec = load_marlin()
    v = spec.variant("marlin-2.1")
    checks = [c for c in generate(spec, v.id, "full") if c.id.endswith("/busy-while-heating")]
    runner = MarlinRunner(EmuTarget(lambda: _PausedWhileHeating(v, spec), f"emu:{v.id}"), v.id,
                          spec=spec, options=RunOptions(profile="full"))
    [result] = runner.run(checks).checks
    assert result.grade is Grade.FAIL and "paused for user" in result.actual
