"""``conform profile diff A B``: two characterisation profiles (``conform characterize``) of one
family compared item by item. Profiles of observations (``[observed]``: grbl, Marlin) are
compared here; any other shape goes to the family the profile names (``Family.diff_profiles``),
or to the default family when it names none."""

from __future__ import annotations

import sys
import tomllib
from typing import Any

import click

from conform.cli.params import INPUT_FILE
from conform.errors import UserError


@click.group(name="profile")
def cli() -> None:
    """Characterisation profiles (from ``conform characterize``).

    \b
    Examples:
      conform profile diff unit.toml unit-v10.toml
      conform profile diff printer-a.toml printer-b.toml
    """


MAX_PROFILE_BYTES = 4 << 20
"""A profile is a few kilobytes; a larger file is refused before it is read."""


def _read(path: str) -> dict[str, object]:
    """The profile's TOML; a file too large, unreadable or not TOML is one line (exit 2)."""
    from conform.errors import load_user_file

    doc = load_user_file(path, tomllib.loads, max_bytes=MAX_PROFILE_BYTES, what="profile")
    return doc if isinstance(doc, dict) else {}


def _variant(doc: dict[str, object]) -> str:
    meta = doc.get("meta")
    named = doc.get("variant") or (meta.get("variant") if isinstance(meta, dict) else None)
    return named if isinstance(named, str) else ""


@cli.command()
@click.argument("a", type=INPUT_FILE)
@click.argument("b", type=INPUT_FILE)
def diff(a: str, b: str) -> None:
    """The items on which two profiles differ; exit 1 when they do. A partial profile (an
    interrupted characterize) names what it did not reach; those items differ.

    \b
    Example:
      conform profile diff unit-a.toml unit-b.toml
    """
    from conform.conformance.observed import diff_observed
    from conform.families import default_family, families

    docs = {a: _read(a), b: _read(b)}
    owners = {}
    for path, doc in docs.items():
        vid = _variant(doc)
        owners[path] = next((f for f in families() if vid in {v.id for v in f.variants()}),
                            None) if vid else None
    fa, fb = owners[a], owners[b]
    if fa is not None and fb is not None and fa is not fb:
        raise UserError(f"{b}: a {fb.name} profile; {a} is a {fa.name} profile: "
                        "profiles of one family only")
    if all(isinstance(d.get("observed"), dict) for d in docs.values()):
        notes, rows, same = diff_observed(a, docs[a], b, docs[b])
    else:
        notes, rows, same = (fa or fb or default_family()).diff_profiles(a, b)
    for note in notes:
        click.echo(note)
    if not rows:
        click.echo(same)
        return
    key = max(4, *(len(str(k)) for k, _, _ in rows))
    width = max(len(a), *(len(_shown(x)) for _, x, _ in rows))
    click.echo(f"{'':{key}} {a:<{width}}  {b}")
    for k, x, y in rows:
        click.echo(f"{k:<{key}} {_shown(x):<{width}}  {_shown(y)}")
    sys.exit(1)


def _shown(x: Any) -> str:
    return ("true" if x else "false") if isinstance(x, bool) else str(x)
