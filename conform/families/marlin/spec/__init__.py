"""Marlin's tables (``specs/marlin/*.toml``), loaded and validated: a bad row is one
``UserError`` line naming the file, the row and the field.

Variants are deltas on one base, as GVE's are: a variant with ``base = "..."`` takes every
field of its base and overrides what it names (``options`` merged switch by switch).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from conform.errors import UserError
from conform.families import table_folder
from conform.families.rows import LineTables, Rows, read_table

FILES = ("variants", "messages", "commands", "caps")
KINDS = ("move", "dwell", "sync", "home", "report_temp", "report_pos", "firmware",
         "autoreport_temp", "autoreport_pos", "line_no", "halt", "quickstop", "break_wait",
         "set_temp", "wait_temp", "set", "position", "eeprom", "host_prompt", "user_wait", "settings",
         "home_offset_here", "restart")
_NUMBERS = ("baud", "bufsize", "max_cmd_size", "rx_buffer", "block_buffer", "keepalive",
            "extruders", "temp_residency", "temp_bed_residency", "temp_window", "first_home_ms",
            "motion_time_pct")
_TEXTS = ("title", "firmware", "machine_name", "uuid", "protocol_version", "source_url")


@dataclass(frozen=True)
class Variant:
    id: str
    title: str
    firmware: str
    baud: int
    bufsize: int
    max_cmd_size: int
    rx_buffer: int
    block_buffer: int
    keepalive: int
    extruders: int
    temp_residency: int
    temp_bed_residency: int
    temp_window: int
    first_home_ms: int
    motion_time_pct: int
    steps_per_mm: tuple[float, ...]
    max_feedrate: tuple[float, ...]
    machine_name: str
    uuid: str
    protocol_version: str
    source_url: str
    options: dict[str, bool]
    cite: dict[str, str]
    base: str | None = None

    def on(self, option: str) -> bool:
        return bool(self.options.get(option, False))

    @property
    def planner_blocks(self) -> int:
        """Blocks the planner holds (planner.h: one slot of the ring stays empty)."""
        return self.block_buffer - 1


@dataclass(frozen=True)
class Message:
    kind: str
    pattern: re.Pattern[str]
    answers: bool
    error: bool
    cite: str


@dataclass(frozen=True)
class Command:
    code: str
    kind: str
    cite: str
    motion: bool = False
    heat: bool = False
    option: str | None = None


@dataclass(frozen=True)
class Cap:
    name: str
    option: str | None
    negate: bool
    always: bool

    def value(self, v: Variant) -> int:
        if self.always or self.option is None:
            return 1
        return int(v.on(self.option) != self.negate)


@dataclass
class MarlinSpec(LineTables):
    root: Path
    variants: dict[str, Variant]
    messages: dict[str, Message]
    commands: dict[str, Command]
    caps: list[Cap]

    family_name = "marlin"

    def variant(self, vid: str) -> Variant:
        return LineTables.variant(self, vid)

    def command(self, code: str, v: Variant) -> Command | None:
        """The command ``code`` (``G1``, ``M105``) when the variant has it."""
        c = self.commands.get(code)
        if c is None or (c.option and not v.on(c.option)):
            return None
        return c


def _read(root: Path, name: str) -> tuple[Rows, dict[str, Any]]:
    return read_table(root, name, ", ".join(f"{f}.toml" for f in FILES))


def _variants(root: Path) -> dict[str, Variant]:
    rows, data = _read(root, "variants")
    raw = data.get("variant")
    if not isinstance(raw, dict) or not raw:
        raise UserError(f"{rows.path}: no [variant.<id>] table")
    out: dict[str, Variant] = {}

    def build(vid: str, seen: tuple[str, ...] = ()) -> Variant:
        if vid in out:
            return out[vid]
        row = f"variant.{vid}"
        d = raw[vid]
        if not isinstance(d, dict):
            raise rows.fail(row, "is not a table")
        fields: dict[str, Any] = {}
        base_id = rows.get(row, d, "base", str, None)
        if base_id is not None:
            if base_id not in raw:
                raise rows.fail(row, f"field 'base': no variant {base_id!r}")
            if base_id in seen:
                raise rows.fail(row, f"field 'base': {' -> '.join((*seen, vid))} is a cycle")
            b = build(base_id, (*seen, vid))
            fields = {k: getattr(b, k) for k in (*_NUMBERS, *_TEXTS, "steps_per_mm", "max_feedrate")}
            fields["options"], fields["cite"] = dict(b.options), dict(b.cite)
        else:
            fields["options"], fields["cite"] = {}, {}
        for key in _NUMBERS:
            if base_id is None or key in d:
                fields[key] = rows.get(row, d, key, int)
                if fields[key] < 0:
                    raise rows.fail(row, f"field {key!r}: must not be negative")
        for key in _TEXTS:
            if base_id is None or key in d:
                fields[key] = rows.get(row, d, key, str)
        for key in ("steps_per_mm", "max_feedrate"):
            if base_id is None or key in d:
                seq = rows.get(row, d, key, list)
                if len(seq) != 4 or not all(isinstance(x, int | float) and not isinstance(x, bool)
                                            and x > 0 for x in seq):
                    raise rows.fail(row, f"field {key!r}: expected 4 positive numbers (X Y Z E)")
                fields[key] = tuple(float(x) for x in seq)
        for key, value in rows.get(row, d, "options", dict, {}).items():
            if not isinstance(value, bool):
                raise rows.fail(row, f"options.{key}: expected true or false, got {value!r}")
            fields["options"][key] = value
        for key, value in rows.get(row, d, "cite", dict, {}).items():
            if not isinstance(value, str) or not value.strip():
                raise rows.fail(row, f"cite.{key}: expected a citation")
            fields["cite"][key] = value
        if base_id is None:
            missing = [k for k in (*_NUMBERS, "options") if k not in fields["cite"]]
            if missing:
                raise rows.fail(row, f"no citation for {', '.join(missing)}")
        if fields["bufsize"] < 1 or fields["max_cmd_size"] < 8 or fields["block_buffer"] < 2:
            raise rows.fail(row, "bufsize >= 1, max_cmd_size >= 8 and block_buffer >= 2")
        v = Variant(id=vid, base=base_id, **fields)
        out[vid] = v
        return v

    for vid in raw:
        build(vid)
    return {vid: out[vid] for vid in raw}


def _messages(root: Path) -> dict[str, Message]:
    rows, data = _read(root, "messages")
    out = {}
    for kind, d in data.get("message", {}).items():
        row = f"message.{kind}"
        text = rows.get(row, d, "pattern", str)
        try:
            pattern = re.compile(text)
        except re.error as exc:
            raise rows.fail(row, f"pattern {text!r}: {exc}") from None
        out[kind] = Message(kind, pattern, rows.get(row, d, "answers", bool, False),
                            rows.get(row, d, "error", bool, False), rows.get(row, d, "cite", str))
    if not out:
        raise UserError(f"{rows.path}: no [message.<kind>] rows")
    return out


def _commands(root: Path) -> dict[str, Command]:
    rows, data = _read(root, "commands")
    out = {}
    for code, d in data.get("command", {}).items():
        row = f"command.{code}"
        if not re.fullmatch(r"[GMT]\d+", code):
            raise rows.fail(row, "a command is G, M or T and a number")
        kind = rows.get(row, d, "kind", str)
        if kind not in KINDS:
            raise rows.fail(row, f"field 'kind': {kind!r} is not one of {', '.join(KINDS)}")
        out[code] = Command(code, kind, rows.get(row, d, "cite", str),
                            rows.get(row, d, "motion", bool, False),
                            rows.get(row, d, "heat", bool, False),
                            rows.get(row, d, "option", str, None))
    return out


def _caps(root: Path) -> list[Cap]:
    rows, data = _read(root, "caps")
    out = []
    for name, d in data.get("cap", {}).items():
        row = f"cap.{name}"
        always = rows.get(row, d, "always", bool, False)
        option = rows.get(row, d, "option", str, None)
        if option is None and not always:
            raise rows.fail(row, "needs 'option' (or always = true)")
        out.append(Cap(name, option, rows.get(row, d, "negate", bool, False), always))
    return out


@lru_cache(maxsize=4)
def _load(root: str) -> MarlinSpec:
    p = Path(root)
    return MarlinSpec(p, _variants(p), _messages(p), _commands(p), _caps(p))


def load_marlin(root: str | None = None) -> MarlinSpec:
    """Marlin's tables (``$CONFORM_SPECS/marlin`` when set, else the shipped ones)."""
    folder = Path(root) if root else table_folder("marlin", __name__)
    if not folder.is_dir():
        raise UserError(f"{folder}: no such folder of marlin tables")
    return _load(str(folder))


def diff(a: Variant, b: Variant) -> list[tuple[str, str, str, str]]:
    """What differs from variant ``a`` to ``b``: (what, a's value, b's value, b's citation)."""
    out = []
    for key in (*_NUMBERS, *_TEXTS[1:], "steps_per_mm", "max_feedrate"):
        if getattr(a, key) != getattr(b, key):
            out.append((key, str(getattr(a, key)), str(getattr(b, key)), b.cite.get(key, "")))
    for opt in sorted(set(a.options) | set(b.options)):
        if a.on(opt) != b.on(opt):
            out.append((f"option {opt}", str(a.on(opt)).lower(), str(b.on(opt)).lower(),
                        b.cite.get("options", "")))
    return out
