"""The diagnosis as text: the one sentence first, then the causes, the lines as the unit read
them and the resume point."""

from __future__ import annotations

from typing import Any

MAX_RECEPTION = 20


def text_lines(d: Any) -> list[str]:
    f = d.facts
    out = [d.headline(), ""]
    out.append(f"{d.path}: {f.family} {f.variant}, {len(f.exchanges)} lines in "
               f"{f.duration:.3f} s")
    for k, c in enumerate(d.causes, 1):
        out.append(f"{k}. {c.kind} ({c.confidence:.2f}) {c.t_start:.3f}-{c.t_end:.3f} s: "
                   f"{c.summary}")
        out += [f"     - {e}" for e in c.evidence[:6]]
        out.append(f"     next: {c.advice}")
    if d.reception:
        out += ["", "as the unit read it (host line -> what the unit parsed):"]
        for p in d.reception[:MAX_RECEPTION]:
            lines = ",".join(str(i + 1) for i in p.host)
            out.append(f"  {p.fate:13} line {lines} {p.sent!r} -> {p.parsed!r}  ({p.why})")
        if len(d.reception) > MAX_RECEPTION:
            out.append(f"  … and {len(d.reception) - MAX_RECEPTION} more")
    elif d.reception is not None:
        out += ["", "as the unit read it: every line intact"]
    r = d.resume
    if r is not None:
        def n(i: int | None) -> str:
            return "none" if i is None else str(i + 1)
        out += ["", f"resume: last executed line {n(r.last_executed)}, last acknowledged "
                    f"{n(r.last_acknowledged)}, uncertain "
                    f"{', '.join(str(i + 1) for i in r.uncertain) or 'none'}",
                f"  {r.command}"]
        out += [f"  preamble: {' / '.join(r.preamble)}"] if r.preamble else []
        out += [f"  - {e}" for e in r.evidence]
    out += [f"note: {x}" for x in f.notes + d.notes]
    return out
