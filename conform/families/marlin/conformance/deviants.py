"""Deviant Marlin units for the commands beyond the line protocol (settings, EEPROM, reports,
tools, messages, dwell, modes, moves): each does one thing as a neighbouring command does, or
as an easy slip in a fork would, and one check of conformance/depth.py must catch it.
Registered with the others in conformance/mutants.py.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from conform.families.marlin.unit import settings as st
from conform.families.marlin.unit.settings import Settings
from conform.families.marlin.unit.unit import MarlinUnit, Queued

Words = dict[str, str]


def _unit(settings: type[Settings], doc: str) -> type[MarlinUnit]:
    """A unit whose settings behave as ``settings`` does."""
    return type(settings.__name__ + "Unit", (MarlinUnit,), {"settings_class": settings,
                                                            "__doc__": doc})


class _M203IntoM201(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        return super().set("M201" if code == "M203" else code, w, position)


class _SwapsXY(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        if code == "M92" and "Y" in w:
            w = {("X" if k == "Y" else k): x for k, x in w.items()}
        return super().set(code, w, position)


class _ResetsOthers(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        if code == "M201" and w:
            self.now["M201"] = list(st.defaults(self.v)["M201"])
        return super().set(code, w, position)


class _LegacySRetract(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        if code == "M204" and "S" in w:
            w = {("R" if k == "S" else k): x for k, x in w.items()}
        return super().set(code, w, position)


class _JUnbounded(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        if code == "M205" and "J" in w:
            self.now["M205"][3] = float(w["J"])
            w = {k: x for k, x in w.items() if k != "J"}
            if not w:
                return []
        return super().set(code, w, position)


class _NoEScale(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        keep = self.now["M203"][3]
        out = super().set(code, w, position)
        self.now["M203"][3] = keep
        return out


class _M206Silent(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        out = super().set(code, w, position)
        return [] if code == "M206" and w else out


class _M301IntoM304(Settings):
    def set(self, code: str, w: Words, position: Callable[[], str]) -> list[str]:
        return super().set("M304" if code == "M301" else code, w, position)


class _FeedIsFlow(Settings):
    def m220(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        if "S" in w:
            self.flow_percent = int(float(w["S"]))
            return []
        return super().m220(w, text, t, eeprom)


class _FlowIsFeed(Settings):
    def m221(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        if "S" in w and "T" not in w:
            self.feed_percent = int(float(w["S"]))
            return []
        return super().m221(w, text, t, eeprom)


class _ReportWithoutHeadings(Settings):
    def report(self, for_replay: bool = False) -> list[str]:
        return ["echo:" + x for x in super().report(for_replay=True)]


class _PaddedM92(Settings):
    def report(self, for_replay: bool = False) -> list[str]:
        out = super().report(for_replay)
        return [x.replace(" M92 X", " M92 X0") if " M92 X" in x else x for x in out]


class _LoadSilent(Settings):
    def load(self, eeprom: dict[str, Any], *, validating: bool = False,
             announce: bool = True) -> list[str]:
        return super().load(eeprom, validating=validating, announce=False)


class _ForgetsOffset(Settings):
    def m500(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        out = super().m500(w, text, t, eeprom)
        eeprom["settings"]["M206"] = [0.0, 0.0, 0.0]
        return out


class _M502Stores(Settings):
    def m502(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        out = super().m502(w, text, t, eeprom)
        eeprom["settings"] = {k: list(x) for k, x in self.now.items()}
        return out


class _EightTools(Settings):
    def tool(self, n: int) -> list[str]:
        return [] if n < 8 else super().tool(n)


class _ToolOffByOne(Settings):
    def tool(self, n: int) -> list[str]:
        return [] if n <= self.v.extruders else super().tool(n)


class _M118KeepsE1(Settings):
    def m118(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return super().m118(w, text.replace("E1", "E 1"), t, eeprom)


class _NoEcho(Settings):
    def m111(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        out = super().m111(w, text, t, eeprom)
        self.debug &= ~1
        return out


class _TimerResumes(Settings):
    def m75(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        if self.timer_start is None:
            self.timer_start = t
        return []


class _ClockInMinutes(Settings):
    def m31(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        s = int(self.elapsed(t))
        return [f"echo:Print time: {s // 60}m {s % 60}s"]


class _NoLogicalOffset(Settings):
    @property
    def home_offset(self) -> list[float]:
        return [0.0, 0.0, 0.0]


class _M221AnyExtruder(Settings):
    def _extruder(self, code: str, w: Words) -> tuple[bool, list[str]]:
        return (True, []) if code == "M221" else super()._extruder(code, w)


class _M113Ignored(Settings):
    def m113(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return super().m113({}, text, t, eeprom) if "S" not in w else []


class _M113Unbounded(Settings):
    def m113(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        out = super().m113(w, text, t, eeprom)
        if st.boolval(w, "S", False):
            self.keepalive = int(float(w["S"]))
        return out


class _M200NoEnable(Settings):
    def m200(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        was = self.volumetric
        out = super().m200(w, text, t, eeprom)
        if "S" not in w:
            self.volumetric = was
        return out


class _M200HeadingKept(Settings):
    def report(self, for_replay: bool = False) -> list[str]:
        return [x.replace("Filament settings", "Filament settings (Disabled):")
                if x == "echo:; Filament settings" else x for x in super().report(for_replay)]


class _M211IgnoresS(Settings):
    def m211(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return [] if "S" in w else super().m211(w, text, t, eeprom)


class _M211Native(Settings):
    def m211(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        off, self.now["M206"] = self.now["M206"], [0.0, 0.0, 0.0]
        try:
            return super().m211(w, text, t, eeprom)
        finally:
            self.now["M206"] = off


class _M302Float(Settings):
    def m302(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return [x.replace(f"temp {self.cold_min}C", f"temp {self.cold_min:.2f}C")
                for x in super().m302(w, text, t, eeprom)]


class _M302PIgnored(Settings):
    def m302(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        if "P" not in w:
            return super().m302(w, text, t, eeprom)
        rest = {k: x for k, x in w.items() if k != "P"}
        return super().m302(rest, text, t, eeprom) if rest else []


class _M303Echo(Settings):
    def m303(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return ["echo:" + x for x in super().m303(w, text, t, eeprom)]


class _M575Silent(Settings):
    def m575(self, w: Words, text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return [x for x in super().m575(w, text, t, eeprom) if "implausible" not in x]


class _Unknown(MarlinUnit):
    unknown: tuple[str, ...] = ()

    def _command(self, code: str) -> Any:
        return None if code in self.unknown else super()._command(code)


class OldCommandsUnknown(_Unknown):
    """Answers M85, M120 and M121 Unknown command (a build without them; this one has them)."""

    unknown = ("M85", "M120", "M121")


class M428AddsOffset(MarlinUnit):
    """M428 adds the distance to the offset it had instead of replacing it."""

    def _m428(self) -> list[str]:
        before = list(self.settings.home_offset)
        out = super()._m428()
        if out and not out[0].startswith(("Error", "echo:")):
            self.settings.home_offset[:] = [a + b for a, b in zip(before, self.settings.home_offset,
                                                                  strict=True)]
            out = [self._position_line()]
        return out


class M428NoLimit(MarlinUnit):
    """M428 sets the offsets however far the axes are from home (no 20 mm limit)."""

    def _m428(self) -> list[str]:
        if not self.homed:
            return super()._m428()
        self.settings.home_offset[:] = [-x for x in self.position[:3]]
        return [self._position_line()]


class M999OneOk(MarlinUnit):
    """M999: Resend: and one ok (the request's ok taken for the command's)."""

    def _ok(self, q: Queued, t: float) -> None:
        if q.text.strip() == "M999":
            return
        super()._ok(q, t)


class InchMode(MarlinUnit):
    """Takes G20 (as with INCH_MODE_SUPPORT) where this build says Unknown command."""

    def _command(self, code: str) -> Any:
        return super()._command("G21" if code == "G20" else code)


class NoArcs(MarlinUnit):
    """Answers G2/G3 Unknown command (as a build without ARC_SUPPORT) although this one has
    it."""

    def _command(self, code: str) -> Any:
        return None if code in ("G2", "G3") else super()._command(code)


class DwellAdds(MarlinUnit):
    """G4 P<ms> S<s>: waits for both added up (the source: S wins)."""

    def _start(self, q: Queued) -> None:
        super()._start(q)
        if q.text.startswith("G4") and "P" in q.text and "S" in q.text:
            p = float(q.text.split("P")[1].split()[0])
            self.cur_done += p / 1000.0


class ExtrudesCold(MarlinUnit):
    """Extrudes with a cold hotend without a word (no PREVENT_COLD_EXTRUSION)."""

    def _say(self, t: float, *lines: str) -> None:
        super()._say(t, *[x for x in lines if x != "echo: cold extrusion prevented"])


class G91LeavesE(MarlinUnit):
    """G91 makes X, Y, Z relative but leaves E absolute (as M82 alone would)."""

    def _start(self, q: Queued) -> None:
        e = self.e_relative
        super()._start(q)
        if q.text.strip().startswith("G91"):
            self.e_relative = e


class FeedPercentIgnored(MarlinUnit):
    """Takes M220 S but moves at the programmed feedrate."""

    def _move(self, t: float, words: dict[str, float]) -> float:
        keep, self.settings.feed_percent = self.settings.feed_percent, 100
        try:
            return super()._move(t, words)
        finally:
            self.settings.feed_percent = keep


class HotendSetsBed(MarlinUnit):
    """M104 sets the bed's target too."""

    def _set_target(self, h: int, target: float, t: float) -> None:
        super()._set_target(h, target, t)
        if h == 0:
            super()._set_target(1, target, t)


DEVIANTS: dict[str, type[MarlinUnit]] = {
    "m203-into-m201": _unit(_M203IntoM201, "M203 writes M201's values (max acceleration) "
                            "instead of the max feedrates."),
    "m92-y-into-x": _unit(_SwapsXY, "M92 Y sets X's steps per mm."),
    "m201-resets-others": _unit(_ResetsOthers, "M201 puts the axes it was not given back to "
                                "their defaults."),
    "m204-s-retract": _unit(_LegacySRetract, "M204 S sets the retract acceleration, not print "
                            "and travel."),
    "m205-j-unbounded": _unit(_JUnbounded, "M205 J takes any value (no 0.01 .. 0.3 range)."),
    "m92-e-no-scale": _unit(_NoEScale, "M92 E below 20 leaves E's max feedrate as it was."),
    "m206-silent": _unit(_M206Silent, "M206 X.. says only ok (no position report)."),
    "m301-into-m304": _unit(_M301IntoM304, "M301 sets the bed PID (M304's) instead of the "
                            "hotend's."),
    "m220-sets-flow": _unit(_FeedIsFlow, "M220 S sets the flow percentage (M221's)."),
    "m221-sets-feed": _unit(_FlowIsFeed, "M221 S sets the feedrate percentage (M220's)."),
    "m503-no-headings": _unit(_ReportWithoutHeadings, "M503 prints no '; heading:' lines."),
    "m503-m92-padded": _unit(_PaddedM92, "M503 prints M92 X with a leading zero."),
    "m501-no-report": _unit(_LoadSilent, "M501 says retrieved without the settings report."),
    "m500-forgets-offset": _unit(_ForgetsOffset, "M500 does not store the M206 home offset."),
    "m502-writes-eeprom": _unit(_M502Stores, "M502 writes the defaults to the EEPROM too."),
    "eight-tools": _unit(_EightTools, "T1..T7 accepted as if there were 8 extruders."),
    "tool-off-by-one": _unit(_ToolOffByOne, "T1 accepted with one extruder (T2 on invalid)."),
    "m118-keeps-e1": _unit(_M118KeepsE1, "M118 E1 prints 'E 1 …' instead of the echo: prefix."),
    "m111-no-echo": _unit(_NoEcho, "M111 S1 reports ECHO but echoes no command."),
    "m75-resumes": _unit(_TimerResumes, "M75 after M77 goes on from the time so far."),
    "m31-minutes": _unit(_ClockInMinutes, "M31 always prints minutes ('0m 2s')."),
    "m206-no-logical": _unit(_NoLogicalOffset, "M206 is stored but the position ignores it."),
    "m221-any-extruder": _unit(_M221AnyExtruder, "M221 T1 accepted with one extruder."),
    "m113-ignored": _unit(_M113Ignored, "M113 S is taken but the interval stays as it was."),
    "m113-unbounded": _unit(_M113Unbounded, "M113 S99 keeps 99 (no 60 s limit)."),
    "m200-d-no-enable": _unit(_M200NoEnable, "M200 D sets the diameter but leaves volumetric "
                              "off."),
    "m200-heading-kept": _unit(_M200HeadingKept, "M503 says 'Filament settings (Disabled):' "
                               "with volumetric on."),
    "m211-ignores-s": _unit(_M211IgnoresS, "M211 S0 is taken but the soft endstops stay on."),
    "m211-native": _unit(_M211Native, "M211 reports the bounds without the M206 offset."),
    "m302-float": _unit(_M302Float, "M302 prints the minimum as a float (170.00C)."),
    "m302-p-ignored": _unit(_M302PIgnored, "M302 P1 does not allow cold extrusion."),
    "m303-echo": _unit(_M303Echo, "M303 E5's error carries an echo: prefix."),
    "m575-silent": _unit(_M575Silent, "M575 with a rate it does not know says only ok."),
    "m85-m120-unknown": OldCommandsUnknown,
    "m428-adds": M428AddsOffset,
    "m428-no-limit": M428NoLimit,
    "m999-one-ok": M999OneOk,
    "g20-accepted": InchMode,
    "no-arcs": NoArcs,
    "dwell-adds": DwellAdds,
    "extrudes-cold": ExtrudesCold,
    "g91-leaves-e": G91LeavesE,
    "m220-no-speed": FeedPercentIgnored,
    "m104-sets-bed": HotendSetsBed,
}
