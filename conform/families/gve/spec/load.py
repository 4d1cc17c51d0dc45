"""Load ``specs/gve/*.toml`` into the typed model, validating every row."""

from __future__ import annotations

import math
import re
import tomllib
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import Any

from conform.errors import UserError, read_user_text
from conform.families import table_folder
from conform.families.gve.spec.model import (
    ANSWER_RADIXES,
    PARAM_KINDS,
    AnswerField,
    CommandSpec,
    EepromCell,
    EepromMap,
    ErrorCode,
    Example,
    ParamSpec,
    Question,
    Spec,
    StatusBit,
    StatusTable,
    StatusWord,
    Variant,
)
from conform.families.gve.spec.schema import Row, SpecError, each, key_line

FILES = ("commands", "errors", "status", "eeprom", "variants", "questions", "examples")
FAMILIES = (
    "identify", "vector", "modal", "exchange", "position", "reference", "mpg", "queue",
    "eeprom", "io", "status", "recovery", "reset", "checksum", "packet", "spindle",
)


def default_root() -> Path:
    """``$CONFORM_SPECS/gve/`` when it exists, else the tables shipped in this package."""
    return table_folder("gve", __package__)


def load_spec(root: str | Path | None = None) -> Spec:
    """Load and validate the tables (cached per folder)."""
    return _load(Path(root) if root is not None else default_root())


MAX_TABLE_BYTES = 2 << 20
"""The tables are a few dozen kB; a file past 2 MB is refused before it is read."""


def _read_table(path: Path) -> tuple[Path, str, dict[str, Any]]:
    """(path, text, data) of one table file; every way it can fail is one SpecError line."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise SpecError(f"{path}: missing table file") from None
    except OSError as exc:
        raise SpecError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if path.is_file() and size > MAX_TABLE_BYTES:
        raise SpecError(f"{path.name}: {size:,} bytes; a table file is at most {MAX_TABLE_BYTES:,}")
    try:
        text = read_user_text(path)
    except UserError as exc:
        raise SpecError(str(exc)) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path.name}: {exc}") from None
    except RecursionError:
        line = _first_line(text, re.compile(r"[\[{]{50}"))
        raise SpecError(f"{path.name}:{line}: nested too deeply" if line else
                        f"{path.name}: nested too deeply") from None
    except ValueError as exc:  # an integer of more than 4 300 digits
        line = _first_line(text, re.compile(r"[0-9_]{4000}"))
        raise SpecError(f"{path.name}:{line}: {exc}".split("; use sys")[0] if line else
                        f"{path.name}: {exc}") from None
    return path, text, data


def _first_line(text: str, pattern: re.Pattern[str]) -> int | None:
    m = pattern.search(text)
    return text.count("\n", 0, m.start()) + 1 if m else None


@lru_cache(maxsize=8)
def _load(root: Path) -> Spec:
    if not root.is_dir():
        raise SpecError(f"spec folder not found: {root}")
    docs = {name: _read_table(root / f"{name}.toml") for name in FILES}
    questions = _questions(*docs["questions"])
    commands = _commands(*docs["commands"], questions)
    errors, inta_bit = _errors(*docs["errors"], commands)
    status = _status(*docs["status"])
    eeprom_maps = _eeprom(*docs["eeprom"])
    variants = _variants(*docs["variants"], commands, eeprom_maps, status)
    examples = _examples(*docs["examples"])
    return Spec(
        root=root,
        commands=MappingProxyType(commands),
        errors=MappingProxyType(errors),
        inta_bit=inta_bit,
        status=status,
        eeprom_maps=MappingProxyType(eeprom_maps),
        variants=MappingProxyType(variants),
        questions=MappingProxyType(questions),
        examples=examples,
    )


INT_LO, INT_HI = -(1 << 31), (1 << 32) - 1
"""Integer bounds fit the protocol's widest fields (32 bits, signed or unsigned)."""
FLOAT_MAX = 3.4028234663852886e38
"""Float bounds fit a float32 (the EEPROM's floats, GVE64 §13.5.11)."""
INTEGER_KINDS = ("int", "uint", "hex")


def _bounds(row: Row, field_name: str, rng: Any, kind: str | None = None) -> tuple[Any, Any]:
    """A ``[lo, hi]`` range: finite numbers that fit the protocol's fields, lo <= hi; integers
    for an integer parameter (``kind``), not negative for an unsigned one."""
    if (not isinstance(rng, list) or len(rng) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in rng)):
        row.fail(field_name, f"expected [lo, hi], got {rng!r}")
    for v in rng:
        if isinstance(v, float) and not math.isfinite(v):
            row.fail(field_name, f"{v!r} is not a finite number")
        if isinstance(v, int) and not INT_LO <= v <= INT_HI:
            row.fail(field_name, f"{v} does not fit a 32-bit field ({INT_LO}..{INT_HI})")
        if isinstance(v, float) and abs(v) > FLOAT_MAX:
            row.fail(field_name, f"{v!r} does not fit a float32")
    lo, hi = rng
    if lo > hi:
        row.fail(field_name, f"expected [lo, hi] with lo <= hi, got {rng!r}")
    if kind in INTEGER_KINDS and not all(isinstance(v, int) for v in rng):
        row.fail(field_name, f"a {kind} parameter needs integer bounds, got {rng!r}")
    if kind in ("uint", "hex") and lo < 0:
        row.fail(field_name, f"a {kind} parameter cannot go below 0, got {rng!r}")
    return lo, hi


def _int_in(row: Row, field_name: str, value: Any, lo: int, hi: int, why: str) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
        row.fail(field_name, f"expected an integer {lo}..{hi} ({why}), got {value!r}")


def _label(data: dict) -> str:
    return repr(data.get("id", data.get("code", data.get("index", data.get("name", "?")))))


# --- commands ---------------------------------------------------------------------------------

COMMAND_KEYS = {
    "id", "mnemonic", "addresses", "family", "params", "answer", "modal", "while_running",
    "motion", "effect", "clause", "questions", "answer_within",
}
ANSWER_WITHIN_MAX = 600.0  # seconds; W's longest reference move answers well inside this
PARAM_KEYS = {"name", "kind", "range", "choices", "sep", "per_axis", "min_count"}
ANSWER_KEYS = {"name", "radix", "width", "per_axis"}


def _commands(path: Path, text: str, data: dict, questions: dict[str, Question]) -> dict[str, CommandSpec]:
    out: dict[str, CommandSpec] = {}
    for row in each(data.get("command"), path, text, "command", _label):
        row.check_keys(COMMAND_KEYS)
        cid = row.get("id", str)
        if cid in out:
            row.fail("id", f"duplicate command id {cid!r}")
        mnemonic = row.get("mnemonic", str)
        if not mnemonic:
            row.fail("mnemonic", "empty")
        addresses = row.int_list("addresses")
        if not addresses or any(not 0 <= a <= 9 for a in addresses):
            row.fail("addresses", "expected one or more addresses 0..9")
        family = row.choice("family", FAMILIES)
        params = []
        for i, raw in enumerate(row.get("params", list)):
            prow = row.sub(raw, f"params[{i}]")
            prow.check_keys(PARAM_KEYS)
            kind = prow.choice("kind", PARAM_KINDS)
            rng = prow.get("range", (str, list), None)
            range_name = lo = hi = None
            if isinstance(rng, str):
                range_name = rng
            elif isinstance(rng, list):
                lo, hi = _bounds(prow, "range", rng, kind)
            choices = prow.str_list("choices", ())
            if kind == "sign" and not choices:
                prow.fail("choices", "a sign parameter needs its choices")
            if kind in ("int", "uint", "hex", "float") and rng is None:
                prow.fail("range", f"a {kind} parameter needs a range")
            per_axis = prow.get("per_axis", bool, False)
            min_count = prow.get("min_count", int, None)
            if min_count is not None and not per_axis:
                prow.fail("min_count", "only per_axis parameters take min_count")
            if min_count is not None and min_count < 1:
                prow.fail("min_count", f"must be at least 1, got {min_count}")
            params.append(ParamSpec(
                name=prow.get("name", str), kind=kind, range_name=range_name, lo=lo, hi=hi,
                choices=choices, sep=prow.get("sep", str, "" if i == 0 else ","),
                per_axis=per_axis, min_count=min_count,
            ))
        answer = []
        for i, raw in enumerate(row.get("answer", list, [])):
            arow = row.sub(raw, f"answer[{i}]")
            arow.check_keys(ANSWER_KEYS)
            width = arow.get("width", int, None)
            if width is not None:
                _int_in(arow, "width", width, 1, 64, "characters of one answer field")
            answer.append(AnswerField(arow.get("name", str), arow.choice("radix", ANSWER_RADIXES),
                                      width))
        qs = row.str_list("questions", ())
        for q in qs:
            if q not in questions:
                row.fail("questions", f"unknown open question {q!r}")
        within = row.get("answer_within", (int, float), 0.5)
        if not math.isfinite(within) or not 0 < within <= ANSWER_WITHIN_MAX:
            row.fail("answer_within", f"expected seconds in (0, {ANSWER_WITHIN_MAX:g}], got {within!r}")
        out[cid] = CommandSpec(
            id=cid, mnemonic=mnemonic, addresses=addresses, family=family, params=tuple(params),
            answer=tuple(answer), modal=row.get("modal", bool, False),
            while_running=row.get("while_running", bool, True), motion=row.get("motion", bool, False),
            effect=row.get("effect", str), clauses=row.clauses(), questions=qs,
            answer_within=float(within),
        )
    return out


# --- errors, status, eeprom -------------------------------------------------------------------

def _errors(path: Path, text: str, data: dict, commands: dict[str, CommandSpec]) -> tuple[dict[int, ErrorCode], int]:
    top = Row(data, path, "top level", None)
    inta_bit = top.get("inta_bit", int)
    _int_in(top, "inta_bit", inta_bit, 0, 3, "a bit of the answer digit")
    out: dict[int, ErrorCode] = {}
    for row in each(data.get("error"), path, text, "error", _label):
        row.check_keys({"code", "name", "meaning", "clause", "raised_by"})
        code = row.get("code", int)
        raised_by = row.str_list("raised_by")
        for cid in raised_by:
            if cid != "*" and cid not in commands:
                row.fail("raised_by", f"unknown command {cid!r}")
        if not 0 <= code <= 7:
            row.fail("code", "error codes are 3 bits (0..7)")
        if code in out:
            row.fail("code", f"duplicate code {code}")
        out[code] = ErrorCode(code, row.get("name", str), row.get("meaning", str), row.clauses(), raised_by)
    missing = set(range(8)) - set(out)
    if missing:
        raise SpecError(f"{path.name}: error codes missing: {sorted(missing)}")
    return out, inta_bit


def _status(path: Path, text: str, data: dict) -> StatusTable:
    top = Row(data, path, "top level", None)
    words = {}
    for row in each(data.get("word"), path, text, "word", _label):
        row.check_keys({"index", "name", "role", "inputs", "meaning", "clause"})
        idx = row.get("index", int)
        _int_in(row, "index", idx, 0, 6, "ST0..ST6")
        words[idx] = StatusWord(idx, row.get("name", str),
                                row.choice("role", ("enable", "polarity", "cause", "system")),
                                row.get("inputs", str), row.get("meaning", str), row.clauses())
    bits = {}
    for row in each(data.get("st6_bit"), path, text, "st6_bit", _label):
        row.check_keys({"bit", "name", "meaning", "clause"})
        bit = row.get("bit", int)
        if not 0 <= bit <= 7:
            row.fail("bit", "bits are 0..7")
        name = row.get("name", str)
        bits[name] = StatusBit(bit, name, row.get("meaning", str), row.clauses())
    for needed in ("STOP", "FREE", "INTCOM", "RUN", "INTA"):
        if needed not in bits:
            raise SpecError(f"{path.name}: st6_bit {needed} missing")
    run_inta = []
    for row in each(data.get("run_inta"), path, text, "run_inta", lambda d: f"{d.get('run')}/{d.get('inta')}"):
        run_inta.append((row.get("run", int), row.get("inta", int), row.get("meaning", str)))
    queue_full_bit = top.get("queue_full_bit", int)
    _int_in(top, "queue_full_bit", queue_full_bit, 0, 7, "a bit of F's answer")
    return StatusTable(MappingProxyType(words), MappingProxyType(bits), queue_full_bit,
                       tuple(run_inta))


def _eeprom(path: Path, text: str, data: dict) -> dict[str, EepromMap]:
    top = Row(data, path, "top level", None)
    blank = top.get("blank", int)
    value_sets: dict[str, dict[str, str]] = {}
    for name, raw in top.get("values", dict, {}).items():
        vrow = Row(raw, path, f"values.{name}", key_line(text, f"values.{name}"))
        vrow.clauses()
        value_sets[name] = {k: v for k, v in raw.items() if k != "clause"}
    cells: dict[str, dict[int, EepromCell]] = {}
    for row in each(data.get("cell"), path, text, "cell", lambda d: f"{d.get('map')}:{d.get('address')}"):
        row.check_keys({"map", "address", "name", "type", "default", "default_from", "values",
                        "range", "clause"})
        ctype = row.choice("type", ("byte", "float", "uint32"))
        address = row.get("address", int)
        size = 1 if ctype == "byte" else 4
        if not 0 <= address <= 256 - size:
            row.fail("address", f"0x{address:X} does not fit a {ctype} in 256 bytes")
        default = row.get("default", (int, float))
        if ctype == "byte" and not (isinstance(default, int) and 0 <= default <= 255):
            row.fail("default", f"a byte default must be 0..255, got {default!r}")
        if ctype == "uint32":
            _int_in(row, "default", default, 0, (1 << 32) - 1, "a uint32")
        if ctype == "float" and (not math.isfinite(default) or abs(default) > FLOAT_MAX):
            row.fail("default", f"{default!r} is not a finite float32")
        values = row.get("values", str, None)
        if values is not None and values not in value_sets:
            row.fail("values", f"unknown value set {values!r}")
        rng = row.get("range", list, None)
        if rng is not None:
            _bounds(row, "range", rng)
        cmap = cells.setdefault(row.get("map", str), {})
        if address in cmap:
            row.fail("address", f"duplicate cell 0x{address:02X}")
        cmap[address] = EepromCell(
            address=address, name=row.get("name", str), type=ctype, default=default,
            default_from=row.get("default_from", str),
            values=MappingProxyType(value_sets.get(values or "", {})),
            range=tuple(rng) if rng else None, clauses=row.clauses(),
        )
    return {name: EepromMap(name, MappingProxyType(c), blank) for name, c in cells.items()}


# --- variants ---------------------------------------------------------------------------------

VARIANT_KEYS = {
    "base", "title", "manual", "firmware", "processor_id", "axes", "queue", "max_rate", "bauds",
    "default_baud", "addresses", "status_words", "input_bits", "eeprom_map", "commands",
    "add_commands", "remove_commands", "ranges", "reset", "cite", "step_polarity_configurable",
}
INHERITED = ("title", "manual", "firmware", "processor_id", "axes", "queue", "max_rate", "bauds",
             "default_baud", "addresses", "status_words", "input_bits", "eeprom_map",
             "step_polarity_configurable")


def _variants(path: Path, text: str, data: dict, commands: dict[str, CommandSpec],
              eeprom_maps: dict[str, EepromMap], status: StatusTable) -> dict[str, Variant]:
    raw_all = Row(data, path, "top level", None).get("variant", dict)
    flat: dict[str, dict[str, Any]] = {}

    def resolve(vid: str, chain: tuple[str, ...] = ()) -> dict[str, Any]:
        if vid in flat:
            return flat[vid]
        row = Row(raw_all[vid], path, f"variant {vid!r}", key_line(text, f"variant.{vid}"))
        row.check_keys(VARIANT_KEYS)
        base_id = row.get("base", str, None)
        if base_id is not None:
            if base_id not in raw_all:
                row.fail("base", f"unknown base variant {base_id!r}")
            if base_id in chain:
                row.fail("base", f"circular base chain {' -> '.join((*chain, vid, base_id))}")
            if len(chain) >= MAX_BASE_CHAIN:
                row.fail("base", f"base chain deeper than {MAX_BASE_CHAIN} variants")
            merged = dict(resolve(base_id, (*chain, vid)))
            merged["commands"] = list(merged["commands"])
            if "commands" in row.data:
                row.fail("commands", "a variant with a base lists add_commands/remove_commands")
        else:
            merged = {"commands": list(row.str_list("commands")), "ranges": {}, "reset": {}, "cite": {}}
        for key in INHERITED:
            if key in row.data:
                merged[key] = row.data[key]
        for cid in row.str_list("add_commands", ()):
            if cid not in commands:
                row.fail("add_commands", f"unknown command {cid!r}")
            if cid in merged["commands"]:
                row.fail("add_commands", f"{cid!r} is already in the base")
            merged["commands"].append(cid)
        for cid in row.str_list("remove_commands", ()):
            if cid not in merged["commands"]:
                row.fail("remove_commands", f"{cid!r} is not in the base")
            merged["commands"].remove(cid)
        for cid in merged["commands"]:
            if cid not in commands:
                row.fail("commands", f"unknown command {cid!r}")
        merged["ranges"] = {**merged["ranges"], **row.get("ranges", dict, {})}
        merged["reset"] = {**merged["reset"], **row.get("reset", dict, {})}
        merged["cite"] = {**merged["cite"], **row.get("cite", dict, {})}
        merged["base"] = base_id
        merged["_row"] = row
        flat[vid] = merged
        return merged

    out = {}
    for vid in raw_all:
        m = resolve(vid)
        row: Row = m["_row"]
        for field_name in ("title", "manual", "firmware", "axes", "queue", "max_rate", "bauds",
                           "addresses", "status_words", "eeprom_map"):
            if field_name not in m:
                row.fail(field_name, "missing (neither here nor in a base)")
        types = {"title": str, "manual": str, "firmware": str, "axes": list, "queue": int,
                 "max_rate": int, "bauds": list, "addresses": dict, "status_words": list,
                 "eeprom_map": str, "default_baud": int, "input_bits": dict, "processor_id": str}
        for field_name, ftype in types.items():
            if field_name in m and (not isinstance(m[field_name], ftype) or isinstance(m[field_name], bool)):
                row.fail(field_name, f"expected {ftype.__name__}, got {m[field_name]!r}")
        if m["manual"] not in ("GVE64", "GVE124"):
            row.fail("manual", f"{m['manual']!r} is not GVE64 or GVE124")
        ranges = {name: _bounds(row, f"ranges.{name}", rng) for name, rng in m["ranges"].items()}
        _check_variant_fields(row, m)
        axes = tuple(m["axes"])
        resolved = {}
        for cid in m["commands"]:
            cmd = commands[cid]
            params = []
            for p in cmd.params:
                lo, hi = p.lo, p.hi
                if p.range_name is not None:
                    if p.range_name not in ranges:
                        row.fail("ranges", f"command {cid!r} needs range {p.range_name!r}")
                    lo, hi = _bounds(row, f"ranges.{p.range_name}", list(ranges[p.range_name]),
                                     p.kind)
                if p.min_count is not None and p.min_count > len(axes):
                    row.fail("axes", f"command {cid!r} needs at least {p.min_count} axes")
                params.append(ParamSpec(p.name, p.kind, p.range_name, lo, hi, p.choices, p.sep,
                                        p.per_axis, p.min_count))
            resolved[cid] = CommandSpec(
                cmd.id, cmd.mnemonic, cmd.addresses, cmd.family, tuple(params), cmd.answer,
                cmd.modal, cmd.while_running, cmd.motion, cmd.effect, cmd.clauses, cmd.questions,
                cmd.answer_within,
            )
        if m["eeprom_map"] not in eeprom_maps:
            row.fail("eeprom_map", f"unknown EEPROM map {m['eeprom_map']!r}")
        for w in m["status_words"]:
            if w not in status.words:
                row.fail("status_words", f"unknown status word {w}")
        out[vid] = Variant(
            id=vid, title=m["title"], manual=m["manual"], firmware=m["firmware"],
            processor_id=m.get("processor_id", "00000000"), base=m["base"], axes=axes,
            queue=m["queue"], max_rate=m["max_rate"], bauds=tuple(m["bauds"]),
            default_baud=m.get("default_baud", m["bauds"][-1]),
            addresses=MappingProxyType(dict(m["addresses"])),
            status_words=tuple(m["status_words"]),
            input_bits=MappingProxyType({k: tuple(v) for k, v in m.get("input_bits", {}).items()}),
            eeprom=eeprom_maps[m["eeprom_map"]], commands=MappingProxyType(resolved),
            ranges=MappingProxyType(ranges), reset=MappingProxyType(m["reset"]),
            cite=MappingProxyType(m["cite"]),
            extras=MappingProxyType({"step_polarity_configurable": m.get("step_polarity_configurable", True)}),
        )
    return out


RESET_INTS = ("A", "V", "B", "$", "T", "VL", "XM", "outputs", "status", "spindle", "index",
              "position")
RESET_KEYS = {*RESET_INTS, "VK", "checksum", "mpg", "ready_after_s"}
MAX_AXES = 8
MAX_BASE_CHAIN = 32
MAX_QUEUE = 65535
MAX_RATE = 10_000_000


def _check_variant_fields(row: Row, m: dict[str, Any]) -> None:
    """Values the emulator and the checks build on: sizes a unit can have, one letter per
    axis, each once."""
    axes = m["axes"]
    if not 1 <= len(axes) <= MAX_AXES:
        row.fail("axes", f"expected 1..{MAX_AXES} axes, got {len(axes)}")
    for a in axes:
        if not isinstance(a, str) or len(a) != 1 or not "A" <= a <= "Z":
            row.fail("axes", f"{a!r} is not one upper-case letter")
    dup = sorted({a for a in axes if axes.count(a) > 1})
    if dup:
        row.fail("axes", f"duplicate axis {', '.join(dup)}")
    _int_in(row, "queue", m["queue"], 1, MAX_QUEUE, "vectors a unit holds")
    _int_in(row, "max_rate", m["max_rate"], 1, MAX_RATE, "pulses per second")
    if not m["bauds"]:
        row.fail("bauds", "expected one or more baud rates")
    for b in m["bauds"]:
        _int_in(row, "bauds", b, 1, MAX_RATE, "bits per second")
    if "default_baud" in m and m["default_baud"] not in m["bauds"]:
        row.fail("default_baud", f"{m['default_baud']!r} is not one of bauds")
    for role in ("interpolator", "spindle"):
        if role not in m["addresses"]:
            row.fail("addresses", f"missing {role!r}")
    for role, a in m["addresses"].items():
        _int_in(row, f"addresses.{role}", a, 0, 9, "one address digit")
    for name, bits in m.get("input_bits", {}).items():
        if not isinstance(bits, list):
            row.fail(f"input_bits.{name}", f"expected a list of bits, got {bits!r}")
        for b in bits:
            _int_in(row, f"input_bits.{name}", b, 0, 7, "a bit of a byte")
    for key, value in m["reset"].items():
        if key not in RESET_KEYS:
            row.fail(f"reset.{key}", f"unknown reset value (known: {', '.join(sorted(RESET_KEYS))})")
        if key in RESET_INTS:
            _int_in(row, f"reset.{key}", value, INT_LO, INT_HI, "a 32-bit value")
        elif key in ("VK", "checksum") and not isinstance(value, bool):
            row.fail(f"reset.{key}", f"expected true/false, got {value!r}")
        elif key == "mpg" and value not in ("+", "&", "-", "none"):
            row.fail("reset.mpg", f"expected one of + & - none, got {value!r}")
        elif key == "ready_after_s" and (isinstance(value, bool) or not isinstance(value, int | float)
                                         or not 0 <= value <= 60):
            row.fail("reset.ready_after_s", f"expected seconds 0..60, got {value!r}")


# --- open questions, examples -----------------------------------------------------------------

def _questions(path: Path, text: str, data: dict) -> dict[str, Question]:
    out = {}
    for row in each(data.get("question"), path, text, "question", _label):
        row.check_keys({"id", "topic", "question", "clause", "default", "alternatives", "settled",
                        "range"})
        qid = row.get("id", str)
        if qid in out:
            row.fail("id", f"duplicate question {qid!r}")
        alts = row.get("alternatives", dict)
        for name, text in alts.items():
            if not isinstance(text, str):
                row.fail(f"alternatives.{name}", f"expected a description, got {text!r}")
            lo, dash, hi = name.partition("-")
            if (row.data.get("range") and dash and lo.isdecimal() and hi.isdecimal()
                    and not (lo.isascii() and hi.isascii() and len(lo) <= 10 and len(hi) <= 10
                             and int(lo) <= int(hi) <= INT_HI)):
                row.fail(f"alternatives.{name}", "a range alternative is lo-hi, 0..4294967295")
        default = row.get("default", str)
        if default not in alts:
            row.fail("default", f"{default!r} is not one of the alternatives ({', '.join(alts)})")
        out[qid] = Question(qid, row.get("topic", str), row.get("question", str), row.clauses(),
                            default, MappingProxyType(dict(alts)), row.get("settled", str, None),
                            row.get("range", str, None))
    return out


GIVEN = re.compile(r"(checksum-on|inta|queue-full|st[0-6]=[0-9A-Fa-f]{1,2}"
                   r"|position=-?[0-9]{1,10}(,-?[0-9]{1,10}){0,7})\Z")
"""The unit states an example may name (conform/families/gve/unit/given.py)."""


def _examples(path: Path, text: str, data: dict) -> tuple[Example, ...]:
    out = []
    for row in each(data.get("example"), path, text, "example", _label):
        row.check_keys({"id", "clause", "kind", "given", "send", "expect", "body", "line"})
        for item in row.str_list("given", ()):
            if GIVEN.match(item) is None:
                row.fail("given", f"{item!r:.60} is not one of checksum-on, inta, queue-full, "
                                  "st<n>=<hex>, position=<x,y,...>")
        out.append(Example(
            id=row.get("id", str), clauses=row.clauses(),
            kind=row.choice("kind", ("checksum", "exchange", "packet")),
            given=row.str_list("given", ()), send=row.str_list("send", ()),
            expect=row.str_list("expect", ()), body=row.get("body", str, None),
            line=row.get("line", str, None),
        ))
    return tuple(out)
