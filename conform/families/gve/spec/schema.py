"""Row-level validation of the TOML tables: every problem names file, line, row and field."""

from __future__ import annotations

import re
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

from conform.errors import UserError


class SpecError(UserError):
    """A table that does not load or validate."""


def header_lines(text: str, table: str) -> list[int]:
    """1-based line numbers of each ``[[table]]`` header, in order."""
    pattern = re.compile(r"^\s*\[\[\s*" + re.escape(table) + r"\s*\]\]\s*(#.*)?$")
    return [i + 1 for i, line in enumerate(text.splitlines()) if pattern.match(line)]


_TABLE_HEADER = re.compile(r"^\s*\[(?!\[)([^\]]*)\]")


@lru_cache(maxsize=16)
def key_lines(text: str) -> dict[str, int]:
    """1-based line of every ``[dotted.table]`` header (first one wins), keyed by the dotted
    name without spaces: one pass, so a file of many tables is not read once per table."""
    out: dict[str, int] = {}
    for i, line in enumerate(text.splitlines()):
        m = _TABLE_HEADER.match(line)
        if m:
            out.setdefault(".".join(part.strip() for part in m.group(1).split(".")), i + 1)
    return out


def key_line(text: str, dotted: str) -> int | None:
    """1-based line of a ``[dotted.table]`` header, if present."""
    return key_lines(text).get(dotted)


class Row:
    """A table row with typed accessors that raise :class:`SpecError` naming the field."""

    def __init__(self, data: Any, path: Path, where: str, line: int | None) -> None:
        self.path = path
        self.where = where
        self.line = line
        if not isinstance(data, dict):
            self.fail(None, f"expected a table, got {type(data).__name__}")
        self.data: dict[str, Any] = data

    def location(self) -> str:
        place = f"{self.path.name}:{self.line}" if self.line else self.path.name
        return f"{place}: {self.where}"

    def fail(self, field: str | None, problem: str) -> None:
        suffix = f": field {field!r}" if field else ""
        raise SpecError(f"{self.location()}{suffix}: {problem}")

    def check_keys(self, allowed: set[str]) -> None:
        for key in self.data:
            if key not in allowed:
                self.fail(key, f"unknown field (allowed: {', '.join(sorted(allowed))})")

    def get(self, field: str, types: type | tuple[type, ...], default: Any = ...) -> Any:
        if field not in self.data:
            if default is ...:
                self.fail(field, "missing")
            return default
        value = self.data[field]
        if isinstance(value, bool) and bool not in _as_tuple(types):
            self.fail(field, f"expected {_names(types)}, got a boolean")
        if not isinstance(value, types):
            self.fail(field, f"expected {_names(types)}, got {type(value).__name__} {value!r}")
        return value

    def str_list(self, field: str, default: Any = ...) -> tuple[str, ...]:
        value = self.get(field, list, default)
        if value is default and default is not ...:
            return tuple(default)
        for item in value:
            if not isinstance(item, str):
                self.fail(field, f"expected a list of strings, found {item!r}")
        return tuple(value)

    def int_list(self, field: str, default: Any = ...) -> tuple[int, ...]:
        value = self.get(field, list, default)
        if value is default and default is not ...:
            return tuple(default)
        for item in value:
            if not isinstance(item, int) or isinstance(item, bool):
                self.fail(field, f"expected a list of integers, found {item!r}")
        return tuple(value)

    def choice(self, field: str, allowed: tuple[str, ...], default: Any = ...) -> str:
        value = self.get(field, str, default)
        if value not in allowed:
            self.fail(field, f"{value!r} is not one of {', '.join(allowed)}")
        return value

    def clauses(self, field: str = "clause") -> tuple[str, ...]:
        value = self.data.get(field)
        if isinstance(value, str):
            value = [value]
        if not value or not isinstance(value, list):
            self.fail(field, "missing: every row must cite the manual clause it comes from")
        for clause in value:
            if not isinstance(clause, str) or not CLAUSE.match(clause):
                self.fail(field, f"{clause!r} is not a clause like 'GVE64 §13.5.2'")
        return tuple(value)

    def sub(self, data: Any, where: str) -> Row:
        return Row(data, self.path, f"{self.where}: {where}", self.line)


CLAUSE = re.compile(r"^(GVE64|GVE124) §\d+(\.\d+)*$|^A\d+$")


def _as_tuple(types: type | tuple[type, ...]) -> tuple[type, ...]:
    return types if isinstance(types, tuple) else (types,)


def _names(types: type | tuple[type, ...]) -> str:
    names = {"str": "a string", "int": "an integer", "list": "a list", "dict": "a table",
             "bool": "true/false", "float": "a number"}
    return " or ".join(names.get(t.__name__, t.__name__) for t in _as_tuple(types))


def each(rows: Any, path: Path, text: str, table: str, label: Callable[[dict], str]) -> list[Row]:
    """Wrap the ``[[table]]`` array of a file as :class:`Row` objects with line numbers."""
    if rows is None:
        raise SpecError(f"{path.name}: no [[{table}]] rows")
    if not isinstance(rows, list):
        raise SpecError(f"{path.name}: '{table}' must be an array of tables ([[{table}]])")
    lines = header_lines(text, table)
    out = []
    for i, data in enumerate(rows):
        name = label(data) if isinstance(data, dict) else "?"
        out.append(Row(data, path, f"{table} {name} (row {i + 1})", lines[i] if i < len(lines) else None))
    return out
