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


# ---- effects seen only from a non-default state (from_state.py) ----------------------------
_G92 = re.compile(r"G92(?![\d.])")


class _Rewritten(GrblUnit):
    """A unit that takes a line as ``pattern`` rewritten to ``into`` (a command mistaken for
    its neighbour)."""

    pattern = re.compile("$^")
    into = ""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        super()._process(self.pattern.sub(self.into, text), overflow, t)


class G10IndexOffByOne(GrblUnit):
    """G10 P2..P6 write the system before the one named (P2 into G54)."""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        super()._process(re.sub(r"(G10.*)P([2-6])", lambda m: f"{m.group(1)}P{int(m.group(2)) - 1}",
                                text), overflow, t)


class L20AsL2(_Rewritten):
    """G10 L20 stores the words as given (the L2 behaviour)."""

    pattern, into = re.compile(r"L20(?!\d)"), "L2"


class G281IntoG30(_Rewritten):
    """G28.1 stores the position as G30."""

    pattern, into = re.compile(r"G28\.1"), "G30.1"


class G301IntoG28(_Rewritten):
    """G30.1 stores the position as G28."""

    pattern, into = re.compile(r"G30\.1"), "G28.1"


class G901Accepted(_Rewritten):
    """G90.1 is taken as a no-op (arc centre absolute mistaken for grbl's default)."""

    pattern, into = re.compile(r"G90\.1"), ""


class StartupIndexOneBased(_Rewritten):
    """``$N1=`` stores into line 0 (the index counted from one)."""

    pattern, into = re.compile(r"^\$N1="), "$N0="


class _Block(GrblUnit):
    """A parser whose block, when ``when`` matches the line, is changed by ``change``."""

    when = re.compile("$^")

    def change(self, block: Block) -> None:
        raise NotImplementedError

    def parse(self, text: str, *, jog: bool = False) -> Block:
        block = super().parse(text, jog=jog)
        if not jog and self.when.search(text):
            self.change(block)
        return block


class G92IgnoresTlo(_Block):
    """G92 Z leaves the tool length offset out of the offset it computes."""

    when = re.compile(r"G92(?![\d.]).*Z")

    def change(self, block: Block) -> None:
        block.modal.g92[2] += self.modal.tlo


class G92ZeroesOtherAxes(_Block):
    """G92 clears the offsets of the axes it does not name."""

    when = _G92

    def change(self, block: Block) -> None:
        text = self._line_text
        for k, a in enumerate("XYZ"):
            if a not in text.split("G92", 1)[1]:
                block.modal.g92[k] = 0.0

    def parse(self, text: str, *, jog: bool = False) -> Block:
        self._line_text = text
        return super().parse(text, jog=jog)


class G921NoWcoRefresh(_Block):
    """G92.1 clears the offset without forcing WCO: into the next report."""

    when = re.compile(r"G92\.1")

    def change(self, block: Block) -> None:
        block.wco = False


class G431Adds(_Block):
    """G43.1 adds to the tool length offset in force instead of replacing it."""

    when = re.compile(r"G43\.1")

    def change(self, block: Block) -> None:
        block.modal.tlo += self.modal.tlo


class G431IgnoresInches(_Block):
    """G43.1 Z under G20 is stored as millimetres."""

    when = re.compile(r"G43\.1")

    def change(self, block: Block) -> None:
        if block.modal.units == "20":
            block.modal.tlo /= 25.4


def _rewrite(pattern: str, into: str) -> type[GrblUnit]:
    """A :class:`_Rewritten` unit taking ``pattern`` as ``into``."""
    return type("Rewritten", (_Rewritten,), {"pattern": re.compile(pattern), "into": into})


class _Kept(_Block):
    """A word that is checked and accepted but not applied: ``field`` of the parser state
    stays as it was (a case missing from the switch that executes it)."""

    field = ""

    def change(self, block: Block) -> None:
        setattr(block.modal, self.field, getattr(self.modal, self.field))


def _kept(word: str, field: str) -> type[GrblUnit]:
    """A :class:`_Kept` unit: G``word`` leaves ``field``."""
    return type("Kept", (_Kept,), {"when": re.compile(rf"G{word}(?![\d.])"), "field": field})


class G21SetsG90(_Block):
    """G21 also puts the distance mode back to G90 (a units change resetting its neighbour)."""

    when = re.compile(r"G21(?![\d.])")

    def change(self, block: Block) -> None:
        block.modal.distance = "90"


class G54ClearsG92(_Block):
    """Selecting G54 clears the G92 offset (a system select taken as G92.1 too)."""

    when = re.compile(r"G54(?![\d.])")

    def change(self, block: Block) -> None:
        block.modal.g92 = [0.0, 0.0, 0.0]


class M30KeepsCoord(GrblUnit):
    """M30 keeps the coordinate system (M2 resets it to G54)."""

    def parse(self, text: str, *, jog: bool = False) -> Block:
        self._m30 = bool(re.search(r"M30(?!\d)", text))
        return super().parse(text, jog=jog)

    def _program_end(self, t: float) -> None:
        coord = self.modal.coord
        super()._program_end(t)
        if getattr(self, "_m30", False):
            self.modal.coord = coord


class ProgramEndKeepsSpindle(GrblUnit):
    """M2/M30 leave the spindle and coolant as they were."""

    def _program_end(self, t: float) -> None:
        kept = self.modal.spindle, self.modal.coolant
        super()._program_end(t)
        self.modal.spindle, self.modal.coolant = kept
        self._spindle_sync()


class _ResetKeeps(GrblUnit):
    """A soft reset that keeps ``kept`` (attribute names) as they were."""

    kept: tuple[str, ...] = ()

    def _reset(self, t: float, power_up: bool = False, announce: float | None = None) -> None:
        was = {k: getattr(self, k) for k in self.kept} if hasattr(self, "modal") else {}
        modal = self.modal.copy() if hasattr(self, "modal") else None
        super()._reset(t, power_up, announce)
        for k, v in was.items():
            setattr(self, k, v)
        if modal is not None:
            self._keep(modal)

    def _keep(self, before: Any) -> None:
        pass


class ResetKeepsG92(_ResetKeeps):
    """A soft reset keeps the G92 offset."""

    def _keep(self, before: Any) -> None:
        self.modal.g92 = list(before.g92)


class ResetKeepsOverrides(_ResetKeeps):
    """A soft reset keeps the feed, rapid and spindle overrides."""

    kept = ("ov_feed", "ov_rapid", "ov_spindle")


class ResetKeepsSpindle(_ResetKeeps):
    """A soft reset keeps the spindle and coolant modes (M3, M8 in $G and A:)."""

    def _keep(self, before: Any) -> None:
        self.modal.spindle, self.modal.coolant = before.spindle, before.coolant


class SleepKeepsCoolant(GrblUnit):
    """$SLP turns the spindle off and leaves the coolant on."""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        kept = self.modal.coolant if text == "$SLP" else None
        super()._process(text, overflow, t)
        if kept is not None and self.state == "Sleep":
            self.modal.coolant = kept


class FloodToggleNoRefresh(GrblUnit):
    """0xA0 toggles the flood coolant without forcing Ov:/A: into the next report."""

    def _realtime(self, b: int, t: float) -> None:
        counter = self._ovr_counter
        super()._realtime(b, t)
        if self.spec.realtime[b].effect == "flood":
            self._ovr_counter = counter


class CheckExitKeepsModes(GrblUnit):
    """Leaving check mode keeps the modes the checked lines set (grbl resets)."""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        kept = self.modal.copy() if text == "$C" and self.state == "Check" else None
        super()._process(text, overflow, t)
        if kept is not None:
            self.modal = kept


class FeedResetResetsAll(GrblUnit):
    """0x90 (feed override 100 %) puts the rapid and spindle overrides back too."""

    def _override(self, effect: str) -> None:
        super()._override(effect)
        if effect == "feed=100":
            self.ov_rapid = self.ov_spindle = 100


class WposWithoutTlo(GrblUnit):
    """WPos: (``$10=0``) leaves the tool length offset out of the work position."""

    def _status_report(self, t: float) -> bytes:
        tlo = self.modal.tlo
        if int(self.settings[10]) & 1:
            return super()._status_report(t)
        self.modal.tlo = 0.0
        try:
            return super()._status_report(t)
        finally:
            self.modal.tlo = tlo


class _RestoreAlso(GrblUnit):
    """``$RST=`` with ``which``: also what ``also`` names, or keeps what ``keep`` names."""

    which = ""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        if text != f"$RST={self.which}":
            super()._process(text, overflow, t)
            return
        self._before_restore()
        super()._process(text, overflow, t)
        self._after_restore()

    def _before_restore(self) -> None:
        pass

    def _after_restore(self) -> None:
        pass


class RstHashRestoresSettings(_RestoreAlso):
    """$RST=# restores the settings too."""

    which = "#"

    def _before_restore(self) -> None:
        self.settings = {n: s.default for n, s in self.spec.settings.items()}


class RstDollarClearsOffsets(_RestoreAlso):
    """$RST=$ clears the G54-G59, G28 and G30 data too."""

    which = "$"

    def _before_restore(self) -> None:
        from conform.families.grbl.protocol.gcode import Modal

        self.eeprom_coords = Modal()


class RstStarKeepsStartup(_RestoreAlso):
    """$RST=* leaves the startup lines."""

    which = "*"

    def _before_restore(self) -> None:
        self._kept = list(self.startup)

    def _after_restore(self) -> None:
        self.startup = self._kept


class AxisSettingSpills(GrblUnit):
    """An axis setting ($100-$132) written for one axis is written to the next axis too."""

    def _process(self, text: str, overflow: bool, t: float) -> None:
        super()._process(text, overflow, t)
        m = re.fullmatch(r"\$1([0-3])([01])=([\d.]+)", text)
        if m:
            from conform.families.grbl.unit.system import store_setting

            store_setting(self, 100 + 10 * int(m.group(1)) + int(m.group(2)) + 1,
                          float(m.group(3)))


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
    Mutant("g10-p-off-by-one", "G10 P2..P6 write the system before the one named",
           ("from_state/effect/g10-l2-p2",), G10IndexOffByOne),
    Mutant("g10-l20-as-l2", "G10 L20 stores the words as given, as L2",
           ("from_state/effect/g10-l20",), L20AsL2),
    Mutant("g28.1-into-g30", "G28.1 stores the position as G30",
           ("from_state/effect/g28.1",), G281IntoG30),
    Mutant("g30.1-into-g28", "G30.1 stores the position as G28",
           ("from_state/effect/g30.1",), G301IntoG28),
    Mutant("g90.1-accepted", "G90.1 is accepted as a no-op (grbl: error:20)",
           ("from_state/effect/g90.1",), G901Accepted),
    Mutant("startup-line-one-based", "$N1= stores startup line 0",
           ("from_state/effect/startup-line-1",), StartupIndexOneBased),
    Mutant("g92-ignores-tlo", "G92 Z leaves the tool length offset out",
           ("from_state/effect/g92",), G92IgnoresTlo),
    Mutant("g92-zeroes-other-axes", "G92 clears the offsets of the axes it does not name",
           ("from_state/effect/g92-one-axis",), G92ZeroesOtherAxes),
    Mutant("g92.1-no-wco-refresh", "G92.1 does not force WCO: into the next report",
           ("from_state/effect/g92.1",), G921NoWcoRefresh),
    Mutant("g43.1-adds", "G43.1 adds to the tool length offset in force",
           ("from_state/effect/g43.1",), G431Adds),
    Mutant("g43.1-ignores-inches", "G43.1 Z under G20 is taken as millimetres",
           ("from_state/effect/g43.1",), G431IgnoresInches),
    Mutant("m30-keeps-coord", "M30 keeps the coordinate system (M2 resets it)",
           ("from_state/effect/program-end-m30",), M30KeepsCoord),
    Mutant("program-end-keeps-spindle", "M2/M30 leave the spindle and coolant on",
           ("from_state/effect/program-end-outputs",), ProgramEndKeepsSpindle),
    Mutant("reset-keeps-g92", "a soft reset keeps the G92 offset",
           ("from_state/effect/soft-reset",), ResetKeepsG92),
    Mutant("reset-keeps-overrides", "a soft reset keeps the overrides",
           ("from_state/effect/soft-reset",), ResetKeepsOverrides),
    Mutant("reset-keeps-spindle", "a soft reset keeps M3/M8 in the parser state",
           ("from_state/effect/soft-reset-outputs",), ResetKeepsSpindle),
    Mutant("sleep-keeps-coolant", "$SLP leaves the flood coolant on",
           ("from_state/effect/sleep-outputs",), SleepKeepsCoolant),
    Mutant("flood-toggle-no-refresh", "0xA0 does not force Ov:/A: into the next report",
           ("from_state/effect/flood-toggle",), FloodToggleNoRefresh),
    Mutant("check-exit-keeps-modes", "leaving check mode keeps the modes set in it",
           ("from_state/effect/check-mode",), CheckExitKeepsModes),
    Mutant("feed-reset-resets-all", "0x90 puts the rapid and spindle overrides back too",
           ("from_state/effect/override-resets",), FeedResetResetsAll),
    Mutant("wpos-without-tlo", "WPos: ($10=0) leaves the tool length offset out",
           ("from_state/effect/status-mask",), WposWithoutTlo),
    Mutant("rst-hash-restores-settings", "$RST=# restores the settings too",
           ("from_state/effect/rst-hash",), RstHashRestoresSettings),
    Mutant("rst-dollar-clears-offsets", "$RST=$ clears the coordinate data too",
           ("from_state/effect/rst-dollar",), RstDollarClearsOffsets),
    Mutant("rst-star-keeps-startup", "$RST=* leaves the startup lines",
           ("from_state/effect/rst-star",), RstStarKeepsStartup),
    Mutant("axis-setting-spills", "an axis setting written is written to the next axis too",
           ("from_state/effect/setting-writes",), AxisSettingSpills),
    Mutant("g49-keeps-tlo", "G49 is accepted and leaves the tool length offset",
           ("from_state/effect/g49",), _kept("49", "tlo")),
    Mutant("g91.1-as-g91", "G91.1 is taken as G91 (distance mode, not arc mode)",
           ("from_state/effect/g91.1",), _rewrite(r"G91\.1", "G91")),
    Mutant("g21-sets-g90", "G21 also puts the distance mode back to G90",
           ("from_state/effect/modal-words",), G21SetsG90),
    Mutant("g54-clears-g92", "selecting G54 clears the G92 offset",
           ("from_state/effect/modal-words",), G54ClearsG92),
    Mutant("g17-ignored", "G17 is accepted and leaves the plane",
           ("from_state/effect/modal-words",), _kept("17", "plane")),
    Mutant("g80-ignored", "G80 is accepted and leaves the motion mode",
           ("from_state/effect/modal-words",), _kept("80", "motion")),
    Mutant("g93-ignored", "G93 is accepted and leaves the feed rate mode",
           ("from_state/effect/modal-words",), _kept("93", "feed_mode")),
    Mutant("g10-p0-as-g54", "G10 L2 P0 writes G54, not the active system",
           ("from_state/effect/g10-l2-p0",), _rewrite(r"(G10.*)P0(?![\d.])", r"\1P1")),
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
