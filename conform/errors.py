"""User-facing errors: one line, a non-zero exit, never a traceback."""

from pathlib import Path


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


class LinkError(UserError):
    """The serial link or endpoint could not be opened or failed."""
