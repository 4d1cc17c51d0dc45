"""User-facing errors: one line, a non-zero exit, never a traceback."""

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar


class UserError(Exception):
    """A mistake in what the user gave us (a file, an option, a table row).

    The CLI prints ``str(err)`` on one line and exits with ``exit_code``.
    """

    exit_code = 2

    def __init__(self, message: str, exit_code: int | None = None) -> None:
        super().__init__(message)
        if exit_code is not None:
            self.exit_code = exit_code


def read_user_text(path: str | Path) -> str:
    """The text of a file the user named; a missing or unreadable one is one ``UserError`` line."""
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise UserError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise UserError(f"{p}: is a directory, not a file") from None
    except UnicodeDecodeError as exc:
        raise UserError(f"{p}: not UTF-8 text (byte offset {exc.start})") from None
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror or exc}") from None


def _value_error(exc: ValueError) -> str:
    return str(exc).split("; use sys")[0]  # the int-digits limit names an interpreter knob


_Parsed = TypeVar("_Parsed")


def load_user_file(path: str | Path, parse: Callable[[str], _Parsed], *, max_bytes: int, what: str,
                   describe: Callable[[ValueError], str] = _value_error) -> _Parsed:
    """``parse`` the text of a file the user named; a file larger than ``max_bytes`` (refused
    before it is read), nested past the interpreter's depth or that ``parse`` rejects with a
    ``ValueError`` (JSON and TOML decode errors are ones; so is an integer of more than
    4 300 digits) is one ``UserError`` line described by ``describe``."""
    p = Path(path)
    try:
        size = p.stat().st_size if p.is_file() else 0
    except OSError:
        size = 0
    if size > max_bytes:
        raise UserError(f"{p}: {size:,} bytes; larger than any {what} ({max_bytes:,})")
    text = read_user_text(p)
    try:
        return parse(text)
    except RecursionError:
        raise UserError(f"{p}: nested too deeply") from None
    except ValueError as exc:
        raise UserError(f"{p}: {describe(exc)}") from None


class LinkError(UserError):
    """The serial link or endpoint could not be opened or failed."""


def writable_folder(path: str | os.PathLike[str], option: str = "--report") -> Path:
    """The folder ``path`` the user named for output, created if needed and checked writable
    before any work is done: a folder that cannot be written is one ``UserError`` line."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise UserError(f"{option} {p}: a file is in the way (expected a folder)") from None
    except OSError as exc:
        raise UserError(f"{option} {p}: cannot create the folder: {exc.strerror or exc}"
                        ) from None
    try:   # a file made and removed: permissions, a read-only or special file system alike
        with tempfile.TemporaryFile(dir=p):
            pass
    except OSError as exc:
        raise UserError(f"{option} {p}: cannot write there: {exc.strerror or exc}") from None
    return p
