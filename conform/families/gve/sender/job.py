"""A job: the command lines a sender streams, from a vector file or G-code.

A vector file has one command per line, with or without ``!`` and the address
(``C100,20,0``, ``!0V2000``); blank lines and ``#`` / ``;`` comments are skipped. Every line
is checked against the spec tables before anything is sent, so a typo stops the job at
load time with the file and line number.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from conform.errors import UserError
from conform.families.gve.protocol import Command, CommandParser
from conform.families.gve.spec.model import Dialect, Variant

PACKABLE = ("C", "B")  # the only commands a packet may carry (GVE64 §13.3.3)


@dataclass(frozen=True)
class Item:
    """One command of a job: ``body`` is the line without ``!``, address and terminator."""

    body: bytes
    name: str
    motion: bool
    source: str = ""  # "file:line" for messages

    @property
    def vector(self) -> tuple[int, ...] | None:
        if self.name not in ("C", "L"):
            return None
        return tuple(int(x) for x in self.body[1:].split(b","))


def parse_item(text: str, variant: Variant, parser: CommandParser, where: str = "") -> Item:
    line = text.strip()
    if line.startswith("!"):
        line = line[2:] if len(line) >= 2 and line[1].isdigit() else line[1:]
    try:
        body = line.encode("ascii")
    except UnicodeEncodeError:
        raise UserError(f"{where}: not ASCII: {text.strip()[:40]!r}") from None
    addr = variant.interpolator_address
    r = parser.parse(b"!%d" % addr + body, False)
    if not isinstance(r, Command):
        raise UserError(f"{where}: {r.detail}")
    spec = variant.commands[r.name]
    return Item(body, r.name, bool(spec.motion), where)


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
        from conform.families.gve.sender.gcode import GcodeOptions, gcode_to_items

        opts = GcodeOptions(**gcode_options)  # type: ignore[arg-type]
        try:
            text = p.read_text(encoding="ascii", errors="replace")
        except OSError as exc:
            raise UserError(f"{p}: cannot read: {exc.strerror}") from None
        return gcode_to_items(text, variant, dialect, opts, source=str(p))
    return load_vector_file(p, variant, dialect)
