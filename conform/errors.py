"""User-facing errors: one line, a non-zero exit, never a traceback."""


class UserError(Exception):
    """A mistake in what the user gave us (a file, an option, a table row).

    The CLI prints ``str(err)`` on one line and exits with ``exit_code``.
    """

    exit_code = 2

    def __init__(self, message: str, exit_code: int | None = None) -> None:
        super().__init__(message)
        if exit_code is not None:
            self.exit_code = exit_code


class LinkError(UserError):
    """The serial link or endpoint could not be opened or failed."""
