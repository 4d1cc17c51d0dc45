"""``conform spec show grbl-1.1f [WHAT]``: the grbl tables as a reader wants them."""

from __future__ import annotations

import re
from typing import Any

from rich.console import Console
from rich.table import Table

from conform.errors import UserError
from conform.families.grbl.spec.load import load_grbl

PARTS = ("settings", "errors", "alarms", "commands", "realtime", "messages")


def one(g: Any, what: str) -> list[tuple[str, str]] | None:
    """One row of the tables by its name: a command (``$H``), a setting (``$110``), an error
    (``error:9``), an alarm (``ALARM:1``) or a realtime byte (``?``, ``0x18``)."""
    key = what.strip()
    cmd = next((c for c in g.commands.values() if c.name.upper() == key.upper()), None) or \
        next((c for c in g.commands.values() if c.syntax.match(key.upper())), None)
    if cmd is not None:
        return [("command", cmd.name), ("allowed in", cmd.states),
                ("prints", ", ".join(cmd.prints) or "ok only"), ("meaning", cmd.meaning),
                ("source", cmd.cite)]
    m = re.fullmatch(r"\$(\d+)", key)
    if m and int(m.group(1)) in g.settings:
        st = g.settings[int(m.group(1))]
        return [("setting", key), ("name", st.name), ("unit", st.unit), ("type", st.type),
                ("range", f"{st.text(st.lo)}..{st.text(st.hi)}" if st.hi < 1e30 else
                 f">= {st.text(st.lo)}"), ("default", st.text(st.default)), ("source", st.cite)]
    m = re.fullmatch(r"(error|alarm):(\d+)", key, re.IGNORECASE)
    if m:
        codes = g.errors if m.group(1).lower() == "error" else g.alarms
        c = codes.get(int(m.group(2)))
        if c is not None:
            return [("code", key), ("name", c.name), ("meaning", c.meaning),
                    ("emulated", "yes" if c.emulated else "no"), ("source", c.cite)]
        return None
    byte = int(key, 16) if re.fullmatch(r"0x[0-9a-fA-F]{1,2}", key) else \
        ord(key) if len(key) == 1 else None
    r = g.realtime.get(byte) if byte is not None else None
    if r is not None:
        return [("byte", f"0x{r.byte:02X}"), ("name", r.name), ("effect", r.effect),
                ("meaning", r.meaning), ("source", r.cite)]
    return None


def show(variant: str, what: str | None, console: Console) -> None:
    g = load_grbl()
    v = g.variant(variant)
    part = (what or "").lower()
    if part and part not in PARTS:
        found = one(g, what or "")
        if found is None:
            raise UserError(f"no command, setting, error or alarm {what!r} in {v.id}'s tables "
                            f"(a part: {', '.join(PARTS)}; or one such as $H, $110, error:9)")
        table = Table(title=f"{v.id}: {what}", show_header=False)
        table.add_column("field")
        table.add_column("value", overflow="fold")
        for row in found:
            table.add_row(*row)
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
