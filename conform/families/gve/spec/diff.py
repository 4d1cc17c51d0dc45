"""What differs between two variants: commands, ranges, queue, axes, status words, reset, EEPROM."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from conform.families.gve.spec.model import Variant


@dataclass(frozen=True, slots=True)
class Difference:
    kind: str  # command-added | command-removed | range | field | reset | eeprom
    what: str
    a: Any
    b: Any
    clause: str


def _fmt_range(r: tuple[Any, Any] | None) -> str:
    return "-" if r is None else f"{r[0]}..{r[1]}"


def diff_variants(a: Variant, b: Variant) -> list[Difference]:
    """Differences from ``a`` to ``b``, each with the clause of ``b`` (or ``a`` for removals)."""
    out: list[Difference] = []
    for cid in b.commands:
        if cid not in a.commands:
            out.append(Difference("command-added", cid, "absent", "present",
                                  b.commands[cid].clause_for(b.manual)))
    for cid in a.commands:
        if cid not in b.commands:
            out.append(Difference("command-removed", cid, "present", "absent",
                                  b.clause("remove_commands") if b.base else a.commands[cid].clause_for(a.manual)))
    for cid, cb in b.commands.items():
        ca = a.commands.get(cid)
        if ca is None:
            continue
        for pa, pb in zip(ca.params, cb.params, strict=False):
            if (pa.lo, pa.hi) != (pb.lo, pb.hi):
                out.append(Difference("range", f"{cid}.{pb.name}", _fmt_range((pa.lo, pa.hi)),
                                      _fmt_range((pb.lo, pb.hi)), cb.clause_for(b.manual)))
    fields = ("manual", "firmware", "axes", "queue", "max_rate", "bauds", "status_words",
              "input_bits", "addresses")
    for name in fields:
        va, vb = getattr(a, name), getattr(b, name)
        if _norm(va) != _norm(vb):
            out.append(Difference("field", name, _show(va), _show(vb), b.clause(name)))
    if a.eeprom.name != b.eeprom.name:
        out.append(Difference("field", "eeprom_map", a.eeprom.name, b.eeprom.name, b.clause("eeprom_map")))
    for key in sorted(set(a.reset) | set(b.reset)):
        if a.reset.get(key) != b.reset.get(key):
            out.append(Difference("reset", key, a.reset.get(key, "-"), b.reset.get(key, "-"), b.clause("reset")))
    if a.extras != b.extras:
        for key in sorted(set(a.extras) | set(b.extras)):
            if a.extras.get(key) != b.extras.get(key):
                out.append(Difference("field", key, a.extras.get(key), b.extras.get(key), b.clause(key)))
    return out


def _norm(value: Any) -> Any:
    if hasattr(value, "items"):
        return {k: _norm(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return tuple(value)
    return value


def _show(value: Any) -> str:
    value = _norm(value)
    if isinstance(value, tuple):
        return ",".join(str(v) for v in value)
    if isinstance(value, dict):
        return "; ".join(f"{k}={_show(v)}" for k, v in value.items())
    return str(value)
