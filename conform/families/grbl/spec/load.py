"""Load ``specs/grbl/*.toml`` into typed tables, validating every row.

A mistake in a table is one ``UserError`` line naming the file, the row and the field, so a
new grbl variant or a corrected code is a data change that either loads or says what is wrong.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from conform.errors import UserError
from conform.families import table_folder
from conform.families.rows import LineTables, Rows, read_table

SPEC_PACKAGE = "conform.families.grbl.spec"
FILES = ("variants", "codes", "settings", "protocol", "status", "examples")
SETTING_TYPES = ("int", "bool", "mask", "float")


@dataclass(frozen=True)
class Code:
    """One ``error:N`` or ``ALARM:N`` code."""

    number: int
    name: str
    meaning: str
    cite: str
    emulated: bool
    send: bytes | None = None         # a line that provokes the code (after ``setup``)
    setup: tuple[bytes, ...] = ()


def f32(x: float) -> float:
    """``x`` rounded to a C ``float`` (grbl keeps settings and coordinates in single
    precision)."""
    try:
        return float(struct.unpack("<f", struct.pack("<f", x))[0])
    except OverflowError:
        return math.copysign(math.inf, x)


def print_float(x: float, decimals: int) -> str:
    """print.c printFloat: the value scaled by 100 (then 10) in single precision, 0.5 added,
    truncated to an integer and its digits printed with the point put back: so 99999.9
    (stored as 99999.898) prints 99999.904 where a correct rounding gives 99999.900. The
    integer is a 32-bit one: what does not fit keeps its low 32 bits (x86's conversion of a
    float past a 64-bit long gives 0 there)."""
    n = f32(x)
    sign = "-" if n < 0 else ""
    n = -n if n < 0 else n
    d = decimals
    while d >= 2:
        n = f32(n * 100)
        d -= 2
    if d:
        n = f32(n * 10)
    n = f32(n + 0.5)
    a = int(n) & 0xFFFFFFFF if math.isfinite(n) and n < 2.0 ** 63 else 0   # (long)n
    digits = str(a) if a else ""
    digits = digits.rjust(decimals, "0")
    if len(digits) == decimals:
        digits = "0" + digits
    if not decimals:
        return sign + digits
    return f"{sign}{digits[:-decimals]}.{digits[-decimals:]}"


@dataclass(frozen=True)
class Setting:
    """One ``$x`` setting (per-axis settings are expanded: $100, $101, $102 ...)."""

    number: int
    name: str
    unit: str
    type: str
    lo: float
    hi: float
    default: float
    cite: str
    decimals: int = 3
    bits: int = 8
    below: int = 4      # the error for a value below ``lo`` (a negative one is always 4)
    needs: tuple[int, ...] = ()   # settings that must be 1 for a non-zero value ($20: $22)
    clears: tuple[int, ...] = ()  # settings a zero value turns off too ($22=0: $20)

    def text(self, value: float) -> str:
        """The value as ``$$`` prints it (a float as print.c printFloat rounds it)."""
        if self.type == "float":
            return print_float(value, self.decimals)
        return str(int(value))

    def coerce(self, value: float) -> float:
        """What grbl stores for ``value`` (floats in single precision, integers truncated,
        booleans 0/1)."""
        if self.type == "float":
            return f32(value)
        n = int(value) & 0xFF if self.bits <= 8 else int(value)   # settings.c: uint8 int_value
        if self.type == "bool":
            return 1 if n else 0
        return n & ((1 << self.bits) - 1)


@dataclass(frozen=True)
class Message:
    kind: str
    pattern: re.Pattern[str]
    answers: bool
    meaning: str
    cite: str


@dataclass(frozen=True)
class Realtime:
    byte: int
    name: str
    effect: str
    cite: str
    meaning: str = ""


@dataclass(frozen=True)
class Command:
    name: str
    syntax: re.Pattern[str]
    states: str
    prints: tuple[str, ...]
    meaning: str
    cite: str


@dataclass(frozen=True)
class Example:
    id: str
    send: bytes
    expect: tuple[str, ...]
    cite: str
    setup: tuple[bytes, ...] = ()
    power_up: bool = False


@dataclass(frozen=True)
class Variant:
    id: str
    title: str
    version: str
    build: str
    axes: tuple[str, ...]
    baud: int
    rx_buffer: int
    line_max: int
    planner_blocks: int
    status_refresh: dict[str, int]
    options: str
    tool_max: int
    line_number_max: int
    n_startup_lines: int
    coord_systems: int
    crlf_is_two_lines: bool
    cite: dict[str, str]
    build_options: dict[str, Any] = field(default_factory=dict)
    family: str = "grbl"

    def option(self, name: str) -> Any:
        """A config.h build option the variant assumes (``build_options``): its value, or
        False when the table leaves it out (commented out in config.h)."""
        return self.build_options.get(name, False)

    @property
    def banner(self) -> str:
        return f"Grbl {self.version} ['$' for help]"


@dataclass
class GrblSpec(LineTables):
    """Every grbl table."""

    root: Path
    variants: dict[str, Variant]
    errors: dict[int, Code]
    alarms: dict[int, Code]
    settings: dict[int, Setting]
    messages: dict[str, Message]
    realtime: dict[int, Realtime]
    overrides: dict[str, Any]
    commands: dict[str, Command]
    status: dict[str, Any]
    examples: list[Example] = field(default_factory=list)

    family_name = "grbl"

    def variant(self, vid: str) -> Variant:
        return LineTables.variant(self, vid)


def _read(root: Path, name: str) -> tuple[Rows, dict[str, Any]]:
    return read_table(root, name)


def _codes(rows: Rows, data: dict[str, Any], section: str) -> dict[int, Code]:
    out = {}
    for key, d in data.get(section, {}).items():
        row = f"{section}.{key}"
        if not key.isdigit():
            raise rows.fail(row, "the code must be a number")
        send = rows.get(row, d, "send", str, None)
        setup = rows.get(row, d, "setup", list, [])
        if not all(isinstance(x, str) for x in setup):
            raise rows.fail(row, "field 'setup': every entry must be a string")
        out[int(key)] = Code(int(key), rows.get(row, d, "name", str), rows.get(row, d, "meaning", str),
                             rows.get(row, d, "cite", str), rows.get(row, d, "emulated", bool),
                             send.encode("latin-1") if send is not None else None,
                             tuple(x.encode("latin-1") for x in setup))
    return dict(sorted(out.items()))


def _setting(rows: Rows, row: str, number: int, d: dict[str, Any], prefix: str = "") -> Setting:
    kind = rows.get(row, d, "type", str)
    if kind not in SETTING_TYPES:
        raise rows.fail(row, f"field 'type': {kind!r} is not one of {', '.join(SETTING_TYPES)}")
    num = (int, float)
    lo, hi = rows.get(row, d, "lo", num), rows.get(row, d, "hi", num)
    default = rows.get(row, d, "default", num)
    if not lo <= hi:
        raise rows.fail(row, f"lo {lo} is above hi {hi}")
    if not (lo <= default <= hi):
        raise rows.fail(row, f"default {default} is outside {lo}..{hi}")
    return Setting(number, prefix + rows.get(row, d, "name", str), rows.get(row, d, "unit", str),
                   kind, float(lo), float(hi), float(default), rows.get(row, d, "cite", str),
                   int(rows.get(row, d, "decimals", int, 3)), int(rows.get(row, d, "bits", int, 8)),
                   int(rows.get(row, d, "below", int, 4)),
                   tuple(int(x) for x in rows.get(row, d, "needs", list, [])),
                   tuple(int(x) for x in rows.get(row, d, "clears", list, [])))


def _settings(rows: Rows, data: dict[str, Any], axes: tuple[str, ...]) -> dict[int, Setting]:
    out: dict[int, Setting] = {}
    for key, d in data.get("setting", {}).items():
        if not key.isdigit():
            raise rows.fail(f"setting.{key}", "the setting number must be a number")
        out[int(key)] = _setting(rows, f"setting.{key}", int(key), d)
    for key, d in data.get("axis_setting", {}).items():
        if not key.isdigit():
            raise rows.fail(f"axis_setting.{key}", "the setting number must be a number")
        for i, axis in enumerate(axes):
            out[int(key) + i] = _setting(rows, f"axis_setting.{key}", int(key) + i, d, f"{axis}-axis ")
    return dict(sorted(out.items()))


def _variant(rows: Rows, vid: str, d: dict[str, Any]) -> Variant:
    row = f'variant."{vid}"'
    g = rows.get
    refresh = g(row, d, "status_refresh", dict)
    for k in ("wco_idle", "wco_busy", "ovr_idle", "ovr_busy"):
        if not isinstance(refresh.get(k), int) or not 1 <= refresh[k] <= 255:
            raise rows.fail(row, f"status_refresh.{k}: expected 1..255")
    v = Variant(vid, g(row, d, "title", str), g(row, d, "version", str), g(row, d, "build", str),
                tuple(g(row, d, "axes", list)), g(row, d, "baud", int), g(row, d, "rx_buffer", int),
                g(row, d, "line_max", int), g(row, d, "planner_blocks", int), dict(refresh),
                g(row, d, "options", str), g(row, d, "tool_max", int),
                g(row, d, "line_number_max", int), g(row, d, "n_startup_lines", int),
                g(row, d, "coord_systems", int), g(row, d, "crlf_is_two_lines", bool),
                dict(g(row, d, "cite", dict, {})), dict(g(row, d, "build_options", dict, {})))
    for key, value in v.build_options.items():
        if not isinstance(value, (bool, int)) or not key.isupper():
            raise rows.fail(row, f"build_options.{key}: expected a config.h NAME = true/false/number")
    for name in ("rx_buffer", "line_max", "planner_blocks", "baud"):
        if getattr(v, name) <= 0:
            raise rows.fail(row, f"field {name!r} must be positive")
    if v.line_max >= v.rx_buffer:
        raise rows.fail(row, "line_max must be below rx_buffer")
    return v


def _unescape_key(rows: Rows, row: str, key: str) -> int:
    try:
        b = int(key, 16)
    except ValueError:
        raise rows.fail(row, "the key must be a byte such as 0x3F") from None
    if not 0 <= b <= 255:
        raise rows.fail(row, "the byte must be within 0x00..0xFF")
    return b


def load_grbl(root: str | Path | None = None) -> GrblSpec:
    """Load and validate the grbl tables (cached for the default folder)."""
    if root is None:
        return _load_default()
    return _load(Path(root))


def spec_dir() -> Path:
    """``$CONFORM_SPECS/grbl/`` when it exists, else the tables shipped in the package."""
    return table_folder("grbl", SPEC_PACKAGE)


def _load_default() -> GrblSpec:
    return _load_cached(spec_dir())


@lru_cache(maxsize=4)
def _load_cached(root: Path) -> GrblSpec:
    return _load(root)


def _load(root: Path) -> GrblSpec:
    parts = {name: _read(root, name) for name in FILES}
    rows, data = parts["variants"]
    variants = {vid: _variant(rows, vid, d) for vid, d in data.get("variant", {}).items()}
    if not variants:
        raise UserError(f"{rows.path}: no [variant.<id>] table")
    axes = next(iter(variants.values())).axes

    rows, data = parts["codes"]
    errors, alarms = _codes(rows, data, "error"), _codes(rows, data, "alarm")
    rows, data = parts["settings"]
    settings = _settings(rows, data, axes)

    rows, data = parts["protocol"]
    messages = {}
    for kind, d in data.get("message", {}).items():
        row = f"message.{kind}"
        messages[kind] = Message(kind, rows.regex(row, rows.get(row, d, "pattern", str)),
                                 rows.get(row, d, "answers", bool), rows.get(row, d, "meaning", str),
                                 rows.get(row, d, "cite", str))
    realtime = {}
    for key, d in data.get("realtime", {}).items():
        row = f'realtime."{key}"'
        b = _unescape_key(rows, row, key)
        realtime[b] = Realtime(b, rows.get(row, d, "name", str), rows.get(row, d, "effect", str),
                               rows.get(row, d, "cite", str), rows.get(row, d, "meaning", str, ""))
    commands = {}
    for name, d in data.get("command", {}).items():
        row = f'command."{name}"'
        commands[name] = Command(name, rows.regex(row, rows.get(row, d, "syntax", str)),
                                 rows.get(row, d, "states", str),
                                 tuple(rows.get(row, d, "prints", list)),
                                 rows.get(row, d, "meaning", str), rows.get(row, d, "cite", str))
        unknown = [p for p in commands[name].prints if p not in messages]
        if unknown:
            raise rows.fail(row, f"prints {unknown[0]!r}: no such message kind")
    overrides = dict(data.get("override", {}))

    rows, status = parts["status"]
    for st in ("state", "field", "mask"):
        if st not in status:
            raise rows.fail(st, "table is missing")

    rows, data = parts["examples"]
    examples = []
    for i, d in enumerate(data.get("example", [])):
        row = f"example #{i + 1}"
        expect = rows.get(row, d, "expect", list)
        if not all(isinstance(x, str) for x in expect):
            raise rows.fail(row, "field 'expect': every entry must be a string")
        setup = rows.get(row, d, "setup", list, [])
        examples.append(Example(rows.get(row, d, "id", str),
                                rows.get(row, d, "send", str).encode("latin-1"), tuple(expect),
                                rows.get(row, d, "cite", str),
                                tuple(str(s).encode("latin-1") for s in setup),
                                rows.get(row, d, "power_up", bool, False)))
    return GrblSpec(root, variants, errors, alarms, settings, messages, realtime, overrides,
                    commands, status, examples)
