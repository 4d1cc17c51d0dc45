"""Load ``specs/*.toml`` into the typed model, validating every row."""

from __future__ import annotations

import os
import tomllib
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import Any

from conform.spec.model import (
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
from conform.spec.schema import Row, SpecError, each, key_line

FILES = ("commands", "errors", "status", "eeprom", "variants", "questions", "examples")
FAMILIES = (
    "identify", "vector", "modal", "exchange", "position", "reference", "mpg", "queue",
    "eeprom", "io", "status", "recovery", "reset", "checksum", "packet", "spindle",
)


def default_root() -> Path:
    """``$CONFORM_SPECS``, else the ``specs/`` folder beside the package."""
    env = os.environ.get("CONFORM_SPECS")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / "specs"


def load_spec(root: str | Path | None = None) -> Spec:
    """Load and validate the tables (cached per folder)."""
    return _load(Path(root) if root is not None else default_root())


@lru_cache(maxsize=8)
def _load(root: Path) -> Spec:
    if not root.is_dir():
        raise SpecError(f"spec folder not found: {root}")
    docs: dict[str, tuple[Path, str, dict[str, Any]]] = {}
    for name in FILES:
        path = root / f"{name}.toml"
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise SpecError(f"{path}: missing table file") from None
        except UnicodeDecodeError as exc:
            raise SpecError(f"{path.name}: not UTF-8 text (byte offset {exc.start})") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SpecError(f"{path.name}: {exc}") from None
        docs[name] = (path, text, data)

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


def _label(data: dict) -> str:
    return repr(data.get("id", data.get("code", data.get("index", data.get("name", "?")))))


# --- commands ---------------------------------------------------------------------------------

COMMAND_KEYS = {
    "id", "mnemonic", "addresses", "family", "params", "answer", "modal", "while_running",
    "motion", "effect", "clause", "questions",
}
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
                if len(rng) != 2 or not all(isinstance(v, int | float) for v in rng) or rng[0] > rng[1]:
                    prow.fail("range", f"expected [lo, hi] with lo <= hi, got {rng!r}")
                lo, hi = rng
            choices = prow.str_list("choices", ())
            if kind == "sign" and not choices:
                prow.fail("choices", "a sign parameter needs its choices")
            if kind in ("int", "uint", "hex", "float") and rng is None:
                prow.fail("range", f"a {kind} parameter needs a range")
            per_axis = prow.get("per_axis", bool, False)
            min_count = prow.get("min_count", int, None)
            if min_count is not None and not per_axis:
                prow.fail("min_count", "only per_axis parameters take min_count")
            params.append(ParamSpec(
                name=prow.get("name", str), kind=kind, range_name=range_name, lo=lo, hi=hi,
                choices=choices, sep=prow.get("sep", str, "" if i == 0 else ","),
                per_axis=per_axis, min_count=min_count,
            ))
        answer = []
        for i, raw in enumerate(row.get("answer", list, [])):
            arow = row.sub(raw, f"answer[{i}]")
            arow.check_keys(ANSWER_KEYS)
            answer.append(AnswerField(arow.get("name", str), arow.choice("radix", ANSWER_RADIXES),
                                      arow.get("width", int, None)))
        qs = row.str_list("questions", ())
        for q in qs:
            if q not in questions:
                row.fail("questions", f"unknown open question {q!r}")
        out[cid] = CommandSpec(
            id=cid, mnemonic=mnemonic, addresses=addresses, family=family, params=tuple(params),
            answer=tuple(answer), modal=row.get("modal", bool, False),
            while_running=row.get("while_running", bool, True), motion=row.get("motion", bool, False),
            effect=row.get("effect", str), clauses=row.clauses(), questions=qs,
        )
    return out


# --- errors, status, eeprom -------------------------------------------------------------------

def _errors(path: Path, text: str, data: dict, commands: dict[str, CommandSpec]) -> tuple[dict[int, ErrorCode], int]:
    top = Row(data, path, "top level", None)
    inta_bit = top.get("inta_bit", int)
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
    return StatusTable(MappingProxyType(words), MappingProxyType(bits),
                       top.get("queue_full_bit", int), tuple(run_inta))


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
        values = row.get("values", str, None)
        if values is not None and values not in value_sets:
            row.fail("values", f"unknown value set {values!r}")
        rng = row.get("range", list, None)
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
        ranges = {}
        for name, rng in m["ranges"].items():
            if (not isinstance(rng, list) or len(rng) != 2
                    or not all(isinstance(v, int | float) for v in rng) or rng[0] > rng[1]):
                row.fail(f"ranges.{name}", f"expected [lo, hi] with lo <= hi, got {rng!r}")
            ranges[name] = tuple(rng)
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
                    lo, hi = ranges[p.range_name]
                if p.min_count is not None and p.min_count > len(axes):
                    row.fail("axes", f"command {cid!r} needs at least {p.min_count} axes")
                params.append(ParamSpec(p.name, p.kind, p.range_name, lo, hi, p.choices, p.sep,
                                        p.per_axis, p.min_count))
            resolved[cid] = CommandSpec(
                cmd.id, cmd.mnemonic, cmd.addresses, cmd.family, tuple(params), cmd.answer,
                cmd.modal, cmd.while_running, cmd.motion, cmd.effect, cmd.clauses, cmd.questions,
            )
        if m["eeprom_map"] not in eeprom_maps:
            row.fail("eeprom_map", f"unknown EEPROM map {m['eeprom_map']!r}")
        for w in m["status_words"]:
            if w not in status.words:
                row.fail("status_words", f"unknown status word {w}")
        if m["queue"] < 1:
            row.fail("queue", "must be at least 1")
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
        default = row.get("default", str)
        if default not in alts:
            row.fail("default", f"{default!r} is not one of the alternatives ({', '.join(alts)})")
        out[qid] = Question(qid, row.get("topic", str), row.get("question", str), row.clauses(),
                            default, MappingProxyType(dict(alts)), row.get("settled", str, None),
                            row.get("range", str, None))
    return out


def _examples(path: Path, text: str, data: dict) -> tuple[Example, ...]:
    out = []
    for row in each(data.get("example"), path, text, "example", _label):
        row.check_keys({"id", "clause", "kind", "given", "send", "expect", "body", "line"})
        out.append(Example(
            id=row.get("id", str), clauses=row.clauses(),
            kind=row.choice("kind", ("checksum", "exchange", "packet")),
            given=row.str_list("given", ()), send=row.str_list("send", ()),
            expect=row.str_list("expect", ()), body=row.get("body", str, None),
            line=row.get("line", str, None),
        ))
    return tuple(out)
