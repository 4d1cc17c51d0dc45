"""Marlin checks at the edges (conformance/edges.py): each passes on the reference units of
both variants, and a unit with the wrong number at its edge fails the check meant for it."""

from __future__ import annotations

import math

import pytest

from conform.conformance.results import Grade
from conform.conformance.runner import RunOptions
from conform.conformance.target import EmuTarget
from conform.families.marlin.conformance import edges
from conform.families.marlin.conformance.checks import MarlinRunner
from conform.families.marlin.spec import load_marlin
from conform.families.marlin.unit import unit as um
from conform.families.marlin.unit.settings import Settings
from conform.families.marlin.unit.unit import MarlinUnit


def _run(vid: str, make, pattern: str = "") -> dict[str, tuple[Grade, str]]:
    spec = load_marlin()
    checks = [c for c in edges.generate(spec, vid, "full") if pattern in c.id]
    assert checks
    runner = MarlinRunner(EmuTarget(make, f"emu:{vid}"), vid, spec=spec,
                          options=RunOptions(profile="full"))
    return {c.id: (c.grade, c.actual) for c in runner.run(checks).checks}


@pytest.mark.parametrize("vid", ["marlin-2.1", "marlin-2.1-adv"])
def test_edge_checks_pass_on_the_reference(vid):
    spec = load_marlin()
    got = _run(vid, lambda: MarlinUnit(spec.variant(vid), spec, t0=0.0))
    assert len(got) >= 13
    assert {i: g for i, g in got.items() if g[0] is not Grade.PASS} == {}


class _ResetOnValidate(Settings):
    def m504(self, w, text, t, eeprom):
        return self.load(eeprom)          # M504 taken as M501: loads the defaults


class _M504Loads(MarlinUnit):
    settings_class = _ResetOnValidate


class _EarlyResidency(MarlinUnit):
    """The residency timer started up to a second early (whole seconds to the window)."""

    def _plan_wait(self, h, t):
        w = super()._plan_wait(h, t)
        if w.set_at > t and w.set_at != math.inf and self.heat[h][1] > self.temp(h, t):
            early = w.set_at - (w.set_at - t) % 1.0
            w.end -= w.set_at - early
            w.set_at = w.window_at = early
        return w


class _ShortMovesSlow(MarlinUnit):
    def _move(self, t, words):
        start = super()._move(t, words)
        if self.planner and "X" in words and abs(words["X"]) < 1:
            end, target = self.planner.pop()
            self.planner.append((end + 0.1, target))   # a short move planned as a trapezoid
        return start


class _M155AloneStops(MarlinUnit):
    def _start(self, q):
        super()._start(q)
        if um._code(q.text) == "M155" and "S" not in um._words(q.text):
            self.temp_every, self.next_temp = 0.0, math.inf


class _QuickstopNeedsKeepalive(MarlinUnit):
    """M400 cut short by a quick stop only while busy: lines are being sent."""

    def _quickstop(self, t):
        busy, done = self.cur_busy, self.cur_done
        super()._quickstop(t)
        if not busy and self.cur is not None:
            self.cur_done = done


class _SlopeAtFirstCheck(MarlinUnit):
    """A cooling wait that gives up at the first slope check whatever the drop."""

    def _plan_wait(self, h, t):
        w = super()._plan_wait(h, t)
        if self.heat[h][1] < self.temp(h, t) and w.set_at == math.inf:
            w.end = t + 60.0
        return w


@pytest.mark.parametrize("unit_class,pattern", [
    (_QuickstopNeedsKeepalive, "m410-no-keepalive"),
    (_SlopeAtFirstCheck, "m109-r-slope-checks"),
    (_M504Loads, "m504-changes-nothing"),
    (_EarlyResidency, "m109-s-bounded"),
    (_ShortMovesSlow, "move-durations"),
    (_M155AloneStops, "m155-goes-on"),
])
def test_a_wrong_edge_fails_its_check(unit_class, pattern):
    spec = load_marlin()
    got = _run("marlin-2.1", lambda: unit_class(spec.variant("marlin-2.1"), spec, t0=0.0),
               pattern)
    assert [g for g, _ in got.values()] == [Grade.FAIL], got
