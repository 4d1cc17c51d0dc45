"""Deviant grbl units: the reference unit with one small bug each, as a firmware change would
make it. The suite tests itself on them (``conform run --mutants --variant grbl-1.1f``,
``conform run --target emu:grbl-1.1f:NAME``); each mutant names the checks meant to catch it
(ids after the variant, fnmatch patterns).

A mutant is a subclass of :class:`GrblUnit` overriding one method, or the reference unit
built from a changed table row (a build option, a limit, a setting's range): everything else
behaves exactly as the reference.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from conform.families.grbl.protocol.gcode import Block, GcodeError, words
from conform.families.grbl.spec.load import GrblSpec, Variant
from conform.families.grbl.unit.model import GrblUnit


class JogCheckedFirst(GrblUnit):
    """The jog's own check (16) runs before gcode.c's STEP 3 checks: ``$J=G2X1F100`` is 16."""

    def parse(self, text: str, *, jog: bool = False) -> Block:
        if jog and any((c == "G" and v not in (20, 21, 53, 90, 91)) or c == "M"
                       for c, v, _ in words(text)):
            raise GcodeError(16)
        return super().parse(text, jog=jog)


class JogTakesSpindleWords(GrblUnit):
    """A jog ignores S and T instead of leaving them as unused words (36)."""

    def parse(self, text: str, *, jog: bool = False) -> Block:
        if jog:
            text = re.sub(r"[ST][-+]?[\d.]+", "", text)
        return super().parse(text, jog=jog)


class _Recoded(GrblUnit):
    """A parser that answers ``code_to`` where grbl answers ``code_from`` on lines ``when``
    matches."""

    code_from = code_to = 0
    when = re.compile("")

    def parse(self, text: str, *, jog: bool = False) -> Block:
        try:
            return super().parse(text, jog=jog)
        except GcodeError as exc:
            if exc.code == self.code_from and self.when.search(text):
                raise GcodeError(self.code_to) from None
            raise


class AnyFractionIs23(_Recoded):
    """An unsupported fractional G code (G61.1, G90.1, G28.2) is error:23, not 20."""

    code_from, code_to, when = 20, 23, re.compile(r"G\d+\.\d")


class ToolKept(GrblUnit):
    """A block without T keeps the tool number (grbl sets it to 0, gcode.c [5])."""

    def parse(self, text: str, *, jog: bool = False) -> Block:
        block = super().parse(text, jog=jog)
        if "T" not in text:
            block.modal.tool = self.modal.tool
        return block


class ResetKeepsToolAndFeed(GrblUnit):
    """A soft reset keeps the tool and the feed rate (gc_init clears the parser state)."""

    def _reset(self, t: float, power_up: bool = False, announce: float | None = None) -> None:
        kept = (self.modal.tool, self.modal.feed) if hasattr(self, "modal") else None
        super()._reset(t, power_up, announce)
        if kept:
            self.modal.tool, self.modal.feed = kept


class G80Lenient(GrblUnit):
    """Under G80 only motion words fail 31; G92's axis words pass."""

    def parse(self, text: str, *, jog: bool = False) -> Block:
        try:
            return super().parse(text, jog=jog)
        except GcodeError as exc:
            if exc.code != 31 or not re.search(r"G(10|28|30|92)(?![\d.])", text):
                raise
            saved = self.modal
            self.modal = saved.copy()
            self.modal.motion = "0"
            try:
                block = super().parse(text.replace("G80", ""), jog=jog)
            finally:
                self.modal = saved
            block.modal.motion = "80"
            return block


class ArcWithoutAxesIs32(_Recoded):
    """G2/G3 without axis words answers 32 (none in the plane) instead of 26."""

    code_from, code_to, when = 26, 32, re.compile(r"G0*[23](?![\d.])")


class NoAlarmDelay(GrblUnit):
    """No half-second pause after ALARM:N (report.c delay_ms(500) left out)."""

    def _alarm(self, t: float, code: int) -> None:
        self._say(t, f"ALARM:{code}")


class PendingLineDropped(GrblUnit):
    """At a reset the line grbl was inside gets no answer (grbl answers it ok)."""

    def _soft_reset(self, t: float) -> None:
        self._owed = False
        self._pending = None
        self._busy = None
        super()._soft_reset(t)


class ProbeFailTakesPosition(GrblUnit):
    """A G38.2 without contact stores the position reached as the probe position."""

    def _probe_done(self, t: float, move: Any) -> None:
        self.prb = list(move.end)
        super()._probe_done(t, move)


class TrailingLetterIgnored(GrblUnit):
    """``$x=5x``: the letters after the value are ignored (system.c: error:3)."""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        super()._process(re.sub(r"^(\$\d+=[-+\d.]+)[A-Z]+$", r"\1", text), overflow, t)


def _variant(build_options: dict[str, Any] | None = None, **changes: Any
             ) -> Callable[[Variant], Variant]:
    def change(v: Variant) -> Variant:
        return dataclasses.replace(v, **changes, build_options={**v.build_options,
                                                                 **(build_options or {})})
    return change


def _setting(number: int, **changes: Any) -> Callable[[GrblSpec], GrblSpec]:
    def change(spec: GrblSpec) -> GrblSpec:
        settings = dict(spec.settings)
        settings[number] = dataclasses.replace(settings[number], **changes)
        return dataclasses.replace(spec, settings=settings)
    return change


@dataclass(frozen=True)
class Mutant:
    name: str
    fault: str
    catches: tuple[str, ...]       # check ids after "<variant>/", fnmatch patterns
    cls: type[GrblUnit] = GrblUnit
    variant: Callable[[Variant], Variant] | None = None
    spec: Callable[[GrblSpec], GrblSpec] | None = None

    def make(self, spec: GrblSpec, vid: str, **options: Any) -> GrblUnit:
        s = self.spec(spec) if self.spec else spec
        v = s.variant(vid)
        return self.cls(self.variant(v) if self.variant else v, s, **options)


MUTANTS: dict[str, Mutant] = {m.name: m for m in (
    Mutant("jog-checked-first", "the jog check runs before the arc and word checks",
           ("gcode.c/example/jog-arc-checked-first",), JogCheckedFirst),
    Mutant("jog-takes-s-t", "a jog ignores S and T", ("gcode.c/example/jog-spindle-word-unused",),
           JogTakesSpindleWords),
    Mutant("line-number-doc-limit", "N up to 9,999,999 (the documents' figure)",
           ("gcode.c/example/line-number-at-max",), variant=_variant(line_number_max=9999999)),
    Mutant("m7-built", "M7 accepted as if ENABLE_M7 were defined",
           ("gcode.c/example/m7-not-built",),
           variant=_variant(build_options={"ENABLE_M7": True})),
    Mutant("fraction-is-23", "unsupported fractional G codes answer 23",
           ("gcode.c/example/g61.1-unsupported",), AnyFractionIs23),
    Mutant("tool-kept", "a block without T keeps the tool number",
           ("gcode.c/example/tool-of-a-block-without-t",), ToolKept),
    Mutant("reset-keeps-tool-feed", "a soft reset keeps the tool and the feed rate",
           ("gcode.c/example/reset-clears-tool-and-feed",), ResetKeepsToolAndFeed),
    Mutant("g80-lenient", "under G80 a G92 with axis words is accepted",
           ("gcode.c/example/g80-axis-words-strict",), G80Lenient),
    Mutant("arc-no-axis-32", "G2 without axis words answers 32",
           ("gcode.c/example/arc-without-axis-words",), ArcWithoutAxesIs32),
    Mutant("no-alarm-delay", "no half-second pause after ALARM:N",
           ("alarm_codes/alarm/2",), NoAlarmDelay),
    Mutant("pending-line-dropped", "the line grbl was inside is not answered at a reset",
           ("alarm_codes/alarm/2",), PendingLineDropped),
    Mutant("probe-fail-silent", "no [PRB:…:0] after a failed probe",
           ("alarm_codes/alarm/5",),
           variant=_variant(build_options={"MESSAGE_PROBE_COORDINATES": False})),
    Mutant("probe-fail-takes-position", "a failed G38.2 stores the position reached",
           ("alarm_codes/alarm/5",), ProbeFailTakesPosition),
    Mutant("setting-0-widened", "$0 accepts 1 and 2 (its documented minimum is 3)",
           ("setting_codes/setting/0/min-1",), spec=_setting(0, lo=1.0)),
    Mutant("setting-trailing-letter", "$x=5x is taken as $x=5",
           ("setting_codes/setting/*/trailing-letter",), TrailingLetterIgnored),
    Mutant("setting-not-uint8", "$1 keeps 256 instead of the truncated uint8_t 0",
           ("setting_codes/setting/1/max+1",), spec=_setting(1, bits=16)),
)}


def mutant(name: str) -> Mutant:
    from conform.errors import UserError

    if name not in MUTANTS:
        raise UserError(f"no grbl mutant {name!r} (mutants: {', '.join(MUTANTS)})")
    return MUTANTS[name]


def run_mutants(spec: GrblSpec, vid: str, run_one: Callable[[Any, str], Any], *,
                names: Sequence[str] | None = None) -> tuple[list[dict[str, Any]], list[Any]]:
    """Every mutant (or those in ``names``) through ``run_one(target, id)``: which checks
    failed on each, and whether one of them is a check meant to catch it."""
    from conform.conformance.results import Grade
    from conform.conformance.target import EmuTarget

    report, runs = [], []
    for m in MUTANTS.values():
        if names is not None and m.name not in names:
            continue
        t0 = time.perf_counter()
        target = EmuTarget(lambda m=m: m.make(spec, vid), f"emu:{vid}:{m.name}")
        try:
            run = run_one(target, vid)
        finally:
            target.close()
        failed = [c.id for c in run.checks if c.grade is Grade.FAIL]
        hit = [c for c in failed if any(fnmatch.fnmatchcase(c.split("/", 1)[1], p)
                                        for p in m.catches)]
        report.append({"name": m.name, "variant": vid, "fault": m.fault,
                       "catches": list(m.catches), "caught_by": failed, "expected_hit": hit,
                       "killed": bool(failed), "seconds": round(time.perf_counter() - t0, 3)})
        runs.append(run)
    return report, runs
