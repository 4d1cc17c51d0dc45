"""``conform spec show marlin-…  [PART]``: Marlin's tables as a reader wants them. PART
``base`` is the variant's delta on its base (``conform spec diff`` for Marlin)."""

from __future__ import annotations

import json
import re
from typing import Any

from rich.table import Table
from rich.text import Text

from conform.errors import UserError
from conform.families.marlin.spec import diff, load_marlin

PARTS = ("commands", "messages", "caps", "options", "base")


def rows(variant: str, part: str) -> tuple[str, tuple[str, ...], list[tuple[str, ...]]]:
    """(title, columns, rows) of one part of a variant's tables."""
    spec = load_marlin()
    v = spec.variant(variant)
    if part == "":
        fields = ("firmware", "baud", "bufsize", "max_cmd_size", "rx_buffer", "block_buffer",
                  "keepalive", "extruders", "steps_per_mm", "max_feedrate", "first_home_ms",
                  "motion_time_pct")
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
    if re.fullmatch(r"[gmt]\d+", part):
        return command(spec, v, part.upper())
    raise UserError(f"{v.id}: nothing called {part!r}: a part ({', '.join(PARTS)}) or a "
                    f"command of {v.id} (e.g. M115; `conform spec show {v.id} commands` "
                    "lists them)")


def command(spec: Any, v: Any, code: str) -> tuple[str, tuple[str, ...], list[tuple[str, ...]]]:
    """One command of the build: what the unit does with it, its source; a setting's
    power-up values; M115's capability lines."""
    from conform.families.marlin.unit import settings as st

    row = spec.commands.get("T0" if code[0] == "T" else code)
    title = f"{v.id}: {code}"
    if row is None:
        # the unit answers it echo:Unknown command: "…" and ok (gcode.cpp
        # GcodeSuite::process_parsed_command, unknown_command_warning)
        raise UserError(f"no command {code} in {v.id}'s tables (the unit answers it "
                        f"echo:Unknown command: \"{code}\" and ok; `conform spec show {v.id} "
                        "commands` lists them)")
    built = spec.command(row.code, v) is not None
    out = [("in this build", "yes" if built else f"no: needs {row.option}"),
           ("kind", row.kind), ("moves", "yes" if row.motion else "no"),
           ("heats", "yes" if row.heat else "no"), ("source", row.cite)]
    if code[0] == "T":
        out.insert(1, ("tools", f"T0..T{v.extruders - 1} (EXTRUDERS {v.extruders}); "
                                f"T{v.extruders} and up: echo:T<n> Invalid extruder"))
    if code in st.ORDER:
        values = st.defaults(v)[code]
        out.insert(1, ("power-up", st.report_line(code, values).strip()))
        out.insert(2, ("M503 heading", st.table().headings[code]))
    if code == "M115":
        caps = [f"Cap:{c.name}:{c.value(v)}" for c in spec.caps] if v.on(
            "EXTENDED_CAPABILITIES_REPORT") else []
        out.insert(1, ("first line", f"FIRMWARE_NAME:Marlin {v.firmware} (…) SOURCE_CODE_URL:"
                       f"{v.source_url} PROTOCOL_VERSION:{v.protocol_version} MACHINE_TYPE:"
                       f"{v.machine_name} EXTRUDER_COUNT:{v.extruders} UUID:{v.uuid}"))
        out.insert(2, ("capabilities", " ".join(caps) or "none (EXTENDED_CAPABILITIES_REPORT "
                                                          "off)"))
    return title, ("field", "value"), out


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
        table.add_row(*(Text(x) for x in r))   # as written (":REPEAT:" is no emoji)
    console.print(table)
    if not what:
        console.print(f"parts: {', '.join(PARTS)} (conform spec show {variant} PART)")
