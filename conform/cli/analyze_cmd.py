"""``conform analyze FILE.mcap``: findings, latency, throughput and queue feeding of a session."""

from __future__ import annotations

import os

import click

from conform.errors import UserError

BIG_FILE = 20 * 1024 * 1024  # show a progress display above this size


@click.command(name="analyze")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=True, path_type=str))
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=str),
              default=None, help="Write DIR/index.html, DIR/summary.md, DIR/findings.json.")
@click.option("--parquet", "parquet_dir", type=click.Path(file_okay=False, path_type=str),
              default=None, help="Write the tables as Parquet files into DIR.")
@click.option("--variant", default=None, help="Decode as this variant (default: the capture's).")
@click.option("--baud", type=float, default=None,
              help="The line's baud rate (default: the capture's, checked against the data).")
@click.option("--dialect", default=None, help="Open-question choices, e.g. A10=every-line.")
@click.option("--no-whatif", is_flag=True, help="Skip the what-if queue replays.")
@click.option("--progress/--no-progress", default=None,
              help="Progress display (default: on for large files on a terminal).")
@click.option("--time-range", default=None, metavar="START:END",
              help="Draw the plots over time for this range only, in seconds from the start "
                   "(either end may be left out), to look closely at a stutter.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Several captures: local processes to use (default: every core).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Several captures: run on this Dask distributed scheduler "
                   "(e.g. tcp://host:8786) instead of local processes.")
def cli(files: tuple[str, ...], report_dir: str | None, parquet_dir: str | None,
        variant: str | None, baud: float | None, dialect: str | None, no_whatif: bool,
        progress: bool | None, time_range: str | None, jobs: int | None,
        scheduler: str | None) -> None:
    """Analyse a capture: findings with manual clauses, latency split, throughput, queue.

    Several files or a folder: each capture analysed in parallel, one Parquet dataset and a
    fleet summary (per machine and session) in the report folder.
    """
    from conform.analysis.analyze import analyze
    from conform.analysis.report import write_parquet, write_report

    if len(files) > 1 or os.path.isdir(files[0]):
        _fleet(files, report_dir, parquet_dir, variant, baud, dialect, jobs, scheduler)
        return
    file = files[0]
    from conform.families.capture_hook import analyze_other_family

    if analyze_other_family(file, variant, report_dir, parquet_dir):  # grbl or unknown traffic
        return
    window = _time_range(time_range)

    try:
        size = os.path.getsize(file)
    except OSError:
        size = 0
    show = progress if progress is not None else (size > BIG_FILE and _tty())
    if baud is not None and baud <= 0:
        raise UserError(f"--baud {baud:g}: must be positive")
    if show:
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                      transient=True) as bar:
            task = bar.add_task("reading", total=size or 1)

            def on_bytes(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            def on_step(name: str) -> None:
                bar.update(task, description=name)

            a = analyze(file, variant=variant, baud=baud, dialect=dialect, progress=on_bytes,
                        step=on_step, whatif_replays=not no_whatif)
    else:
        a = analyze(file, variant=variant, baud=baud, dialect=dialect,
                    whatif_replays=not no_whatif)
    a.time_range = window
    m = a.metrics
    click.echo(f"{file}: {m['exchanges']} exchanges in {m['duration_s']:.3f} s "
               f"({m['exchanges_per_s']:.1f}/s), {m['vectors_accepted']} vectors, "
               f"baud {int(m['baud']['used'])}")
    damage = a.raw.status.describe()
    if damage:
        click.echo(f"capture damaged: {damage}; analysed what is intact")
    counts = m.get("finding_counts", {})
    if counts:
        click.echo("findings: " + ", ".join(f"{k} {n}" for k, n in counts.items()))
    else:
        click.echo("findings: none")
    for f in a.findings:
        if f.severity in ("hazard", "error"):
            click.echo(f"  {f.t:10.4f}s {f.severity:7} {f.kind}: {f.message}")
    if report_dir:
        paths = write_report(a, report_dir)
        click.echo(f"report: {paths['html']}")
    if parquet_dir:
        write_parquet(a, parquet_dir)
        click.echo(f"tables: {parquet_dir}")
    if damage:
        raise SystemExit(1)


def _time_range(text: str | None) -> tuple[float, float] | None:
    """``START:END`` in seconds (either may be empty) as a pair; ``UserError`` if malformed."""
    if text is None:
        return None
    lo, sep, hi = text.partition(":")
    try:
        pair = (float(lo) if lo.strip() else float("-inf"), float(hi) if hi.strip() else float("inf"))
    except ValueError:
        pair = (float("nan"), float("nan"))
    if not sep or not pair[0] < pair[1]:
        raise UserError(f"--time-range {text!r}: expected START:END in seconds, START < END")
    return pair


def _fleet(files: tuple[str, ...], report_dir: str | None, parquet_dir: str | None,
           variant: str | None, baud: float | None, dialect: str | None, jobs: int | None,
           scheduler: str | None) -> None:
    from conform.analysis.fleet import analyze_fleet, write_fleet_report

    options = {"variant": variant, "baud": baud, "dialect": dialect}
    s = analyze_fleet(files, parquet_dir=parquet_dir, options=options, jobs=jobs,
                      scheduler=scheduler)
    t = s["totals"]
    click.echo(f"{t['sessions']} captures on {t['machines']} machines: {t['exchanges']} "
               f"exchanges, {t['hazards']} hazards, {t['errors']} not analysed")
    for m in s["machines"]:
        click.echo(f"  {m['machine']}: {m['sessions']} sessions, {m['exchanges']} exchanges, "
                   f"{m['hazards']} hazards, {m['starvations']} starvations"
                   + (f", {m['damaged']} damaged" if m["damaged"] else "")
                   + (f", {m['errors']} not analysed" if m["errors"] else ""))
    for r in s["sessions"]:
        if r["error"]:
            click.echo(f"  {r['path']}: {r['error']}")
    if report_dir:
        paths = write_fleet_report(s, report_dir)
        click.echo(f"report: {paths['html']}")
    if parquet_dir:
        click.echo(f"tables: {parquet_dir}/exchanges (one dataset, partitioned by machine)")
    if any(r["state"] != "clean" for r in s["sessions"]):
        raise SystemExit(1)  # some captures damaged or not analysed: listed above


def _tty() -> bool:
    import sys

    return sys.stderr.isatty()
