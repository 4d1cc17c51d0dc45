"""``conform spec show marlin-…  [PART]``: Marlin's tables as a reader wants them. PART
``base`` is the variant's delta on its base (``conform spec diff`` for Marlin)."""

from __future__ import annotations

import json
from typing import Any

from rich.table import Table

from conform.errors import UserError
from conform.families.marlin.spec import diff, load_marlin

PARTS = ("commands", "messages", "caps", "options", "base")


def rows(variant: str, part: str) -> tuple[str, tuple[str, ...], list[tuple[str, ...]]]:
    """(title, columns, rows) of one part of a variant's tables."""
    spec = load_marlin()
    v = spec.variant(variant)
    if part == "":
        fields = ("firmware", "baud", "bufsize", "max_cmd_size", "rx_buffer", "block_buffer",
                  "keepalive", "extruders", "steps_per_mm", "max_feedrate")
        return (f"{v.title} ({v.id})", ("field", "value", "source"),
                [(f, str(getattr(v, f)), v.cite.get(f, "")) for f in fields])
    if part == "commands":
        return (f"{v.id}: commands", ("command", "kind", "motion", "heat", "source"),
                [(c.code, c.kind, "yes" if c.motion else "", "yes" if c.heat else "", c.cite)
                 for c in spec.commands.values() if spec.command(c.code, v)])
    if part == "messages":
        return (f"{v.id}: messages", ("kind", "pattern", "answers", "source"),
                [(m.kind, m.pattern.pattern, "yes" if m.answers else "", m.cite)
                 for m in spec.messages.values()])
    if part == "caps":
        return (f"{v.id}: M115 capabilities", ("cap", "value", "option"),
                [(c.name, str(c.value(v)), c.option or "always") for c in spec.caps])
    if part == "options":
        return (f"{v.id}: configuration", ("option", "enabled", "source"),
                [(k, str(on).lower(), v.cite.get("options", "")) for k, on in sorted(v.options.items())])
    if part == "base":
        if v.base is None:
            raise UserError(f"{v.id} is a base variant (no delta to show)")
        return (f"{v.base} → {v.id}", ("what", v.base, v.id, "source"),
                list(diff(spec.variant(v.base), v)))
    cmd = spec.command(part.upper(), v)
    if cmd is not None:   # one command, as `spec show gve124 V` shows one
        return (f"{v.id}: {cmd.code}", ("command", "kind", "motion", "heat", "option", "source"),
                [(cmd.code, cmd.kind, "yes" if cmd.motion else "", "yes" if cmd.heat else "",
                  cmd.option or "always", cmd.cite)])
    raise UserError(f"{v.id}: nothing called {part!r}: a part ({', '.join(PARTS)}) or a "
                    f"command of {v.id} (e.g. M115; `conform spec show {v.id} commands` "
                    "lists them)")


def show(variant: str, what: str | None, console: Any, as_json: bool = False) -> None:
    title, cols, body = rows(variant, (what or "").lower())
    if as_json:
        print(json.dumps({"title": title, "rows": [dict(zip(cols, r, strict=True)) for r in body]},
                         indent=1))
        return
    table = Table(title=title)
    for col in cols:
        table.add_column(col, overflow="fold")
    for r in body:
        table.add_row(*r)
    console.print(table)
    if not what:
        console.print(f"parts: {', '.join(PARTS)} (conform spec show {variant} PART)")
