"""Typed, immutable model of the spec tables (what ``specs/gve/*.toml`` say, resolved per variant)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from conform.errors import UserError

PARAM_KINDS = ("int", "uint", "hex", "axis", "sign", "float")
ANSWER_RADIXES = ("dec", "hex", "text", "float")


@dataclass(frozen=True, slots=True)
class ParamSpec:
    """One parameter of a command; ``lo``/``hi`` are resolved for a variant (None in the raw row)."""

    name: str
    kind: str
    range_name: str | None = None
    lo: int | float | None = None
    hi: int | float | None = None
    choices: tuple[str, ...] = ()
    sep: str = ","
    per_axis: bool = False
    min_count: int | None = None

    def in_range(self, value: Any) -> bool:
        if self.lo is None or self.hi is None:
            return True
        return self.lo <= value <= self.hi


@dataclass(frozen=True, slots=True)
class AnswerField:
    name: str
    radix: str
    width: int | None = None


@dataclass(frozen=True, slots=True)
class CommandSpec:
    """A command row; in a :class:`Variant` its parameters carry that variant's ranges."""

    id: str
    mnemonic: str
    addresses: tuple[int, ...]
    family: str
    params: tuple[ParamSpec, ...]
    answer: tuple[AnswerField, ...]
    modal: bool
    while_running: bool
    motion: bool
    effect: str
    clauses: tuple[str, ...]
    questions: tuple[str, ...]
    answer_within: float = 0.5  # seconds a host waits for the answer (H and W answer only when done)

    def clause_for(self, manual: str) -> str:
        """The clause of ``manual`` ("GVE64", "GVE124") this row cites, else its first clause."""
        for clause in self.clauses:
            if clause.startswith(manual + " "):
                return clause
        return self.clauses[0]

    def param(self, name: str) -> ParamSpec:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f"command {self.id!r} has no parameter {name!r}")


@dataclass(frozen=True, slots=True)
class ErrorCode:
    code: int
    name: str
    meaning: str
    clauses: tuple[str, ...]
    raised_by: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class StatusWord:
    index: int
    name: str
    role: str
    inputs: str
    meaning: str
    clauses: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class StatusBit:
    bit: int
    name: str
    meaning: str
    clauses: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class StatusTable:
    words: Mapping[int, StatusWord]
    st6_bits: Mapping[str, StatusBit]
    queue_full_bit: int
    run_inta: tuple[tuple[int, int, str], ...]

    def bit(self, name: str) -> int:
        return self.st6_bits[name].bit


@dataclass(frozen=True, slots=True)
class EepromCell:
    address: int
    name: str
    type: str  # byte | float | uint32
    default: int | float
    default_from: str
    values: Mapping[str, str] = field(default_factory=dict)
    range: tuple[float, float] | None = None
    clauses: tuple[str, ...] = ()

    @property
    def size(self) -> int:
        return 1 if self.type == "byte" else 4


@dataclass(frozen=True, slots=True)
class EepromMap:
    name: str
    cells: Mapping[int, EepromCell]
    blank: int

    def image(self) -> bytes:
        """The 256-byte content at delivery (defaults; ``blank`` elsewhere)."""
        import struct

        data = bytearray([self.blank] * 256)
        for cell in self.cells.values():
            if cell.type == "byte":
                raw = bytes([int(cell.default)])
            elif cell.type == "float":
                raw = struct.pack("<f", float(cell.default))
            else:
                raw = struct.pack("<I", int(cell.default))
            data[cell.address : cell.address + len(raw)] = raw
        return bytes(data)


@dataclass(frozen=True, slots=True)
class Question:
    id: str
    topic: str
    question: str
    clauses: tuple[str, ...]
    default: str
    alternatives: Mapping[str, str]
    settled: str | None
    range: str | None = None  # a range name whose bounds the chosen alternative ("lo-hi") sets


@dataclass(frozen=True, slots=True)
class Example:
    id: str
    clauses: tuple[str, ...]
    kind: str
    given: tuple[str, ...] = ()
    send: tuple[str, ...] = ()
    expect: tuple[str, ...] = ()
    body: str | None = None
    line: str | None = None


@dataclass(frozen=True)
class Variant:
    """One modelled unit, fully resolved (base deltas applied)."""

    id: str
    title: str
    manual: str
    firmware: str
    processor_id: str
    base: str | None
    axes: tuple[str, ...]
    queue: int
    max_rate: int
    bauds: tuple[int, ...]
    default_baud: int
    addresses: Mapping[str, int]
    status_words: tuple[int, ...]
    input_bits: Mapping[str, tuple[int, ...]]
    eeprom: EepromMap
    commands: Mapping[str, CommandSpec]
    ranges: Mapping[str, tuple[Any, Any]]
    reset: Mapping[str, Any]
    cite: Mapping[str, str]
    extras: Mapping[str, Any]

    def command(self, command_id: str) -> CommandSpec | None:
        return self.commands.get(command_id)

    def has(self, command_id: str) -> bool:
        return command_id in self.commands

    def range(self, command_id: str, param: str | None = None) -> tuple[Any, Any]:
        """The (lo, hi) range of a command's parameter (its first one when ``param`` is None)."""
        cmd = self.commands.get(command_id)
        if cmd is None:
            raise KeyError(f"{self.id} has no command {command_id!r}")
        p = cmd.params[0] if param is None else cmd.param(param)
        return (p.lo, p.hi)

    def commands_at(self, address: int) -> list[CommandSpec]:
        return [c for c in self.commands.values() if address in c.addresses]

    def clause(self, field_name: str) -> str:
        """The clause cited for a variant field (falls back to the manual's name)."""
        return self.cite.get(field_name, self.manual)

    @property
    def interpolator_address(self) -> int:
        return self.addresses["interpolator"]

    @property
    def spindle_address(self) -> int:
        return self.addresses["spindle"]


@dataclass(frozen=True)
class Spec:
    """All tables. ``variant(id)`` and ``dialect(...)`` are the usual entry points."""

    root: Path
    commands: Mapping[str, CommandSpec]
    errors: Mapping[int, ErrorCode]
    inta_bit: int
    status: StatusTable
    eeprom_maps: Mapping[str, EepromMap]
    variants: Mapping[str, Variant]
    questions: Mapping[str, Question]
    examples: tuple[Example, ...]

    def variant(self, variant_id: str) -> Variant:
        try:
            return self.variants[variant_id]
        except KeyError:
            from conform.families import unknown_variant

            raise UserError(unknown_variant(variant_id, "gve")) from None

    def dialect(self, choices: Mapping[str, str] | None = None) -> Dialect:
        """The open-question choices: the defaults, overridden by ``choices``."""
        values = {q.id: q.default for q in self.questions.values()}
        for key, value in (choices or {}).items():
            question = self.questions.get(key)
            if question is None:
                raise UserError(f"dialect: unknown open question {key!r:.40} "
                                f"(known: A1..A{len(self.questions)})")
            if value not in question.alternatives:
                alts = ", ".join(question.alternatives)
                raise UserError(f"dialect: {key}={value!r:.40} is not an alternative (choose: {alts})")
            values[key] = value
        defaults = {q.id: q.default for q in self.questions.values()}
        ranges = {}
        for q in self.questions.values():
            lo, _, hi = values[q.id].partition("-")
            if q.range and lo.isascii() and hi.isascii() and lo.isdigit() and hi.isdigit():
                ranges[q.range] = (int(lo), int(hi))
        return Dialect(MappingProxyType(values), MappingProxyType(defaults), MappingProxyType(ranges))


@dataclass(frozen=True)
class Dialect:
    """The chosen alternative for every open question (A1…)."""

    choices: Mapping[str, str]
    defaults: Mapping[str, str]
    ranges: Mapping[str, tuple[int, int]]  # range name -> bounds set by an open question

    def __getitem__(self, question_id: str) -> str:
        return self.choices[question_id]

    def is_default(self, question_id: str) -> bool:
        return self.choices[question_id] == self.defaults[question_id]

    def changed(self) -> dict[str, str]:
        return {k: v for k, v in self.choices.items() if v != self.defaults[k]}

    def __hash__(self) -> int:
        return hash(tuple(sorted(self.choices.items())))
