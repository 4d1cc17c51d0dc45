"""``conform profile diff A B``: compare two characterisation profiles."""

from __future__ import annotations

import sys

import click

from conform.cli.params import INPUT_FILE
from conform.families.gve.conformance.profile import diff_profiles, load_profile, unanswered
from conform.families.gve.spec import load_spec


@click.group(name="profile")
def cli() -> None:
    """Characterisation profiles (from ``conform characterize``).

    \b
    Example:
      conform profile diff unit.toml unit-v10.toml
    """


@cli.command()
@click.argument("a", type=INPUT_FILE)
@click.argument("b", type=INPUT_FILE)
def diff(a: str, b: str) -> None:
    """Open questions on which two profiles differ; exit 1 when they do. A partial profile
    (an interrupted characterize) names the questions it did not answer; they differ.

    \b
    Example:
      conform profile diff unit-a.toml unit-b.toml
    """
    pa, pb = load_profile(a), load_profile(b)
    for path, p in ((a, pa), (b, pb)):
        missing = unanswered(p)
        if missing:
            click.echo(f"{path}: partial profile ({p.meta.get('interrupted', 'interrupted')}); "
                       f"{len(missing)} question(s) not answered: {', '.join(missing)}")
    rows = diff_profiles(pa, pb, dict(load_spec().dialect().choices))
    if not rows:
        click.echo("same dialect")
        return
    width = max(len(str(x)) for _, x, _ in rows)
    click.echo(f"{'':4} {a:<{width}}  {b}")
    for q, x, y in rows:
        click.echo(f"{q:<4} {x or '(absent)':<{width}}  {y or '(absent)'}")
    sys.exit(1)
