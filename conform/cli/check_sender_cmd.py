"""``conform check-sender [OPTIONS] -- COMMAND ARGS...``: grade a user's sender program.

The program runs once per scenario against the reference unit on a pty; ``{port}`` in its
arguments becomes the device path (also in ``CONFORM_PORT``), ``{job}`` the job file it
should stream (``CONFORM_JOB``), in the unit's own language. Exit status: 0 no MUST rule
failed, 1 one did, 2 usage or a harness ERROR, 130 interrupted (Ctrl-C, SIGTERM, SIGHUP: the
report then holds the scenarios that finished).
"""

from __future__ import annotations

import sys

import click

from conform.cli.params import (
    INPUT_FILE,
    OUTPUT_DIR,
    VARIANT,
    default_variant_text,
    json_option,
    quiet_option,
    seed_option,
)


@click.command(name="check-sender", context_settings={"ignore_unknown_options": True})
@click.option("--variant", type=VARIANT, default=None, help=f"The unit to emulate (default {default_variant_text()}).")
@click.option("--scenario", "scenarios", multiple=True, metavar="NAME",
              help="Run only these scenarios (repeatable; default: all). `--scenario list` "
                   "lists them.")
@click.option("--report", "report_dir", default=None, type=OUTPUT_DIR,
              help="Write index.html, summary.md, junit.xml, results.json here "
                   "(default reports/check-sender-<timestamp>/).")
@click.option("--timeout", type=float, default=None, metavar="SECONDS",
              help="Seconds before a program still running is stopped and graded as hung "
                   "(default per scenario, 30).")
@click.option("--job", "job_file", default=None, type=INPUT_FILE,
              help="A job file in the unit's own language (its family's job format) to use in every "
                   "scenario instead "
                   "of the scenario's own.")
@seed_option()
@quiet_option()
@json_option("results.json's document")
@click.argument("command", nargs=-1, type=click.UNPROCESSED)
def cli(variant: str | None, scenarios: tuple[str, ...], report_dir: str | None,
        timeout: float | None, job_file: str | None, seed: int, quiet: bool, as_json: bool,
        command: tuple[str, ...]) -> None:
    """Run COMMAND once per scenario against the emulator and grade it per rule and clause.

    \b
    Examples:
      conform check-sender --scenario list
      conform check-sender --scenario clean -- python tests/senders/careful.py {port} {job}
    """
    import json

    from conform.sendercheck.grade import check, default_family, family_for
    from conform.sendercheck.options import (
        check_timeout,
        job_of_family,
        read_job,
        report_folder,
        require_program,
    )
    from conform.sendercheck.report import write_reports
    from conform.stops import shield

    names = [n.strip() for x in scenarios for n in x.split(",") if n.strip()]
    shapes = family_for(variant) if variant else default_family()
    if "list" in names:
        for s in shapes.scenarios.values():
            click.echo(f"{s.name:16} {s.title}")
        return
    require_program(list(command))
    check_timeout(timeout)
    shapes.variant(variant or shapes.default_variant)
    job_lines = read_job(job_file)
    lines = job_lines or []
    job_of_family(job_lines, job_file,
                  shapes.moves(lines) if shapes.moves else len(shapes.units(lines)), shapes.name)
    directory = report_folder(report_dir)

    def say(msg: str) -> None:
        if not quiet:
            click.echo(f"check-sender: {msg}", err=True)

    results = check(list(command), variant=variant, names=names or None,
                    directory=directory, timeout=timeout, seed=seed, job_lines=job_lines,
                    progress=say)
    with shield():   # the report of what finished, even while a signal stops us
        write_reports(results, directory)
    if as_json:
        click.echo(json.dumps(results.to_json(), indent=1, default=str))
    else:
        counts = ", ".join(f"{g} {n}" for g, n in sorted(results.counts().items()))
        for v in results.verdicts:   # every verdict short of PASS, named
            if v.grade not in ("PASS", "NOT-APPLICABLE"):
                click.echo(f"  {v.grade} {v.scenario}/{v.rule} ({v.level}, {v.clause}): "
                           f"{v.detail}")
        click.echo(f"{len(results.scenarios)} scenario(s) in {results.duration:.1f} s: "
                   f"{counts or 'nothing graded'}")
        if results.interrupted:
            click.echo(f"INCOMPLETE: {results.interrupted}")
        click.echo(f"report: {directory / 'index.html'}")
    if results.interrupted:
        click.echo(f"check-sender: {results.interrupted}; report written", err=True)
    sys.exit(results.exit_code)   # an interruption's status (128 + N) replaces it (cli.main)
