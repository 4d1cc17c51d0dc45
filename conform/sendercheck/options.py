"""What ``conform check-sender`` checks of its options before any session starts, whichever
family judges the sender: one-line errors naming the option or file."""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path

from conform.errors import UserError, read_user_text, writable_folder

MAX_TIMEOUT_S = 86400


def require_program(command: list[str]) -> None:
    """The sender to judge: given, and a program that can be run."""
    if not command:
        raise UserError("no program given: conform check-sender [OPTIONS] -- COMMAND ARGS... "
                        "(`{port}` in ARGS becomes the device path)")
    if shutil.which(command[0]) is None:
        raise UserError(f"{command[0]}: no such program (not found or not executable)")
    if not any("{port}" in arg or "CONFORM_PORT" in arg for arg in command):
        raise UserError(f"no {{port}} in `{shlex.join(command)}`: write {{port}} where the "
                        "program takes the device path (a program that reads $CONFORM_PORT "
                        "itself: -- env CONFORM_PORT={port} PROGRAM ...)")


def check_timeout(timeout: float | None) -> None:
    if timeout is not None and not 0 < timeout <= MAX_TIMEOUT_S:
        raise UserError(f"--timeout {timeout:g}: seconds, more than 0 and at most "
                        f"{MAX_TIMEOUT_S}")


def job_of_family(lines: list[str] | None, job_file: str | None, moves: int, family: str
                  ) -> None:
    """A ``--job`` in which the family finds nothing its unit would execute (``moves`` 0) is
    another family's (a g-code file for a vector unit, or the reverse): a usage error, not a
    sender that fails every rule."""
    if lines is not None and not moves:
        raise UserError(f"--job {job_file}: no line of it is a move a {family} unit executes; "
                        "is it a job of another family?")


def read_job(job_file: str | None) -> list[str] | None:
    """The non-blank lines of ``--job`` (None without one)."""
    if job_file is None:
        return None
    text = read_user_text(job_file)
    for n, line in enumerate(text.splitlines(), 1):
        if not line.isascii():
            col = next(i for i, c in enumerate(line) if not c.isascii()) + 1
            raise UserError(f"{job_file}: line {n}, column {col}: not ASCII (a unit's job is "
                            "plain ASCII)")
    lines = [x for x in text.splitlines() if x.strip()]
    if not lines:
        raise UserError(f"{job_file}: no job lines in the file")
    return lines


def report_folder(report_dir: str | None) -> Path:
    """``--report``, else ``reports/check-sender-<timestamp>/``."""
    from conform.report.render import default_dir

    if report_dir:
        return writable_folder(report_dir, "--report")
    return writable_folder(default_dir(prefix="check-sender-"))
