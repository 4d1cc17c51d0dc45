"""What the Marlin reference unit keeps between commands besides motion and heat: the
settings a host sets and reads back (M92, M200, M201, M203, M204, M205, M206, M301, M304,
M220, M221), the settings report (M503), the EEPROM (M500, M501, M502, M504), tools (T<n>),
messages (M117, M118), debug flags (M111), the print timer (M31, M75, M77), the endstop
report (M119), the keepalive interval (M113), the inactivity timeout (M85), endstops on/off
(M120/M121), software endstops (M211), cold extrusion (M302), M303's heater check and
M575's baud rate.

``Settings.run`` answers one such command: the lines it prints before its ``ok``. Every
behaviour cites Marlin 2.1.2.4's function (spec/tables/settings.toml, commands.toml); the
report's exact lines are the real firmware's (shared/recordings/marlin-2.1.2.4/
reports.transcript).
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from conform.families.marlin.spec import Variant, load_marlin
from conform.families.rows import read_table

# module/settings.cpp MarlinSettings::report: the order of the groups
ORDER = ("M92", "M203", "M201", "M204", "M205", "M206", "M301", "M304")
HEADINGS = {"M92": "Steps per unit", "M203": "Max feedrates (units/s)"}
WORDS = {"M92": "XYZE", "M203": "XYZE"}
DEBUG_NAMES = ("ECHO", "INFO", "ERRORS", "DRYRUN", "COMMUNICATION")   # M111.cpp, bit by bit
_WORD = re.compile(r"([A-Za-z])\s*([-+]?\d*\.?\d*)")
FILAMENT_DIA = 1.75     # Configuration.h DEFAULT_NOMINAL_FILAMENT_DIA (VOLUMETRIC_DEFAULT_ON off)
EXTRUDE_MINTEMP = 170   # Configuration.h PREVENT_COLD_EXTRUSION, EXTRUDE_MINTEMP
SOFT_MIN = (0.0, 0.0, 0.0)          # Configuration.h X_MIN_POS, Y_MIN_POS, Z_MIN_POS
SOFT_MAX = (200.0, 200.0, 200.0)    # X_MAX_POS (X_BED_SIZE 200), Y_MAX_POS (Y_BED_SIZE), Z_MAX_POS
BAUDS = (2400, 9600, 19200, 38400, 57600, 115200, 250000, 500000, 1000000)   # M575.cpp
BAUD_SHORT = {24: 2400, 96: 9600, 192: 19200, 384: 38400, 576: 57600, 1152: 115200,
              250: 250000, 500: 500000, 19: 19200, 38: 38400, 57: 57600, 115: 115200}


@dataclass(frozen=True)
class Table:
    version: str
    stored_bytes: int
    headings: dict[str, str]
    words: dict[str, str]
    defaults: dict[str, tuple[float, ...]]
    cite: dict[str, str]


@lru_cache(maxsize=4)
def _table(root: str) -> Table:
    rows, data = read_table(Path(root), "settings")
    headings, words, defaults, cite = dict(HEADINGS), dict(WORDS), {}, {}
    for code in ORDER[2:]:
        row = f"setting.{code}"
        d = data.get("setting", {}).get(code)
        if d is None:
            raise rows.fail(row, "is missing (M503 reports it)")
        headings[code] = rows.get(row, d, "heading", str)
        words[code] = rows.get(row, d, "words", str)
        values = rows.get(row, d, "default", list)
        if len(values) != len(words[code]) or not all(
                isinstance(x, int | float) and not isinstance(x, bool) for x in values):
            raise rows.fail(row, f"field 'default': expected {len(words[code])} numbers "
                            f"({words[code]})")
        defaults[code] = tuple(float(x) for x in values)
        cite[code] = rows.get(row, d, "cite", str)
    return Table(rows.get("top", data, "version", str), rows.get("top", data, "stored_bytes", int),
                 headings, words, defaults, cite)


def table() -> Table:
    return _table(str(load_marlin().root))


def defaults(v: Variant) -> dict[str, list[float]]:
    """Every setting's power-up values (settings.cpp MarlinSettings::reset)."""
    out = {k: list(x) for k, x in table().defaults.items()}
    out["M92"], out["M203"] = list(v.steps_per_mm), list(v.max_feedrate)
    return out


def number(x: float) -> str:
    """A float as Marlin's serial prints it (two decimals)."""
    return f"{x:.2f}"


def report_line(code: str, values: list[float]) -> str:
    """``  M92 X80.00 Y80.00 Z400.00 E500.00`` (the two spaces are the firmware's)."""
    return f"  {code} " + " ".join(f"{w}{number(x)}" for w, x in zip(table().words[code], values,
                                                                       strict=True))


def words(text: str) -> dict[str, str]:
    """The parameters after the command: letter -> its text (``""``: seen without a value)."""
    out: dict[str, str] = {}
    for letter, value in _WORD.findall(text):
        out.setdefault(letter.upper(), value)
    return out


def boolval(w: dict[str, str], letter: str, default: bool) -> bool:
    """parser.boolval: the letter alone is true, with a value its byte is (0: false)."""
    if letter not in w:
        return default
    x = _value(w, letter)
    return True if x is None else int(x) != 0


def _value(w: dict[str, str], letter: str) -> float | None:
    """parser.seenval: the letter with a number after it."""
    text = w.get(letter, "")
    try:
        return float(text) if text not in ("", "-", "+", ".") else None
    except ValueError:
        return None


@dataclass
class Settings:
    """The unit's settings in RAM and in its EEPROM (None: never stored, the boot's empty
    eeprom.dat), the active tool, debug flags, the print timer."""

    v: Variant
    now: dict[str, list[float]] = field(default_factory=dict)
    feed_percent: int = 100
    flow_percent: int = 100
    debug: int = 0
    timer_start: float | None = None
    timer_total: float = 0.0
    keepalive: int = -1                 # M113 (host_keepalive_interval; -1: the variant's)
    inactive_s: float = 0.0             # M85 (max_inactive_time; 0: off)
    endstops_on: bool = True            # M120/M121 (ENDSTOPS_ALWAYS_ON_DEFAULT)
    volumetric: bool = False            # M200 S (parser.volumetric_enabled)
    filament: float = FILAMENT_DIA      # M200 D (planner.filament_size[0])
    soft_endstops: bool = True          # M211 S (soft_endstop._enabled)
    cold_min: int = EXTRUDE_MINTEMP     # M302 S (thermalManager.extrude_min_temp, celsius_t)
    cold_allowed: bool = False          # M302 P (thermalManager.allow_cold_extrude)

    def __post_init__(self) -> None:
        if not self.now:
            self.now = defaults(self.v)
        if self.keepalive < 0:
            self.keepalive = self.v.keepalive

    def too_cold(self, temp: float) -> bool:
        """temperature.h tooColdToExtrude: !allow_cold_extrude && temp < extrude_min_temp."""
        return not self.cold_allowed and temp < self.cold_min

    @property
    def steps(self) -> list[float]:
        return self.now["M92"]

    @property
    def max_feed(self) -> list[float]:
        return self.now["M203"]

    @property
    def home_offset(self) -> list[float]:
        return self.now["M206"]

    # -- the commands -------------------------------------------------------------------------
    def run(self, code: str, args: str, text: str, t: float, eeprom: dict[str, Any],
            position: Callable[[], str]) -> list[str]:
        """The lines ``code`` prints before its ok: ``args`` is what follows the command,
        ``text`` the command as parsed (after N, before the checksum); ``eeprom`` is the
        unit's EEPROM (kept across resets), ``position`` gives the M114 line."""
        w = words(args)
        if code[:1] == "T":
            return self.tool(int(code[1:]))
        if code in ORDER:
            return self.set(code, w, position)
        handler = getattr(self, f"m{code[1:]}", None) if code[:1] == "M" else None
        return handler(w, text, t, eeprom) if handler else []

    def tool(self, n: int) -> list[str]:
        """gcode/control/T.cpp GcodeSuite::T -> module/tool_change.cpp tool_change: a tool
        past EXTRUDERS is invalid_extruder_error (``echo:T<n> Invalid extruder``)."""
        return [] if n < self.v.extruders else [f"echo:T{n} Invalid extruder"]

    def _extruder(self, code: str, w: dict[str, str]) -> tuple[bool, list[str]]:
        """gcode.cpp get_target_extruder_from_command: T past EXTRUDERS stops the command."""
        e = _value(w, "T")
        if e is not None and int(e) >= self.v.extruders:
            return False, [f"echo:{code} Invalid extruder {int(e)}"]
        return True, []

    def set(self, code: str, w: dict[str, str], position: Callable[[], str]) -> list[str]:
        letters = table().words[code]
        if code in ("M92", "M201", "M203"):
            ok, out = self._extruder(code, w)
            if not ok:
                return out
            if not any(x in w for x in letters + ("T" if code != "M92" else "")):
                return [report_line(code, self.now[code])]        # M92_report(true), ...
        elif code in ("M205", "M206"):
            if not w:                                              # parser.seen_any()
                return [report_line(code, self.now[code])]        # M206_report()
        elif not any(x in w for x in letters + ("S" if code == "M204" else "")):
            return [report_line(code, self.now[code])]
        values = self.now[code]
        out: list[str] = []
        if code == "M204" and _value(w, "S") is not None:          # legacy S: print and travel
            values[0] = values[2] = float(_value(w, "S") or 0.0)
        for i, letter in enumerate(letters):
            x = _value(w, letter)
            if x is None:
                continue
            if code == "M205" and letter == "J" and not 0.01 <= x <= 0.3:
                out.append("Error:?J out of range (0.01 to 0.3)")
                continue
            if code == "M205" and letter == "B":
                x = float(int(x))                                  # parser.value_ulong
            if code == "M92" and letter == "E" and x < 20 and x > 0:
                # M92.cpp: a small E steps value scales the E max feedrate up by old/new
                self.now["M203"][3] *= values[3] / x
            values[i] = x
        if code == "M206":
            out.append(position())                                 # report_current_position
        return out

    def m220(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/config/M220.cpp: S sets feedrate_percentage; no parameter: ``FR:<n>%``."""
        s = _value(w, "S")
        if s is not None:
            self.feed_percent = int(s)
        return [] if w else [f"FR:{self.feed_percent}%"]

    def m221(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/config/M221.cpp: S sets the extruder's flow_percentage; without S:
        ``echo:E<n> Flow: <n>%``."""
        ok, out = self._extruder("M221", w)
        if not ok:
            return out
        s = _value(w, "S")
        if s is not None:
            self.flow_percent = int(s)
            return []
        return [f"echo:E0 Flow: {self.flow_percent}%"]

    def report(self, for_replay: bool = False) -> list[str]:
        """module/settings.cpp MarlinSettings::report (M503; S0: for replay, without the
        headings and the echo: prefix)."""
        tab = table()
        # M200_report: report_heading without its end, " (Disabled):" only when off
        filament = "Filament settings" + ("" if self.volumetric else " (Disabled)")
        groups = [("Linear Units", "  G21 ; (mm)"), ("Temperature Units", "  M149 C ; Units in "
                  "Celsius"), (filament, self.m200_line())]
        groups += [(tab.headings[c], report_line(c, self.now[c])) for c in ORDER]
        if for_replay:
            return [line for _, line in groups]
        out = []
        for heading, line in groups:
            colon = "" if heading == "Filament settings" else ":"
            out += [f"echo:; {heading}{colon}", f"echo:{line}"]
        return out

    def m200_line(self) -> str:
        return f"  M200 S{int(self.volumetric)} D{number(self.filament)}"

    def m200(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/config/M200-M205.cpp GcodeSuite::M200: no D, S or T: M200_report (the line
        alone); T past EXTRUDERS stops it; D<n> sets the diameter and turns volumetric on, D0
        turns it off; S (boolval) decides last."""
        if not any(k in w for k in "DST"):
            return [self.m200_line()]
        ok, out = self._extruder("M200", w)
        if not ok:
            return out
        enable, can = self.volumetric, True
        d = _value(w, "D")
        if d is not None:
            if d:
                self.filament, enable = d, True
            else:
                can = False
        self.volumetric = can and boolval(w, "S", enable)
        return []

    def m113(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/host/M113.cpp GcodeSuite::M113: S (value_byte, NOMORE 60) sets
        host_keepalive_interval (0: no busy: lines); no S: ``echo:M113 S<n>``."""
        s = _value(w, "S")
        if s is None:
            return [f"echo:M113 S{self.keepalive}"]
        self.keepalive = min(max(int(s), 0), 255, 60)
        return []

    def m85(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/control/M85.cpp GcodeSuite::M85: S<seconds> sets max_inactive_time (the kill
        when it runs out is not modelled); nothing printed."""
        if "S" in w:
            self.inactive_s = _value(w, "S") or 0.0
        return []

    def m120(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/control/M120_M121.cpp: endstops.enable_globally(true); nothing printed."""
        self.endstops_on = True
        return []

    def m121(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/control/M120_M121.cpp: endstops.enable_globally(false); nothing printed."""
        self.endstops_on = False
        return []

    def m211(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/control/M211.cpp GcodeSuite::M211: S sets soft_endstop._enabled and prints
        nothing; without S, M211_report(forReplay=true): ``  M211 S1 ; ON`` and the bounds
        in logical coordinates (asLogical: the M206 offset added), print_pos with two
        decimals."""
        if "S" in w:
            self.soft_endstops = boolval(w, "S", True)
            return []
        off = self.home_offset
        lo = " ".join(f"{a}{number(x + off[i])}" for i, (a, x) in enumerate(zip("XYZ", SOFT_MIN,
                                                                                 strict=True)))
        hi = " ".join(f"{a}{number(x + off[i])}" for i, (a, x) in enumerate(zip("XYZ", SOFT_MAX,
                                                                                 strict=True)))
        on = int(self.soft_endstops)
        return [f"  M211 S{on} ; {'ON' if on else 'OFF'}", f"  Min:  {lo}   Max:  {hi}"]

    def m302(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/config/M302.cpp GcodeSuite::M302: S sets extrude_min_temp (a celsius_t, a
        whole number); with S or P, cold extrusion is allowed when the minimum is 0 or P is
        true; neither: ``echo:Cold extrudes are enabled|disabled (min temp <n>C)``."""
        seen_s, seen_p = "S" in w, "P" in w
        if seen_s:
            self.cold_min = int(_value(w, "S") or 0)
        if seen_s or seen_p:
            self.cold_allowed = self.cold_min == 0 or (seen_p and boolval(w, "P", True))
            return []
        state = "en" if self.cold_allowed else "dis"
        return [f"echo:Cold extrudes are {state}abled (min temp {self.cold_min}C)"]

    def m303(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/temp/M303.cpp GcodeSuite::M303: E (default 0) names the heater: 0 (PIDTEMP,
        one hotend) or -1 (the bed, PIDTEMPBED); any other: ``PID Autotune failed! Bad heater
        id`` (SERIAL_ECHOLNPGM: no echo:) and nothing heats. The autotune itself
        (temperature.cpp PID_autotune) is not modelled: a valid M303 is answered ok alone."""
        e = _value(w, "E")
        heater = int(e) if e is not None else 0
        return [] if heater in (0, -1) else ["PID Autotune failed! Bad heater id"]

    def m575(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/config/M575.cpp GcodeSuite::M575 (BAUD_RATE_GCODE): B (shorthands 115 ->
        115200, 250 -> 250000 ...) one of the rates, P -99 or 0 (one serial port):
        ``echo: Serial 0 baud rate set to <b>`` and the port is opened again at that rate
        (the emulator's link keeps its own); another P: nothing; another rate:
        ``echo:?(B)aud rate implausible.``"""
        b = int(_value(w, "B") or 0)
        b = BAUD_SHORT.get(b, b)
        if b not in BAUDS:
            return ["echo:?(B)aud rate implausible."]
        p = _value(w, "P")
        port = int(p) if p is not None else -99
        return [f"echo: Serial 0 baud rate set to {b}"] if port in (-99, 0) else []

    def m503(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/eeprom/M500-M504.cpp GcodeSuite::M503: settings.report(!S)."""
        s = _value(w, "S")
        return self.report(for_replay=s is not None and s == 0)

    def _crc(self, stored: dict[str, list[float]]) -> int:
        blob = repr(sorted(stored.items())).encode()
        return zlib.crc32(blob) & 0xFFFF

    def m500(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """settings.cpp MarlinSettings::save: the settings written, ``echo:Settings Stored
        (<bytes> bytes; crc <crc>)`` (EEPROM_CHITCHAT)."""
        eeprom["settings"] = {k: list(x) for k, x in self.now.items()}
        eeprom["volumetric"] = (self.volumetric, self.filament)
        return [f"echo:Settings Stored ({table().stored_bytes} bytes; crc "
                f"{self._crc(eeprom['settings'])})"]

    def load(self, eeprom: dict[str, Any], *, validating: bool = False,
             announce: bool = True) -> list[str]:
        """settings.cpp MarlinSettings::_load: a stored layout of this version is taken
        (``echo:V88 stored settings retrieved (...)`` and, with EEPROM_CHITCHAT, the whole
        report); none: ``EEPROM version mismatch`` and the defaults (reset)."""
        tab = table()
        stored = eeprom.get("settings")
        if stored is None:
            out = [f"echo:EEPROM version mismatch (EEPROM=? Marlin={tab.version})"]
            return out + ([] if validating else self.reset())
        if validating:
            return ["echo:EEPROM OK"]
        self.now = {k: list(x) for k, x in stored.items()}
        self.volumetric, self.filament = eeprom.get("volumetric", (False, FILAMENT_DIA))
        out = [f"echo:{tab.version} stored settings retrieved ({tab.stored_bytes} bytes; crc "
               f"{self._crc(stored)})"]
        return out + (self.report() if announce else [])

    def reset(self) -> list[str]:
        """settings.cpp MarlinSettings::reset: every setting to its power-up value."""
        self.now = defaults(self.v)
        self.volumetric, self.filament = False, FILAMENT_DIA
        return ["echo:Hardcoded Default Settings Loaded"]

    def m501(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return self.load(eeprom)

    def m502(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        return self.reset()

    def m504(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """GcodeSuite::M504: settings.validate(), ``echo:EEPROM OK`` when it holds a layout."""
        return self.load(eeprom, validating=True)

    def m111(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/control/M111.cpp: S sets marlin_debug_flags; ``echo:DEBUG:`` and the names
        of the flags set (``off`` for none)."""
        s = _value(w, "S")
        if s is not None:
            self.debug = int(s) & 0xFF
        names = [n for i, n in enumerate(DEBUG_NAMES) if self.debug >> i & 1]
        return ["echo:DEBUG:" + (",".join(names) if self.debug else "off")]

    def m118(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/host/M118.cpp: up to three leading A1 (``//``), E1 (``echo:``), P<n> (the
        port) are taken off; the rest is printed."""
        rest = re.sub(r"^\s*M118\s*", "", text, flags=re.IGNORECASE)
        has_a = has_e = False
        for _ in range(3):
            if rest[:2] in ("A1", "E1") or (rest[:1] == "P" and rest[1:2].isdigit()):
                has_a |= rest[0] == "A"
                has_e |= rest[0] == "E"
                rest = rest[2:].lstrip(" ")
            else:
                break
        return [("echo:" if has_e else "") + ("//" if has_a else "") + rest]

    def m119(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """module/endstops.cpp Endstops::report_states: the configured min endstops."""
        return ["Reporting endstop status", "x_min: open", "y_min: open", "z_min: open"]

    def elapsed(self, t: float) -> float:
        return self.timer_total + (t - self.timer_start if self.timer_start is not None else 0)

    def m31(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/stats/M31.cpp: ``echo:Print time: `` and duration_t::toString."""
        s = int(self.elapsed(t))
        h, m, sec = s // 3600, s // 60 % 60, s % 60
        shown = f"{h}h {m}m {sec}s" if h else f"{m}m {sec}s" if m else f"{sec}s"
        return [f"echo:Print time: {shown}"]

    def m75(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """gcode/stats/M75-M78.cpp M75: print_job_timer.start() (libs/stopwatch.cpp
        Stopwatch::start: a stopped timer is reset first, so it counts from 0 again)."""
        if self.timer_start is None:
            self.timer_start, self.timer_total = t, 0.0
        return []

    def m77(self, w: dict[str, str], text: str, t: float, eeprom: dict[str, Any]) -> list[str]:
        """M77: print_job_timer.stop() (the time stays for M31)."""
        if self.timer_start is not None:
            self.timer_total, self.timer_start = self.elapsed(t), None
        return []
