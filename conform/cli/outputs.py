"""What a command writes, checked before it starts: a capture already recorded is never
replaced without ``--force``, a report folder that cannot be written and a link path taken by a
file are one line (exit 2) before any work is done — so nothing recorded is lost to a typo or
to re-running a recipe."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import click

from conform.errors import UserError, writable_folder

if TYPE_CHECKING:
    from collections.abc import Callable

    from click.decorators import FC

__all__ = ["force_option", "free_link", "fresh_output", "writable_folder"]


def force_option(what: str = "FILE") -> Callable[[FC], FC]:
    """``--force``: replace an existing output file."""
    return click.option("--force", is_flag=True,
                        help=f"Replace {what} if it exists (by default an existing file is "
                             "refused, so a recorded session is never overwritten).")


def fresh_output(path: str | os.PathLike[str] | None, force: bool, option: str) -> None:
    """Refuse ``path`` when a file is already there, unless ``force``, and when its folder
    cannot be made or written (a file in the way, no permission): before the work."""
    if path is None:
        return
    p = Path(path)
    if p.is_dir():
        raise UserError(f"{option} {p}: is a folder; name a file in it")
    writable_folder(p.parent, f"{option} {p}: its folder")
    if force:
        return
    if p.exists() or p.is_symlink():
        raise UserError(f"{option} {p}: the file exists; choose another name or add --force "
                        "to replace it")


def free_link(path: str | os.PathLike[str] | None, option: str = "--link") -> None:
    """A symlink path to create: free, or a symlink (replaced); anything else is refused."""
    if path is None:
        return
    p = Path(path)
    if p.is_symlink():
        return
    if p.exists():
        kind = "folder" if p.is_dir() else "file"
        raise UserError(f"{option} {p}: a {kind} is there (only a symlink is replaced); "
                        "choose another path")
    if not p.parent.is_dir():
        raise UserError(f"{option} {p}: no folder {p.parent}")
