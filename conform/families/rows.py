"""Reading a family's TOML tables with one-line errors that name the file, the row and the
field (every family's loader uses it, so a bad table reads the same in each)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from conform.errors import UserError


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


def read_table(root: Path, name: str, needed: str = "") -> tuple[Rows, dict[str, Any]]:
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
