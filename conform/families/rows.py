"""Reading a family's TOML tables with one-line errors that name the file, the row and the
field (every family's loader uses it, so a bad table reads the same in each)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from conform.errors import UserError
from conform.jsondoc import JsonObject


class Rows:
    """Typed field access to one table file's rows."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, row: str, msg: str) -> UserError:
        return UserError(f"{self.path}: [{row}] {msg}")

    def get(self, row: str, d: Any, key: str, kind: type | tuple[type, ...],
            default: Any = ...) -> Any:
        """``d[key]`` of type ``kind`` (a bool is not a number), or ``default`` when absent;
        without a default a missing field is an error."""
        if not isinstance(d, dict):
            raise self.fail(row, "is not a table")
        if key not in d:
            if default is ...:
                raise self.fail(row, f"field {key!r} is missing")
            return default
        value = d[key]
        if isinstance(value, bool) and kind in (int, float, (int, float)):
            raise self.fail(row, f"field {key!r}: expected a number, got {value!r}")
        if not isinstance(value, kind):
            name = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
            raise self.fail(row, f"field {key!r}: expected {name}, got {value!r}")
        return value

    def regex(self, row: str, text: str) -> re.Pattern[str]:
        try:
            return re.compile(text)
        except re.error as exc:
            raise self.fail(row, f"pattern {text!r} is not a regular expression: {exc}") from None


def read_table(root: Path, name: str, needed: str = "") -> tuple[Rows, JsonObject]:
    """``root/name.toml`` parsed; ``needed`` (the files the family's tables need) is named
    when the file is missing."""
    path = root / f"{name}.toml"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise UserError(f"{path}: missing" + (f" (the tables need {needed})" if needed else "")
                        ) from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: not UTF-8 text at byte {exc.start}") from None
    try:
        return Rows(path), tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML: {exc}") from None


class LineTables:
    """What a family's loaded tables answer the same way in every family: a variant by id (a
    one-line error naming the family's variants) and the kind of one line from the unit (the
    first ``messages`` row whose pattern matches). Mixed into the family's tables dataclass,
    which has ``variants``, ``messages`` (rows with ``kind`` and ``pattern``) and names its
    family in ``family_name``."""

    family_name = ""
    variants: dict[str, Any]   # the family's rows, by id
    messages: dict[str, Any]

    def variant(self, vid: str) -> Any:
        try:
            return self.variants[vid]
        except KeyError:
            from conform.families import unknown_variant

            raise UserError(unknown_variant(vid, self.family_name)) from None

    def classify(self, line: str) -> tuple[str, re.Match[str] | None]:
        """The message kind of one line from the unit (``unknown`` when no row matches)."""
        for m in self.messages.values():
            hit = m.pattern.match(line)
            if hit:
                return m.kind, hit
        return "unknown", None
