"""What ``conform characterize`` found on a unit, item by item: the observed value next to the
tables' value with the evidence, printed one line each and written as a TOML profile
(``[observed]``, ``[table]``, ``[evidence]``) that ``conform profile diff`` compares."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from conform.errors import UserError
from conform.jsondoc import JsonObject

if TYPE_CHECKING:
    from conform.conformance.target import Target
    from conform.families import Family


@dataclass
class Observation:
    name: str
    table: object      # what the tables say
    observed: object   # what the unit did
    evidence: str

    @property
    def same(self) -> bool:
        return self.observed == self.table


def _toml(x: object) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    return '"' + str(x).replace("\\", "\\\\").replace('"', '\\"') + '"'


def write_profile(obs: Sequence[Observation], path: str, *, target: str, variant: str,
                  title: str, interrupted: str | None = None,
                  unanswered: Sequence[str] = ()) -> None:
    """The profile file; an item not observed has no ``[observed]`` entry. An interrupted
    characterisation is marked ``partial`` with how it stopped and the items not reached."""
    lines = [f"# {title}", f"target = {_toml(target)}", f"variant = {_toml(variant)}"]
    if interrupted is not None:
        lines += ["partial = true", f"interrupted = {_toml(interrupted)}",
                  "unanswered = [" + ", ".join(_toml(n) for n in unanswered) + "]"]
    lines += ["", "[observed]"]
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


def report(obs: Sequence[Observation], output: str, echo: Callable[[str], object] = print) -> None:
    """One line per item (``=`` as the tables say, ``!`` not), then the count that differ."""
    for o in obs:
        mark = "=" if o.same else "!"
        echo(f"{o.name:>18} {mark} {o.observed!s:<12} (table: {o.table}) — {o.evidence}")
    differ = [o.name for o in obs if not o.same]
    echo(f"{output}: {len(differ)} item(s) differ from the tables"
         + (": " + ", ".join(differ) if differ else ""))


Probe = Callable[["Target", str, list[Observation]], object]
"""probe(target, variant, out): appends each Observation to ``out`` as it is found."""

ProbeHooks = tuple[Probe, Callable[["Target"], str], Sequence[str]]
"""``Family.characterize_probes``: (probe, stop(target) halting the unit, the items probed)."""


def characterize_target(fam: Family, target_text: str, output: str, variant: str | None, *,
                        baud: int, probe: Probe, stop: Callable[[Target], str],
                        items: Sequence[str], title: str,
                        echo: Callable[[str], object] = print) -> None:
    """``conform characterize`` for a family whose probes yield observations: open the target
    (``emu:VARIANT[:MUTANT]`` or a port) and probe, the unit halted by ``stop`` however the run
    ends; then write the profile and print it. Stopped by a signal, it writes what was found
    so far as a partial profile (``items``: what is probed, in order; a name ending in ``*``
    stands for every item it begins) and exits 128 + N."""
    from conform.conformance.target import HarnessError
    from conform.stops import halting

    target, implied = fam.open_target(target_text, baud=baud, permissions=None)
    vid = variant or implied or fam.default_variant
    obs: list[Observation] = []

    def partial(how: str) -> str:
        done = {o.name for o in obs}
        left = [n for n in items if n not in done and not (
            n.endswith("*") and any(d.startswith(n[:-1]) for d in done))]
        write_profile(obs, output, target=target_text, variant=vid, title=title,
                      interrupted=f"{how} after {len(obs)} items", unanswered=left)
        return f"partial profile {output}: {len(obs)} items found, {len(left)} not reached"

    try:
        known = [v.id for v in fam.variants()]
        if vid not in known:
            raise UserError(f"{vid!r} is not a {fam.name} variant (known: {', '.join(known)})")
        with halting(None if target.emulated else lambda: stop(target), partial):
            try:
                probe(target, vid, obs)
            except HarnessError as exc:   # the unit fell silent: say so, never a profile of guesses
                said = partial("the unit stopped answering") if obs else "Nothing was written"
                raise UserError(f"{target_text}: the unit did not answer ({exc}): is it on, on "
                                f"this port and at this baud rate (--baud)? {said}") from None
    finally:
        target.close()
    write_profile(obs, output, target=target_text, variant=vid, title=title)
    report(obs, output, echo)


def diff_observed(a: str, doc_a: JsonObject, b: str, doc_b: JsonObject
                  ) -> tuple[list[str], list[tuple[str, object, object]], str]:
    """Two observation profiles item by item: (notes on partial ones, rows (item, a, b) that
    differ, the line when none does)."""
    notes = []
    for path, doc in ((a, doc_a), (b, doc_b)):
        left = doc.get("unanswered") if doc.get("partial") is True else None
        if isinstance(left, list):
            notes.append(f"{path}: partial profile ({doc.get('interrupted', 'interrupted')}); "
                         f"{len(left)} item(s) not reached: {', '.join(map(str, left))}")
    oa, ob = doc_a.get("observed", {}), doc_b.get("observed", {})
    names = list(dict.fromkeys([*oa, *ob, *_left(doc_a), *_left(doc_b)]))

    def shown(doc: JsonObject, obs: JsonObject, name: str) -> object:
        if name in obs:
            return obs[name]
        return "(not answered)" if name in _left(doc) else "(absent)"

    rows = [(n, shown(doc_a, oa, n), shown(doc_b, ob, n)) for n in names
            if shown(doc_a, oa, n) != shown(doc_b, ob, n) or n in _left(doc_a) or n in _left(doc_b)]
    return notes, rows, "same observations"


def _left(doc: JsonObject) -> list[str]:
    left = doc.get("unanswered") if doc.get("partial") is True else None
    return [str(x) for x in left] if isinstance(left, list) else []
