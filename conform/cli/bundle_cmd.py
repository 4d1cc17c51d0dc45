"""``conform bundle CAPTURE… -o FILE.zip``: one file to send to someone."""

from __future__ import annotations

import click

from conform.cli.params import INPUT_PATH, OUTPUT_FILE


@click.command(name="bundle")
@click.argument("files", nargs=-1, required=True, type=INPUT_PATH)
@click.option("-o", "--output", required=True, type=OUTPUT_FILE, help="The zip to write.")
@click.option("--redact", is_flag=True,
              help="Replace the host name, user name and folders (not the traffic) and "
                   "leave out USB serial numbers.")
@click.option("--force", is_flag=True, help="Overwrite OUTPUT if it exists.")
def cli(files: tuple[str, ...], output: str, redact: bool, force: bool) -> None:
    """Pack captures with their diagnosis, analysis report, findings and tables, the conform
    version, the OS and Python and the serial ports' descriptions into one zip.

    \b
    Examples:
      conform bundle session.mcap -o support.zip --redact
      conform analyze support.zip          # open it again
    """
    from pathlib import Path

    from conform.diagnosis.bundle import write_bundle
    from conform.errors import writable_folder

    writable_folder(Path(output).parent, f"-o {output}: its folder")   # before the work

    out = write_bundle(list(files), output, redact=redact, force=force,
                       echo=lambda s: click.echo(s, err=True))
    click.echo(f"bundle: {out}")
