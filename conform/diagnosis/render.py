"""The diagnosis as text: the one sentence first, then the causes, the lines as the unit read
them and the resume point."""

from __future__ import annotations

from typing import Any

MAX_RECEPTION = 20
FATE_ORDER = {"damaged-valid": 0, "damaged": 1, "merged": 2, "truncated": 3}


def _ranges(numbers: list[int]) -> str:
    """1,2,3,7 -> "1-3, 7" (at most a dozen ranges, then a count)."""
    runs: list[list[int]] = []
    for n in numbers:
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    text = [f"{a}-{b}" if b > a else str(a) for a, b in runs[:12]]
    return ", ".join(text) + (f", … ({len(runs) - 12} more ranges)" if len(runs) > 12 else "")


def text_lines(d: Any) -> list[str]:
    f = d.facts
    out = [d.headline(), ""]
    out.append(f"{d.path}: {f.family} {f.variant}, {len(f.exchanges)} lines in "
               f"{f.duration:.3f} s")
    o = getattr(d, "outcome", None)
    if o is not None:
        m = o.measured
        out.append(f"outcome: {o.kind}" + (f" (by the {o.by})" if o.by else "")
                   + ("" if m is None or d.causes else
                      f"; confidence {m[0] / m[1]:.2f}, n={m[1]} in the labelled corpus"))
        out += [f"  - {e}" for e in o.evidence[:4]]
    for k, c in enumerate(d.causes, 1):
        out.append(f"{k}. {c.kind} ({c.shown()}) {c.t_start:.3f}-{c.t_end:.3f} s: "
                   f"{c.summary}")
        out += [f"     - {e}" for e in c.evidence[:6]]
        out.append(f"     next: {c.advice}")
    hazards = getattr(d, "hazards", [])
    if hazards:
        out += ["", "hazards on the way (not what ended the session):"]
    for c in hazards[:8]:
        out.append(f"  {c.kind} (score {c.confidence:.2f}) {c.t_start:.3f}-{c.t_end:.3f} s: "
                   f"{c.summary}")
        out += [f"     - {e}" for e in c.evidence[:3]]
    if len(hazards) > 8:
        out.append(f"  … and {len(hazards) - 8} more")
    if d.reception:
        out += ["", "as the unit read it (host line -> what the unit parsed), what ran wrong "
                    "first:"]
        shown = sorted((p for p in d.reception if p.fate != "dropped"),
                       key=lambda p: (FATE_ORDER.get(p.fate, 9), p.host[:1]))
        for p in shown[:MAX_RECEPTION]:
            lines = ",".join(str(i + 1) for i in p.host)
            out.append(f"  {p.fate:13} line {lines} {p.sent!r} -> {p.parsed!r}  ({p.why})")
        if len(shown) > MAX_RECEPTION:
            out.append(f"  … and {len(shown) - MAX_RECEPTION} more")
        dropped = sorted(p.host[0] + 1 for p in d.reception if p.fate == "dropped" and p.host)
        if dropped:
            out.append(f"  dropped       {len(dropped)} line(s) never reached the parser: "
                       f"{_ranges(dropped)}")
    elif d.reception is not None:
        out += ["", "as the unit read it: every line intact"]
    r = d.resume
    if r is not None:
        def n(i: int | None) -> str:
            return "none" if i is None else str(i + 1)
        out += ["", f"resume: last executed line {n(r.last_executed)}, last acknowledged "
                    f"{n(r.last_acknowledged)}, uncertain "
                    f"{_ranges([i + 1 for i in r.uncertain]) or 'none'}",
                f"  {r.command}"]
        out += [f"  preamble: {' / '.join(r.preamble)}"] if r.preamble else []
        out += [f"  - {e}" for e in r.evidence]
    out += [f"note: {x}" for x in f.notes + d.notes]
    return out
