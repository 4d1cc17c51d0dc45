"""What ``conform characterize`` found on a unit, item by item: the observed value next to the
tables' value with the evidence, printed one line each and written as a TOML profile
(``[observed]``, ``[table]``, ``[evidence]``) that ``conform profile diff`` compares."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from conform.errors import UserError


@dataclass
class Observation:
    name: str
    table: Any
    observed: Any
    evidence: str

    @property
    def same(self) -> bool:
        return self.observed == self.table


def _toml(x: Any) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    return '"' + str(x).replace("\\", "\\\\").replace('"', '\\"') + '"'


def write_profile(obs: Sequence[Observation], path: str, *, target: str, variant: str,
                  title: str) -> None:
    """The profile file; an item not observed has no ``[observed]`` entry."""
    lines = [f"# {title}", f"target = {_toml(target)}", f"variant = {_toml(variant)}", "",
             "[observed]"]
    lines += [f"{_key(o.name)} = {_toml(o.observed)}" for o in obs if o.observed is not None]
    lines += ["", "[table]"] + [f"{_key(o.name)} = {_toml(o.table)}" for o in obs
                                if o.table is not None]
    lines += ["", "[evidence]"] + [f"{_key(o.name)} = {_toml(o.evidence)}" for o in obs]
    try:
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None


def _key(name: str) -> str:
    return name if name.replace("_", "").isalnum() else _toml(name)


def report(obs: Sequence[Observation], output: str, echo: Callable[[str], Any] = print) -> None:
    """One line per item (``=`` as the tables say, ``!`` not), then the count that differ."""
    for o in obs:
        mark = "=" if o.same else "!"
        echo(f"{o.name:>18} {mark} {o.observed!s:<12} (table: {o.table}) — {o.evidence}")
    differ = [o.name for o in obs if not o.same]
    echo(f"{output}: {len(differ)} item(s) differ from the tables"
         + (": " + ", ".join(differ) if differ else ""))


def characterize_target(fam: Any, target_text: str, output: str, variant: str | None, *,
                        baud: int, probe: Callable[[Any, str], list[Observation]],
                        stop: Callable[[Any], Any], title: str,
                        echo: Callable[[str], Any] = print) -> None:
    """``conform characterize`` for a family whose probes yield observations: open the target
    (``emu:VARIANT[:MUTANT]`` or a port), probe with the unit halted by ``stop`` however the
    run ends, then write the profile and print it."""
    from conform.stops import halting

    target, implied = fam.open_target(target_text, baud=baud, permissions=None)
    vid = variant or implied or fam.default_variant
    try:
        known = [v.id for v in fam.variants()]
        if vid not in known:
            raise UserError(f"{vid!r} is not a {fam.name} variant (known: {', '.join(known)})")
        with halting(None if target.emulated else lambda: stop(target)):
            obs = probe(target, vid)
    finally:
        target.close()
    write_profile(obs, output, target=target_text, variant=vid, title=title)
    report(obs, output, echo)
