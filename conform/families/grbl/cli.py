"""``conform spec show grbl-1.1f [WHAT]``: the grbl tables as a reader wants them."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from conform.errors import UserError
from conform.families.grbl.spec.load import load_grbl

PARTS = ("settings", "errors", "alarms", "commands", "realtime", "messages")


def show(variant: str, what: str | None, console: Console) -> None:
    g = load_grbl()
    v = g.variant(variant)
    part = (what or "").lower()
    one = None if not part or part in PARTS else next(
        (c for c in g.commands.values() if c.name.upper() == (what or "").upper()
         or c.syntax.match((what or "").upper())), None)
    if part and part not in PARTS and one is None:
        raise UserError(f"{v.id}: nothing called {what!r}: a part ({', '.join(PARTS)}) or a "
                        f"$ command (e.g. '$H'; `conform spec show {v.id} commands` lists them)")
    if one is not None:   # one command, as `spec show gve124 V` shows one
        table = Table(title=f"{v.id}: {one.name}", show_header=False)
        table.add_column("field")
        table.add_column("value", overflow="fold")
        for name, value in (("command", one.name), ("states", one.states),
                            ("prints", ", ".join(one.prints) or "-"), ("meaning", one.meaning),
                            ("source", one.cite)):
            table.add_row(name, value)
        console.print(table)
        return
    if not part:
        table = Table(title=f"{v.title} ({v.id})", show_header=False)
        table.add_column("field")
        table.add_column("value")
        table.add_column("source", overflow="fold")
        for name in ("version", "build", "baud", "rx_buffer", "line_max", "planner_blocks",
                     "options", "crlf_is_two_lines"):
            table.add_row(name, str(getattr(v, name)), v.cite.get(name, ""))
        console.print(table)
        console.print(f"parts: {', '.join(PARTS)} (conform spec show {v.id} PART)")
        return
    table = Table(title=f"{v.id}: {part}")
    if part == "settings":
        cols = ("$", "name", "unit", "type", "range", "default", "source")
        rows = [(f"${n}", s.name, s.unit, s.type, f"{s.text(s.lo)}..{s.text(s.hi)}"
                 if s.hi < 1e30 else f"≥ {s.text(s.lo)}", s.text(s.default), s.cite)
                for n, s in g.settings.items()]
    elif part in ("errors", "alarms"):
        codes = g.errors if part == "errors" else g.alarms
        cols = ("code", "name", "meaning", "emulated", "source")
        rows = [(str(n), c.name, c.meaning, "yes" if c.emulated else "no", c.cite)
                for n, c in codes.items()]
    elif part == "commands":
        cols = ("command", "states", "prints", "meaning", "source")
        rows = [(c.name, c.states, ", ".join(c.prints), c.meaning, c.cite)
                for c in g.commands.values()]
    elif part == "realtime":
        cols = ("byte", "name", "effect", "source")
        rows = [(f"0x{b:02X}", r.name, r.effect, r.cite) for b, r in g.realtime.items()]
    else:
        cols = ("kind", "pattern", "answers a line", "source")
        rows = [(m.kind, m.pattern.pattern, "yes" if m.answers else "", m.cite)
                for m in g.messages.values()]
    for col in cols:
        table.add_column(col, overflow="fold")
    for row in rows:
        table.add_row(*row)
    console.print(table)
