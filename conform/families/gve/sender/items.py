"""One command of a job, checked against the spec tables: what a vector file's line and a
G-code block both become (job.py reads the files, gcode.py translates G-code)."""

from __future__ import annotations

from dataclasses import dataclass

from conform.errors import UserError
from conform.families.gve.protocol import Command, CommandParser
from conform.families.gve.spec.model import Variant

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
