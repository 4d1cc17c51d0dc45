"""``conform analyze FILE.mcap``: findings, latency, throughput and queue feeding of a session."""

from __future__ import annotations

import os

import click

from conform.cli.params import (
    FRACTIONAL_BAUD,
    INPUT_PATH,
    OUTPUT_DIR,
    VARIANT,
    echo_json,
    json_option,
)
from conform.cli.progress import progress as show_progress
from conform.errors import UserError


@click.command(name="analyze")
@click.argument("files", nargs=-1, required=True, type=INPUT_PATH)
@click.option("--report", "report_dir", type=OUTPUT_DIR,
              default=None, help="Write DIR/index.html, DIR/summary.md, DIR/findings.json.")
@click.option("--parquet", "parquet_dir", type=OUTPUT_DIR, default=None,
              help="Write the tables (exchanges, frames_host, frames_unit, series, "
                   "queue_depth) as Parquet files into DIR, for pandas, polars or DuckDB.")
@click.option("--variant", type=VARIANT, default=None,
              help="Decode as this variant (default: the capture's).")
@click.option("--baud", type=FRACTIONAL_BAUD, default=None,
              help="The line's baud rate (default: the capture's, checked against the data).")
@click.option("--dialect", default=None, help="Open-question choices, e.g. A10=every-line.")
@click.option("--no-whatif", is_flag=True, help="Skip the what-if queue replays.")
@click.option("--progress/--no-progress", default=None,
              help="Progress display (default: bars on a terminal, a line every few seconds "
                   "off one).")
@click.option("--time-range", default=None, metavar="START:END",
              help="Draw the plots over time for this range only, in seconds from the start "
                   "(either end may be left out), to look closely at a stutter.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Several captures: local processes to use (default: every core).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Several captures: run on this Dask distributed scheduler "
                   "(e.g. tcp://host:8786) instead of local processes.")
@json_option("findings.json's document (several captures: the fleet summary), plus the paths "
             "written")
def cli(files: tuple[str, ...], report_dir: str | None, parquet_dir: str | None,
        variant: str | None, baud: float | None, dialect: str | None, no_whatif: bool,
        progress: bool | None, time_range: str | None, jobs: int | None,
        scheduler: str | None, as_json: bool) -> None:
    """Analyse a capture: findings with manual clauses, latency split, throughput, queue.

    Several files or a folder: each capture analysed in parallel, one Parquet dataset and a
    fleet summary (per machine and session) in the report folder.

    \b
    Examples:
      conform analyze captures/careless-noisy.mcap
      conform analyze captures/usb-latency.mcap --report out/ --parquet out/tables/
      conform analyze captures/good-rs232.mcap --json | jq .metrics.exchanges
      conform analyze captures/ --report fleet/     # every capture in the folder
      conform analyze support.zip                   # the captures of a conform bundle
    """
    from conform.analysis import analyze
    from conform.analysis.report import findings_document, write_report
    from conform.diagnosis import headline_for
    from conform.families import DEFAULT_FAMILY

    def echo(text: str) -> None:
        click.echo(text, err=as_json)

    from conform.diagnosis.bundle import expand_bundles

    files = expand_bundles(files, echo)  # a support bundle (conform bundle): its captures
    if len(files) > 1 or os.path.isdir(files[0]):
        with show_progress("conform analyze", quiet=progress is False, transient=True) as bar:
            bar.task(f"analysing {len(files)} inputs" if len(files) > 1 else
                     f"analysing the captures in {files[0]}")
            _fleet(files, report_dir, parquet_dir, variant, baud, dialect, jobs, scheduler,
                   echo, as_json)
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
    with show_progress("conform analyze", quiet=progress is False, transient=True) as bar:
        task = bar.task(os.path.basename(file), size or None, unit="bytes")

        def on_bytes(done: int, total: int) -> None:
            task.update(completed=done, total=total)

        a = analyze(file, variant=variant, baud=baud, dialect=dialect, progress=on_bytes,
                    step=lambda name: task.update(step=name), whatif_replays=not no_whatif,
                    parquet=parquet_dir)  # the tables are written as the capture streams
        a.time_range = window
        said: list[str] = []       # the diagnosis, for the first screen and the report's top
        task.update(step="diagnosis")
        headline_for(file, a, DEFAULT_FAMILY, said.append)
        paths = {}
        if report_dir:
            task.update(step="writing the report (plots)")
            paths["report"] = str(write_report(a, report_dir)["html"])
        if parquet_dir:
            paths["parquet"] = parquet_dir
    m = a.metrics
    for line in said:
        echo(line)
    echo(f"{file}: {m['exchanges']} exchanges in {m['duration_s']:.3f} s "
         f"({m['exchanges_per_s']:.1f}/s), {m['vectors_accepted']} vectors, "
         f"baud {int(m['baud']['used'])}")
    damage = a.raw.status.describe()
    if damage:
        echo(f"capture damaged: {damage}; analysed what is intact")
    for note in a.notes:
        echo(f"note: {note}")
    counts = m.get("finding_counts", {})
    echo("findings: " + (", ".join(f"{k} {n}" for k, n in counts.items()) if counts else "none"))
    for f in a.findings:
        if f.severity in ("hazard", "error"):
            echo(f"  {f.t:10.4f}s {f.severity:7} {f.kind}: {f.message}")
    if "report" in paths:
        echo(f"report: {paths['report']}")
    if parquet_dir:
        echo(f"tables: {parquet_dir}")
    if as_json:
        echo_json(findings_document(a) | paths | {"diagnosis": getattr(a, "diagnosis", None)})
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
           scheduler: str | None, echo, as_json: bool) -> None:  # noqa: ANN001
    from conform.analysis.fleet import analyze_fleet, write_fleet_report

    options = {"variant": variant, "baud": baud, "dialect": dialect}
    s = analyze_fleet(files, parquet_dir=parquet_dir, options=options, jobs=jobs,
                      scheduler=scheduler)
    t = s["totals"]
    echo(f"{t['sessions']} captures on {t['machines']} machines: {t['exchanges']} "
         f"exchanges, {t['hazards']} hazards, {t['errors']} not analysed")
    for m in s["machines"]:
        echo(f"  {m['machine']}: {m['sessions']} sessions, {m['exchanges']} exchanges, "
             f"{m['hazards']} hazards, {m['starvations']} starvations"
             + (f", {m['damaged']} damaged" if m["damaged"] else "")
             + (f", {m['errors']} not analysed" if m["errors"] else ""))
    for r in s["sessions"]:
        if r["error"]:
            echo(f"  {r['path']}: {r['error']}")
    paths = {}
    if report_dir:
        paths["report"] = str(write_fleet_report(s, report_dir)["html"])
        echo(f"report: {paths['report']}")
    if parquet_dir:
        paths["parquet"] = parquet_dir
        echo(f"tables: {parquet_dir}/exchanges (one dataset, partitioned by machine)")
    if as_json:
        echo_json(s | paths)
    if any(r["state"] != "clean" for r in s["sessions"]):
        raise SystemExit(1)  # some captures damaged or not analysed: listed above
