"""``conform samples DIR``: the files the README's tour uses, from the installed package."""

from __future__ import annotations

import click

from conform.cli.outputs import force_option


@click.command(name="samples")
@click.argument("directory", metavar="DIR", type=click.Path(file_okay=False, path_type=str))
@force_option("sample files already in DIR")
def cli(directory: str, force: bool) -> None:
    """Write the sample captures (every protocol family's), the jobs, the reference sender
    scripts, the recorded transcripts and the documents into DIR, laid out as in a clone of the
    repository (captures/, captures/jobs/, tests/senders/, tests/data/, docs/): the
    README's tour then runs in DIR from an installed wheel, and its links work there.

    \b
    Examples:
      conform samples conform-samples && cd conform-samples
      conform analyze captures/careless-noisy.mcap
    """
    from collections import Counter

    from conform.samples import write_samples

    written = write_samples(directory, force=force)
    folders = Counter(str(p.parent.relative_to(directory)) for p in written)
    for folder, n in folders.items():
        click.echo(f"{directory.rstrip('/')}/{folder}/: {n} file(s)")
    click.echo(f"{len(written)} sample files in {directory} (the README's tour runs there)")
