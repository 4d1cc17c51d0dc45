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
    quiet_option,
)
from conform.cli.progress import progress as show_progress
from conform.errors import UserError, writable_folder

FAIL_ON = ("never", "warning", "error", "hazard")   # the findings' severities, mildest first


@click.command(name="analyze")
@click.argument("files", nargs=-1, required=True, type=INPUT_PATH)
@click.option("--report", "report_dir", type=OUTPUT_DIR,
              default=None, help="Write DIR/index.html, DIR/summary.md, DIR/findings.json.")
@click.option("--parquet", "parquet_dir", type=OUTPUT_DIR, default=None,
              help="Write the analysis's tables (exchanges, frames_host, frames_unit, series "
                   "and the protocol family's own) as Parquet files into DIR, for pandas, "
                   "polars or DuckDB.")
@click.option("--variant", type=VARIANT, default=None,
              help="Decode as this variant (default: the capture's).")
@click.option("--baud", type=FRACTIONAL_BAUD, default=None,
              help="The line's baud rate (default: the capture's, checked against the data).")
@click.option("--dialect", default=None, help="Open-question choices, e.g. A10=every-line.")
@click.option("--no-whatif", is_flag=True, help="Skip the what-if queue replays.")
@click.option("--progress/--no-progress", default=None,
              help="Progress display (default: bars on a terminal, a line every few seconds "
                   "off one); --no-progress is -q.")
@quiet_option()
@click.option("--time-range", default=None, metavar="START:END",
              help="Draw the plots over time for this range only, in seconds from the start "
                   "(either end may be left out), to look closely at a stutter.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Several captures: local processes to use (default: every core).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Several captures: run on this Dask distributed scheduler "
                   "(e.g. tcp://host:8786) instead of local processes.")
@click.option("--fail-on", type=click.Choice(FAIL_ON), default="never", show_default=True,
              help="Exit 1 when a finding of this severity or a worse one is found (warning < "
                   "error < hazard); by default findings do not change the exit status, only a "
                   "damaged capture does.")
@json_option("findings.json's document (several captures: the fleet summary), plus the paths "
             "written")
def cli(files: tuple[str, ...], report_dir: str | None, parquet_dir: str | None,
        variant: str | None, baud: float | None, dialect: str | None, no_whatif: bool,
        progress: bool | None, quiet: bool, time_range: str | None, jobs: int | None,
        scheduler: str | None, fail_on: str, as_json: bool) -> None:
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
    from conform.families import default_family

    def echo(text: str) -> None:
        click.echo(text, err=as_json)

    from conform.diagnosis.bundle import expand_bundles

    quiet = quiet or progress is False

    files = expand_bundles(files, echo)  # a support bundle (conform bundle): its captures
    if report_dir:   # before the analysis: a folder that cannot be written is one line now
        writable_folder(report_dir, "--report")
    if parquet_dir:
        writable_folder(parquet_dir, "--parquet")
    if len(files) > 1 or os.path.isdir(files[0]):
        with show_progress("conform analyze", quiet=quiet, transient=True) as bar:
            bar.task(f"analysing {len(files)} inputs" if len(files) > 1 else
                     f"analysing the captures in {files[0]}")
            if fail_on not in ("never", "hazard"):
                raise UserError(f"--fail-on {fail_on}: several captures are judged by their "
                                "hazards only (--fail-on hazard)")
            _fleet(files, report_dir, parquet_dir, variant, baud, dialect, jobs, scheduler,
                   echo, as_json, fail_on)
        return
    file = files[0]
    spread = [o for o, v in (("--scheduler", scheduler), ("--jobs", jobs)) if v is not None]
    if spread:   # said, not silently dropped: they spread several captures over workers
        click.echo(f"note: {' and '.join(spread)} {'spread' if len(spread) > 1 else 'spreads'} "
                   "several captures over workers; one capture is analysed here, in this "
                   "process", err=True)
    from conform.families.capture_hook import analyze_other_family, not_this_family

    wrong = not_this_family(file, variant) if variant else None
    if wrong:
        raise UserError(f"{file}: {wrong}")

    window = _time_range(time_range)
    if window and not report_dir:
        raise UserError(f"--time-range {time_range}: draws the report's plots over that range; "
                        "give --report DIR too")
    other = analyze_other_family(file, variant, report_dir, parquet_dir, as_json)
    if other:  # another family's traffic, or unknown traffic
        unused = [f"--time-range {time_range}"] * bool(window) + [f"--dialect {dialect}"] * bool(
            dialect)   # the default family's options; another family's analysis takes neither
        if unused:
            click.echo(f"{' and '.join(unused)}: not used: they apply to "
                       f"{default_family().name} captures; this one is another family's",
                       err=True)
        _fail(getattr(other, "findings", []), fail_on)
        return

    try:
        size = os.path.getsize(file)
    except OSError:
        size = 0
    with show_progress("conform analyze", quiet=quiet, transient=True) as bar:
        task = bar.task(os.path.basename(file), size or None, unit="bytes")

        def on_bytes(done: int, total: int) -> None:
            task.update(completed=done, total=total)

        a = analyze(file, variant=variant, baud=baud, dialect=dialect, progress=on_bytes,
                    step=lambda name: task.update(step=name), whatif_replays=not no_whatif,
                    parquet=parquet_dir)  # the tables are written as the capture streams
        a.time_range = window
        duration = a.metrics.get("duration_s") or 0.0
        if window and not (window[0] <= duration and window[1] >= 0):
            raise UserError(f"--time-range {time_range}: outside the capture (0 to "
                            f"{duration:.3f} s); nothing would be drawn")
        said: list[str] = []       # the diagnosis, for the first screen and the report's top
        task.update(step="diagnosis")
        headline_for(file, a, default_family().name, said.append)
        paths = {}
        if report_dir:
            task.update(step="writing the report (plots)")
            paths["report"] = str(write_report(a, report_dir)["html"])
        if parquet_dir:
            paths["parquet"] = parquet_dir
    for line in said:
        echo(line)
    for line in a.summary_lines():
        echo(line)
    damage = a.raw.status.describe()
    if "report" in paths:
        echo(f"report: {paths['report']}")
    if parquet_dir:
        echo(f"tables: {parquet_dir}")
    if as_json:
        echo_json(findings_document(a) | paths | {"diagnosis": getattr(a, "diagnosis", None)})
    if damage:
        raise SystemExit(1)
    _fail(a.findings, fail_on)


def _fail(findings: list, fail_on: str) -> None:
    """Exit 1 when a finding is at least as severe as ``--fail-on`` (said on stderr)."""
    if fail_on == "never":
        return
    rank = FAIL_ON.index(fail_on)
    worse = [f for f in findings if f.severity in FAIL_ON and FAIL_ON.index(f.severity) >= rank]
    if worse:
        click.echo(f"conform analyze: {len(worse)} finding(s) of severity {fail_on} or worse "
                   "(--fail-on)", err=True)
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
           scheduler: str | None, echo, as_json: bool,  # noqa: ANN001
           fail_on: str = "never") -> None:
    from conform.analysis.fleet import (
        analyze_fleet,
        count,
        fleet_datasets,
        totals_text,
        write_fleet_report,
    )

    options = {"variant": variant, "baud": baud, "dialect": dialect}
    s = analyze_fleet(files, parquet_dir=parquet_dir, options=options, jobs=jobs,
                      scheduler=scheduler, report_dir=report_dir)
    t = s["totals"]
    echo(f"{count(t['sessions'], 'capture')} on {count(t['machines'], 'machine')}: "
         f"{count(t['exchanges'], 'exchange')}{totals_text(t, s['columns'])}, "
         f"{t['errors']} not analysed")
    for m in s["machines"]:
        echo(f"  {m['machine']}: {count(m['sessions'], 'session')}, "
             f"{count(m['exchanges'], 'exchange')}" + totals_text(m, s["columns"])
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
        echo(f"tables: {', '.join(fleet_datasets(parquet_dir))} (a dataset each, partitioned "
             "by machine)")
    if as_json:
        echo_json(s | paths)
    if any(r["state"] != "clean" for r in s["sessions"]):
        raise SystemExit(1)  # some captures damaged or not analysed: listed above
    if fail_on == "hazard" and t.get("hazards"):
        click.echo(f"conform analyze: {t['hazards']} hazard(s) (--fail-on)", err=True)
        raise SystemExit(1)
