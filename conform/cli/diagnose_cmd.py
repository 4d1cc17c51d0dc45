"""``conform diagnose CAPTURE…``: why a session stopped, stalled or went wrong."""

from __future__ import annotations

import click

from conform.cli.params import INPUT_PATH, VARIANT, echo_json, json_option


@click.command(name="diagnose")
@click.argument("files", nargs=-1, required=True, type=INPUT_PATH)
@click.option("--variant", type=VARIANT, default=None,
              help="Decode as this variant (default: the capture's).")
@json_option("{\"causes\": [...], ...} per capture, most likely cause first")
def cli(files: tuple[str, ...], variant: str | None, as_json: bool) -> None:
    """Say how the session ended (completed, ended, stopped and by whom, stalled, aborted by
    the unit, capture damaged), then the cause of a stop or stall with its evidence and what
    to do, the hazards seen on the way, the lines as the unit read them, and where to resume
    a job that did not finish.

    \b
    Causes: sender-stopped, unit-silent, unit-busy, link-lost, buffer-overflow, lost-line,
    deadlock, starvation, noise, protocol-misuse, unit-alarm, overflow-risk.

    \b
    Examples:
      conform diagnose captures/careless-noisy.mcap
      conform diagnose session.mcap --json | jq '.causes[0]'
    """
    from conform.diagnosis import diagnose
    from conform.diagnosis.render import text_lines
    from conform.errors import UserError
    from conform.families.capture_hook import not_this_family

    docs = []
    for file in files:
        wrong = not_this_family(file, variant) if variant else None
        if wrong:       # refused as `conform analyze` refuses it
            raise UserError(f"{file}: {wrong}")
        d = diagnose(file, variant=variant)
        if as_json:
            docs.append(d.to_json())
            continue
        for line in text_lines(d):
            click.echo(line)
        if len(files) > 1:
            click.echo("")
    if as_json:
        echo_json(docs[0] if len(docs) == 1 else {"captures": docs})
