"""What the Marlin reference unit keeps between commands besides motion and heat: the
settings a host sets and reads back (M92, M201, M203, M204, M205, M206, M301, M304, M220,
M221), the settings report (M503), the EEPROM (M500, M501, M502, M504), tools (T<n>),
messages (M117, M118), debug flags (M111), the print timer (M31, M75, M77) and the endstop
report (M119).

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

    def __post_init__(self) -> None:
        if not self.now:
            self.now = defaults(self.v)

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
        groups = [("Linear Units", "  G21 ; (mm)"), ("Temperature Units", "  M149 C ; Units in "
                  "Celsius"), ("Filament settings (Disabled)", "  M200 S0 D1.75")]
        groups += [(tab.headings[c], report_line(c, self.now[c])) for c in ORDER]
        if for_replay:
            return [line for _, line in groups]
        out = []
        for heading, line in groups:
            out += [f"echo:; {heading}:", f"echo:{line}"]
        return out

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
        out = [f"echo:{tab.version} stored settings retrieved ({tab.stored_bytes} bytes; crc "
               f"{self._crc(stored)})"]
        return out + (self.report() if announce else [])

    def reset(self) -> list[str]:
        """settings.cpp MarlinSettings::reset: every setting to its power-up value."""
        self.now = defaults(self.v)
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
