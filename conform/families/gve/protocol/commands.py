"""Commands: encoding from the tables and parsing a received line into a typed command or a
typed rejection (GVE64 §13.5, GVE124 §12.5). Pure functions, no I/O."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from conform.families.gve.protocol.checksum import append_checksum, checksum, split_checksum
from conform.families.gve.spec.model import CommandSpec, Dialect, ParamSpec, Variant

CR = b"\r"

MAX_DIGITS = 40
"""A numeral with more significant digits than this is out of every range in the tables (the
widest field is 32 bits); it is answered as out of range without converting it, so that no
length of a number (Python refuses int() of more than 4 300 digits) can raise."""

# error codes (specs/gve/errors.toml)
OK, QUEUE_FULL, WATCHDOG, UNKNOWN, SYNTAX, RANGE, NOTHING_TO_GO, RUNNING = range(8)


@dataclass(frozen=True, slots=True)
class Command:
    """A well-formed command: ``name`` is the row id in specs/gve/commands.toml."""

    address: int
    name: str
    args: tuple[Any, ...]
    checksum: bool
    raw: bytes


@dataclass(frozen=True, slots=True)
class Rejection:
    """A line the unit rejects. ``code`` is the error it answers, None for silence.

    kind: ``garbage`` (not a command line), ``address`` (another unit's), ``checksum``,
    ``unknown`` (no such mnemonic), ``absent`` (not in this firmware version), ``syntax``, ``range``.
    """

    kind: str
    code: int | None
    detail: str
    raw: bytes
    name: str | None = None
    address: int | None = None


def _format_arg(param: ParamSpec, value: Any) -> str:
    if param.kind == "hex":
        return "%02X" % value
    if param.kind == "float":
        text = repr(float(value))
        return text[:-2] if text.endswith(".0") else text
    return str(value)


def encode_command(
    variant: Variant | None,
    spec: CommandSpec,
    args: Sequence[Any] = (),
    *,
    address: int = 0,
    checksum_on: bool = False,
    terminator: bytes = CR,
) -> bytes:
    """Build the bytes of a command. Per-axis parameters take as many values as given."""
    out = [f"!{address}{spec.mnemonic}"]
    values = list(args)
    for param in spec.params:
        if param.per_axis:
            count = len(values) if variant is None else min(len(values), len(variant.axes))
            for i in range(count):
                out.append(param.sep if i == 0 else ",")
                out.append(_format_arg(param, values.pop(0)))
            continue
        if not values:
            raise ValueError(f"{spec.id}: missing value for parameter {param.name!r}")
        out.append(param.sep)
        out.append(_format_arg(param, values.pop(0)))
    if values:
        raise ValueError(f"{spec.id}: {len(values)} value(s) too many")
    body = "".join(out).encode("ascii")
    if checksum_on:
        body = append_checksum(body)
    return body + terminator


# --- parsing ----------------------------------------------------------------------------------

# Possessive quantifiers: a token never gives back what it matched (a token holds no ',' and is
# followed by ',' or the end), so a line of spaces or digits cannot make the match backtrack.
_TOKENS_STRICT = {
    "int": r"(-?[0-9]++)",
    "uint": r"([0-9]++)",
    "hex": r"([0-9A-Fa-f]++)",
    "float": r"(-?[0-9]++(?:\.[0-9]*+)?+(?:[eE][-+]?[0-9]++)?+)",
    "axis": r"([A-Za-z])",
}
_TOKENS_LENIENT = {
    "int": r"( *+[-+]?+ *+[0-9]*+ *+)",
    "uint": r"( *+\+?+ *+[0-9]*+ *+)",
    "hex": r"( *+[0-9A-Fa-f]*+ *+)",
    "float": r"( *+[-+]?+ *+[0-9]*+(?:\.[0-9]*+)?+(?:[eE][-+]?[0-9]++)?+ *+)",
    "axis": r"( *+[A-Za-z] *+)",
}


_NUMERIC = frozenset(("int", "uint", "hex"))


def _significant(raw: str) -> str | None:
    """``raw`` without leading zeros (its sign kept); None for more digits than any field."""
    sign = "-" if raw[:1] == "-" else ""
    digits = raw.lstrip("+-").lstrip("0") or "0"
    return None if len(digits) > MAX_DIGITS else sign + digits


class _Form:
    """One command row compiled for a variant and dialect: a regex over the parameter text."""

    __slots__ = ("spec", "regex", "converters", "params", "min_fields", "axis_letters", "absent")

    def __init__(self, spec: CommandSpec, variant: Variant, dialect: Dialect, absent: bool) -> None:
        self.spec = spec
        self.absent = absent
        lenient = dialect["A22"] == "lenient"
        tokens = _TOKENS_LENIENT if lenient else _TOKENS_STRICT
        parts: list[str] = []
        self.params: list[ParamSpec] = []
        self.converters: list[str] = []
        for param in spec.params:
            lo, hi = param.lo, param.hi
            if param.range_name in dialect.ranges:
                lo, hi = dialect.ranges[param.range_name]
            param = ParamSpec(param.name, param.kind, param.range_name, lo, hi, param.choices,
                              param.sep, param.per_axis, param.min_count)
            if param.kind == "sign":
                tok = "(" + "|".join(re.escape(c) for c in param.choices) + ")"
            else:
                tok = tokens[param.kind]
            sep = re.escape(param.sep)
            if param.per_axis:
                n = len(variant.axes)
                need = param.min_count or n
                first = f"{sep}{tok}" + "".join(f",{tok}" for _ in range(need - 1))
                optional = "".join(f"(?:,{tok}" for _ in range(n - need)) + ")?" * (n - need)
                parts.append(first + optional)
                self.params.extend([param] * n)
                self.converters.extend([param.kind] * n)
            else:
                parts.append(sep + tok)
                self.params.append(param)
                self.converters.append(param.kind)
        self.regex = re.compile("".join(parts) + r"\Z", re.DOTALL)
        self.axis_letters = {a.upper() for a in variant.axes}

    def parse(self, text: str, lenient: bool) -> tuple[tuple[Any, ...] | None, str, int]:
        """(args, detail, code): args None on failure with the error code to answer."""
        m = self.regex.match(text)
        if m is None:
            return None, f"{self.spec.id}: parameters {text!r} do not match the form", SYNTAX
        values: list[Any] = []
        for raw, kind, param in zip(m.groups(), self.converters, self.params, strict=True):
            if raw is None:  # an optional trailing axis left out: that axis does not move
                values.append(0)
                continue
            if lenient and kind != "sign":
                raw = raw.replace(" ", "")
                if raw in ("", "+", "-"):
                    if kind == "axis":
                        return None, f"{self.spec.id}: empty {param.name}", SYNTAX
                    raw = "0"
            if kind in _NUMERIC:
                digits = raw if len(raw) <= MAX_DIGITS else _significant(raw)
                if digits is None:
                    return None, f"{self.spec.id}: {param.name} has more than {MAX_DIGITS} digits", RANGE
                value: Any = int(digits, 16 if kind == "hex" else 10)
            elif kind == "float":
                try:
                    value = float(raw)
                except ValueError:  # lenient forms without digits: ".", "E5"
                    return None, f"{self.spec.id}: {param.name} {raw!r} is not a number", SYNTAX
            elif kind == "axis":
                value = raw.upper()
                if value not in self.axis_letters:
                    return None, f"{self.spec.id}: axis {raw!r} is not one of this unit's axes", RANGE
                values.append(value)
                continue
            else:
                values.append(raw)
                continue
            if not param.in_range(value):
                return None, f"{self.spec.id}: {param.name}={raw} outside {param.lo}..{param.hi}", RANGE
            values.append(value)
        return tuple(values), "", OK


class CommandParser:
    """Parse received lines for one variant and dialect (GVE64 §13.5, §13.3.2)."""

    def __init__(self, variant: Variant, dialect: Dialect, all_commands: dict[str, CommandSpec] | None = None) -> None:
        from conform.families.gve.spec import load_spec

        self.variant = variant
        self.dialect = dialect
        self.lenient = dialect["A22"] == "lenient"
        self.any_case = dialect["A21"] == "any-case"
        self._other_address_code = 3 if dialect["A23"] == "error-3" else None
        self._a11 = dialect["A11"]
        self._checksum_code = 2 if self._a11 == "watchdog-2" else SYNTAX
        universe = all_commands if all_commands is not None else load_spec().commands
        self.addresses = set(variant.addresses.values())
        if dialect["A19"] == "none" and variant.manual == "GVE124":
            self.addresses.discard(variant.spindle_address)
        # address -> mnemonic -> [forms]; forms of commands absent in this variant are kept so
        # that they are told apart from unknown ones (answered 3 either way, GVE64 §14.1)
        self.table: dict[int, dict[str, list[_Form]]] = {}
        role = {variant.interpolator_address: 0, variant.spindle_address: 7}
        for address, table_address in role.items():
            by_mnemonic: dict[str, list[_Form]] = {}
            for cid, base in universe.items():
                if table_address not in base.addresses:
                    continue
                spec = variant.commands.get(cid)
                if spec is not None:
                    form = _Form(spec, variant, dialect, absent=False)
                else:
                    form = _Form(_resolve_absent(base, variant), variant, dialect, absent=True)
                by_mnemonic.setdefault(base.mnemonic, []).append(form)
            if dialect["A2"] == "s-too" and "$" in by_mnemonic:
                by_mnemonic["S"] = by_mnemonic["$"]
            if dialect["A3"] == "zero-too" and "O" in by_mnemonic:
                by_mnemonic["0"] = by_mnemonic["O"]
            for forms in by_mnemonic.values():
                forms.sort(key=lambda f: len(f.spec.params))
            self.table[address] = by_mnemonic
        self.max_len = max(len(m) for t in self.table.values() for m in t)
        self._heads = {
            address: re.compile("|".join(re.escape(m) for m in sorted(t, key=len, reverse=True)),
                                re.IGNORECASE if self.any_case else 0)
            for address, t in self.table.items()}

    def parse(self, line: bytes, checksum_on: bool) -> Command | Rejection:
        if len(line) < 2 or line[0] != 0x21 or not 0x30 <= line[1] <= 0x39:
            return Rejection("garbage", None, "not a command line (expected '!' and an address digit)", line)
        address = line[1] - 0x30
        if address not in self.addresses:
            return Rejection("address", self._other_address_code,
                             f"address {address} is not this unit's", line, address=address)
        body = line
        with_sum = False
        if checksum_on:
            body, value = split_checksum(line)
            if value is None:
                if self._a11 != "lenient":
                    return Rejection("checksum", self._checksum_code,
                                     "checksums are on but the line has none", line,
                                     address=address)
            elif checksum(body + b",") != value:
                return Rejection("checksum", self._checksum_code,
                                 f"checksum {value:02X} does not match {checksum(body + b','):02X}",
                                 line, address=address)
            else:
                with_sum = True
        try:
            text = body[2:].decode("ascii")
        except UnicodeDecodeError as exc:
            return Rejection("syntax", SYNTAX, f"non-ASCII byte at offset {exc.start + 2}", line,
                             address=address)
        m = self._heads[address].match(text)  # the longest mnemonic the line starts with
        if m is not None:
            head = m.group()
            forms = self.table[address][head.upper() if self.any_case else head]
            rest = text[len(head):]
            form = forms[0] if len(forms) == 1 else (forms[0] if not rest else forms[-1])
            if form.absent:
                return Rejection("absent", UNKNOWN, f"{form.spec.id} is not in {self.variant.id}",
                                 line, form.spec.id, address)
            args, detail, code = form.parse(rest, self.lenient)
            if args is None:
                kind = "range" if code == RANGE else "syntax"
                return Rejection(kind, code, detail, line, form.spec.id, address)
            return Command(address, form.spec.id, args, with_sum, line)
        return Rejection("unknown", UNKNOWN, f"unknown command {text[:8]!r}", line, address=address)


def _resolve_absent(base: CommandSpec, variant: Variant) -> CommandSpec:
    """An absent command still needs ranges to compile; any concrete bound will do."""
    params = tuple(
        ParamSpec(p.name, p.kind, None, p.lo if p.lo is not None else 0,
                  p.hi if p.hi is not None else 0, p.choices, p.sep, p.per_axis,
                  min(p.min_count, len(variant.axes)) if p.min_count else None)
        for p in base.params
    )
    return CommandSpec(base.id, base.mnemonic, base.addresses, base.family, params, base.answer,
                       base.modal, base.while_running, base.motion, base.effect, base.clauses,
                       base.questions, base.answer_within)
