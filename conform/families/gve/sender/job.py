"""A job: the command lines a sender streams, from a vector file or G-code.

A vector file has one command per line, with or without ``!`` and the address
(``C100,20,0``, ``!0V2000``); blank lines and ``#`` / ``;`` comments are skipped. Every line
is checked against the spec tables before anything is sent, so a typo stops the job at
load time with the file and line number.
"""

from __future__ import annotations

import os
from pathlib import Path

from conform.errors import UserError
from conform.families.gve.protocol import CommandParser
from conform.families.gve.sender.gcode import GcodeOptions, gcode_to_items
from conform.families.gve.sender.items import PACKABLE, Item, parse_item
from conform.families.gve.spec.model import Dialect, Variant

__all__ = ["PACKABLE", "Item", "load_job", "load_vector_file", "parse_item"]

def load_vector_file(path: str | os.PathLike[str], variant: Variant,
                     dialect: Dialect) -> list[Item]:
    p = Path(path)
    try:
        text = p.read_text(encoding="ascii", errors="replace")
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror}") from None
    parser = CommandParser(variant, dialect)
    items = []
    for no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].split(";", 1)[0].strip()
        if line:
            items.append(parse_item(line, variant, parser, f"{p}:{no}"))
    if not items:
        raise UserError(f"{p}: no commands in the file")
    return items


def load_job(path: str | os.PathLike[str], variant: Variant, dialect: Dialect,
             **gcode_options: object) -> list[Item]:
    """A vector file, or G-code when the name ends in .nc/.gcode/.ngc/.tap/.g."""
    p = Path(path)
    if p.suffix.lower() in (".nc", ".gcode", ".ngc", ".tap", ".g", ".cnc"):
        opts = GcodeOptions(**gcode_options)  # type: ignore[arg-type]
        try:
            text = p.read_text(encoding="ascii", errors="replace")
        except OSError as exc:
            raise UserError(f"{p}: cannot read: {exc.strerror}") from None
        return gcode_to_items(text, variant, dialect, opts, source=str(p))
    return load_vector_file(p, variant, dialect)
