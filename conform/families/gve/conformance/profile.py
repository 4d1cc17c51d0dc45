"""Characterisation profiles: what a unit actually does on each open question, as TOML.

Format (shared with ``conform emulate --profile``)::

    [meta]
    target = "/dev/ttyUSB0"
    variant = "gve64-v19"
    [dialect]
    A10 = "every-line"
    [evidence.A10]
    status = "determined"          # determined | ambiguous | no-match | not-probed
    matches = ["every-line"]
    probe = ["!0@", "!0V1000", ...]
    answers = ["0,0", "0", ...]

An interrupted ``conform characterize`` writes ``partial = true``, ``interrupted`` (how and
after how many questions) and ``unanswered = ["A13", ...]`` in ``[meta]``, and only the
answered questions in ``[dialect]``.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.errors import UserError, load_user_file


@dataclass
class Profile:
    dialect: dict[str, str]
    meta: dict[str, Any] = field(default_factory=dict)
    evidence: dict[str, dict[str, Any]] = field(default_factory=dict)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(str(value), ensure_ascii=True)


def dumps(profile: Profile) -> str:
    out = ["# conform characterisation profile: what the unit does on each open question",
           "# (load it with `conform emulate --profile` or `conform run --dialect`)", "",
           "[meta]"]
    out += [f"{k} = {_toml_value(v)}" for k, v in profile.meta.items()]
    out += ["", "[dialect]"]
    out += [f"{k} = {_toml_value(v)}" for k, v in sorted(profile.dialect.items(), key=_qkey)]
    for q, ev in sorted(profile.evidence.items(), key=_qkey):
        out += ["", f"[evidence.{q}]"]
        out += [f"{k} = {_toml_value(v)}" for k, v in ev.items()]
    return "\n".join(out) + "\n"


def _qkey(item: tuple[str, Any]) -> tuple[int, str]:
    k = item[0]
    n = k[1:]
    return (int(n) if n.isascii() and n.isdigit() and len(n) < 10 else 1 << 31, k)


def write_profile(profile: Profile, path: str | Path) -> None:
    try:
        Path(path).write_text(dumps(profile), encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None


MAX_PROFILE_BYTES = 4 << 20
"""A profile is a few kB; a file past this is refused before it is read."""


def load_profile(path: str | Path) -> Profile:
    p = Path(path)
    data = load_user_file(p, tomllib.loads, max_bytes=MAX_PROFILE_BYTES, what="profile")
    dialect = data.get("dialect")
    if not isinstance(dialect, dict):
        raise UserError(f"{p}: {_whose(data) or 'no [dialect] table'}: a GVE dialect profile "
                        "is what `conform characterize` writes for a GVE unit")
    for k, v in dialect.items():
        if not isinstance(v, str):
            raise UserError(f"{p}: [dialect] {k} must be a string, not {type(v).__name__}")
    for table in ("meta", "evidence"):
        if not isinstance(data.get(table, {}), dict):
            raise UserError(f"{p}: [{table}] must be a table, not {type(data[table]).__name__}")
    return Profile(dict(dialect), dict(data.get("meta", {})), dict(data.get("evidence", {})))


def complete_profile(path: str | Path) -> Profile:
    """A profile to take a dialect from: a partial one is refused, since its unanswered
    questions would silently take the defaults."""
    prof = load_profile(path)
    missing = unanswered(prof)
    if missing:
        raise UserError(f"{path}: a partial profile ({prof.meta.get('interrupted', 'interrupted')})"
                        f" leaves {', '.join(missing)} unanswered; characterize the unit again")
    return prof


def load_profile_dialect(spec: Any, path: str | Path) -> Any:
    """The dialect a profile describes (validated against questions.toml)."""
    prof = complete_profile(path)
    try:
        return spec.dialect(prof.dialect)
    except UserError as exc:
        raise UserError(f"{path}: {exc}") from None


def unanswered(p: Profile) -> list[str]:
    """The questions a partial profile (an interrupted ``characterize``) did not answer."""
    if not p.meta.get("partial"):
        return []
    listed = p.meta.get("unanswered", [])
    return [str(q) for q in listed] if isinstance(listed, list) else []


NOT_ANSWERED = "(not answered)"


def diff_profiles(a: Profile, b: Profile, defaults: dict[str, str] | None = None
                  ) -> list[tuple[str, str | None, str | None]]:
    """(question, choice in a, choice in b) for every question on which they differ; a question
    a profile leaves out counts as its default (from ``defaults``) when one is given, except
    where a partial profile says it was never answered (:data:`NOT_ANSWERED`)."""
    base = defaults or {}
    da = base | a.dialect | dict.fromkeys(unanswered(a), NOT_ANSWERED)
    db = base | b.dialect | dict.fromkeys(unanswered(b), NOT_ANSWERED)
    keys = sorted(set(da) | set(db), key=lambda k: _qkey((k, None)))
    return [(k, da.get(k), db.get(k)) for k in keys if da.get(k) != db.get(k)]


def _whose(data: dict) -> str:
    """What the file is when it is another family's profile (it names its variant), else
    nothing."""
    from conform.families import family_for_variant

    meta = data.get("meta")
    variant = data.get("variant") or (meta.get("variant") if isinstance(meta, dict) else None)
    if not isinstance(variant, str) or not variant:
        return ""
    fam = family_for_variant(variant)
    known = any(v.id == variant for v in fam.variants())
    return f"a {fam.name} profile ({variant}), not a GVE one" if known and fam.name != "gve" else ""

