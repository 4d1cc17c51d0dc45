"""``conform report results.json``: re-render the reports of a conformance run."""

from __future__ import annotations

from pathlib import Path

import click

from conform.conformance.results import RunResults
from conform.report.render import write_reports


@click.command(name="report")
@click.argument("results", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(file_okay=False), default=None,
              help="Folder to write into (default: the folder of RESULTS).")
def cli(results: str, output: str | None) -> None:
    """Write index.html, summary.md and junit.xml (and results.json) from RESULTS."""
    data = RunResults.load(results)
    out = Path(output) if output else Path(results).resolve().parent
    write_reports(data, out)
    click.echo(f"report: {out / 'index.html'}")
