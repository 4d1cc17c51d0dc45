"""Analyse many captures at once: a fleet of machines, a week of shifts.

    conform analyze captures/ --report fleet/ --parquet tables/          # all local cores
    conform analyze m1/*.mcap m2/*.mcap --scheduler tcp://sched:8786     # Dask distributed

Every capture is analysed on its own (one task per file) by a pool of local processes or by
the workers of an existing Dask distributed scheduler; each task writes its tables into one
Parquet dataset per table (``DIR/<table>/machine=M/S.parquet`` for every table a single
analysis writes: exchanges, frames_host, frames_unit, series, queue_depth; hive partitioned,
so pandas, polars or DuckDB read the whole fleet as one table) and returns a small summary row. The
rows become the fleet summary (per machine and session: duration, exchanges, throughput,
latency percentiles, findings, and the columns each family declares, ``Family.fleet_columns``)
as HTML, Markdown and JSON. With a report folder each session's own report is written under
it too (``sessions/<machine>/<session>/index.html``), linked from the session's row.

A file that cannot be analysed is a row with its error, not the end of the run. Workers of a
distributed scheduler must see the files and the output folder at the same paths.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from conform.errors import UserError
from conform.families import Family, FleetColumn, default_family, families, family
from conform.jsondoc import JsonObject

if TYPE_CHECKING:
    from conform.families import AnalysisResult

SUMMARY_KEYS = ("machine", "session", "family", "path", "state", "error", "started",
                "duration_s", "exchanges", "exchanges_per_s", "findings", "severities",
                "rtt_p50_ms", "rtt_p95_ms", "rtt_p99_ms", "rtt_max_ms", "report"
                )  # every family's; then the families' own (``fleet_columns``)
SEVERITIES = ("hazard", "error", "warning", "info")


def fleet_columns() -> list[FleetColumn]:
    """The columns the registered families add to a fleet summary, each key once (the
    first family's declaration of it)."""
    out: dict[str, FleetColumn] = {}
    for fam in families():
        for col in getattr(fam, "fleet_columns", ()):
            out.setdefault(col.key, col)
    return list(out.values())


def expand_inputs(items: Iterable[str]) -> list[Path]:
    """Files as given; directories walked for ``*.mcap`` (sorted). ``UserError`` if none."""
    out: list[Path] = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            out.extend(sorted(q for q in p.rglob("*.mcap") if q.is_file()))
        elif p.exists():
            out.append(p)
        else:
            raise UserError(f"{p}: no such file or folder")
    if not out:
        raise UserError(f"no .mcap captures in {', '.join(map(str, items))}")
    return out


def name_machines(items: Iterable[str]) -> tuple[list[Path], list[str | None]]:
    """The captures of ``items`` (``expand_inputs``) and the machine each is named after
    where its folder does not say it (None: the session's ``machine`` key, else its folder,
    decided when it is analysed). A capture in a subfolder of a folder given is that
    subfolder's machine (``week/mill-1/mon.mcap``: ``mill-1``). Captures side by side in one
    folder (a folder given, or files named one by one) are the folder's machine when they
    come from one unit; from several, each is named after its unit (``unit_identity``: the
    variant or family and the port it was recorded on, an emulator's by its variant)."""
    files = expand_inputs(items)
    walked = {q for item in items if Path(item).is_dir()
              for q in Path(item).rglob("*.mcap") if q.parent != Path(item)}
    flat: dict[Path, list[tuple[int, str | None, str | None]]] = {}
    for i, q in enumerate(files):
        if q not in walked:
            meta, unit = unit_identity(q)
            flat.setdefault(q.resolve().parent, []).append((i, meta.get("machine"), unit))
    names: list[str | None] = [None] * len(files)
    for folder, caps in flat.items():
        units = {u for _i, _m, u in caps if u}
        for i, named, unit in caps:
            names[i] = named or (unit if len(units) > 1 and unit else folder.name or "-")
    return files, names


def unit_identity(path: Path) -> tuple[dict[str, str], str | None]:
    """A capture's session metadata and the unit it was recorded from, as its metadata and
    first bytes say it (``grbl-1.1f on host:/dev/ttyUSB0``, ``gve64-v19 emulator``); None
    when the file says nothing of it."""
    from conform.families.peek import peek_capture, peek_family

    try:
        meta = {str(k): str(v) for k, v in peek_capture(str(path))[2].items()}
    except Exception:  # noqa: BLE001 - not ours to report: its analysis says what is wrong
        return {}, None
    if not meta:
        return meta, None
    detected = peek_family(str(path), None)[0] if not meta.get("variant") else None
    what = meta.get("variant") or (detected.family if detected else default_family().name)
    port, host = meta.get("unit_port"), meta.get("hostname")
    if port:
        return meta, f"{what} on {host}:{port}" if host else f"{what} on {port}"
    if "emulator" in meta.get("capture_method", ""):
        return meta, f"{what} emulator"
    return meta, what


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._")[:80] or "unnamed"


def machine_of(path: Path, metadata: dict[str, dict[str, str]]) -> str:
    """The machine a capture belongs to: the session's ``machine`` key, else its folder."""
    session = metadata.get("conform.session", {})
    return str(session.get("machine") or path.parent.name or session.get("hostname") or "-")


def analyze_one(path: str, parquet_dir: str | None, options: JsonObject,
                report_dir: str | None = None, machine: str | None = None) -> JsonObject:
    """One fleet task: analyse ``path``, write its Parquet parts (and, with ``report_dir``,
    its own report under ``report_dir/sessions/``), return its summary row. ``machine``:
    its machine's name (``name_machines``; None: ``machine_of``)."""
    from conform.analysis import analyze

    p = Path(path)
    row: JsonObject = dict.fromkeys(SUMMARY_KEYS) | dict.fromkeys(
        c.key for c in fleet_columns())
    row.update(machine=machine or p.parent.name or "-", session=p.stem, path=str(p),
               state="error", started=_mtime(p))
    part_machine = row["machine"]
    other = _other_family(p, parquet_dir, options, row, report_dir, machine)
    if other is not None:
        return other
    row["family"] = default_family().name
    sink = None
    if parquet_dir:  # this capture's tables: one file of each of the fleet's datasets
        from conform.analysis.tables import ParquetStream

        sink = ParquetStream(Path(parquet_dir), part=Path(f"machine={_safe(row['machine'])}",
                                                          f"{_safe(p.stem)}.parquet"),
                             const={"session": p.stem, "t0": None})
    a = _attempt(row, lambda: analyze(p, whatif_replays=False, parquet=sink, **options))
    if a is None:
        return row
    _fill(row, a, machine or machine_of(p, a.raw.metadata),
          a.raw.metadata.get("conform.session", {}))
    if sink is not None and row["machine"] != part_machine:  # named by the metadata
        for name, written in a.tables.items():
            d = sink.dir / name / f"machine={_safe(row['machine'])}"
            d.mkdir(parents=True, exist_ok=True)
            written.replace(d / written.name)
    _session_report(row, a, report_dir, default_family().name)
    return row


def _fill(row: JsonObject, a: AnalysisResult, machine: str, meta: JsonObject) -> None:
    """A row from an analysis: its ``fleet_row()``, the machine, what its family's latency
    measures (``Family.latency_measure``), the findings per severity and the session's start
    (its metadata's ``started``, else the file's time; None for a session on an emulator's
    virtual clock, whose ``started`` is no wall-clock time: ``clock`` says so)."""
    from conform.capture.recorder import CALLERS_CLOCK

    row.update(a.fleet_row())
    row["machine"] = machine
    try:
        row["latency"] = family(str(row["family"])).latency_measure
    except Exception:  # noqa: BLE001 - a family the registry does not know: the engine's words
        row["latency"] = Family.latency_measure
    sev = dict.fromkeys(SEVERITIES, 0)
    for f in getattr(a, "findings", []):
        sev[f.severity] = sev.get(f.severity, 0) + 1
    row["severities"] = sev
    if meta.get("clock_source") == CALLERS_CLOCK:
        row["started"], row["clock"] = None, "virtual"
        return
    started = _iso_seconds(meta.get("started"))
    if started is not None:
        row["started"] = started


def _mtime(p: Path) -> float | None:
    try:
        return p.stat().st_mtime
    except OSError:
        return None


def _iso_seconds(text: object) -> float | None:
    """An ISO time (``2026-11-25T10:00:00+00:00``) as Unix seconds; None if it is not one."""
    from datetime import datetime

    try:
        return datetime.fromisoformat(str(text)).timestamp() if text else None
    except ValueError:
        return None


def session_folder(row: JsonObject) -> Path:
    """Where a session's own report goes in a fleet's report folder (relative)."""
    return Path("sessions", _safe(str(row["machine"])), _safe(str(row["session"])))


def _session_report(row: JsonObject, a: AnalysisResult, report_dir: str | None, family: str) -> None:
    """The session's own report (with its diagnosis at the top, as ``conform analyze FILE``
    writes it) under the fleet's report folder; the row's ``report``: its relative path. One
    that cannot be written is said in the row's error, the analysis stands."""
    if not report_dir:
        return
    from conform.diagnosis import headline_for

    rel = session_folder(row)
    try:
        headline_for(row["path"], a, family, lambda _text: None)
        a.write_report(str(Path(report_dir) / rel))
    except Exception as exc:  # noqa: BLE001 - said in the row: the other sessions go on
        row["error"] = f"its report could not be written: {type(exc).__name__}: {exc}"
        return
    row["report"] = (rel / "index.html").as_posix()


def _other_family(p: Path, parquet_dir: str | None, options: JsonObject,
                  row: JsonObject, report_dir: str | None = None,
                  machine: str | None = None) -> JsonObject | None:
    """A capture of another family's traffic (conform.families.capture_hook decides, as for
    one file), analysed by that family: its ``fleet_row()`` fills the row and its tables go
    to ``DIR/<family>/<table>/machine=M/<session>.parquet``. None: the default family's."""
    import shutil

    from conform.families.peek import peek_family

    d, meta = peek_family(str(p), options.get("variant"))
    if d is None:
        return None
    row["family"] = d.family
    if d.family == "unknown":
        row["error"] = f"protocol unknown ({d.why})"
        return row
    machine = machine or machine_of(p, {"conform.session": meta})
    base = Path(parquet_dir or ".") / d.family
    tmp = base / f".{_safe(machine)}-{_safe(p.stem)}"
    a = _attempt(row, lambda: family(d.family).analyze(  # a family may stream its tables there
        str(p), variant=options.get("variant"), detected=d.why,
        parquet=str(tmp) if parquet_dir else None))
    if a is None:
        if parquet_dir:
            shutil.rmtree(tmp, ignore_errors=True)
        return row
    _fill(row, a, machine, meta)
    if parquet_dir:
        for table in a.write_tables(str(tmp)).values():
            dest = base / table.stem / f"machine={_safe(row['machine'])}" / f"{_safe(p.stem)}.parquet"
            dest.parent.mkdir(parents=True, exist_ok=True)
            table.replace(dest)
        shutil.rmtree(tmp, ignore_errors=True)
    _session_report(row, a, report_dir, d.family)
    return row


_A = TypeVar("_A")


def _attempt(row: JsonObject, run: Callable[[], _A]) -> _A | None:
    """``run()``'s analysis, or None with the row's error set: one bad file must not end a
    fleet run."""
    try:
        return run()
    except UserError as exc:
        row["error"] = str(exc)
    except Exception as exc:  # noqa: BLE001 - reported in the row
        row["error"] = f"{type(exc).__name__}: {exc}"
    return None


def run_local(paths: list[str], parquet_dir: str | None, options: JsonObject,
              jobs: int | None = None, report_dir: str | None = None,
              machines: list[str | None] | None = None) -> list[JsonObject]:
    """Every file on a pool of local processes (all cores by default); ``machines``: each
    file's machine where it is named before (``name_machines``)."""
    jobs = jobs or os.cpu_count() or 1
    n = len(paths)
    machines = machines or [None] * n
    if jobs == 1 or n == 1:
        return [analyze_one(p, parquet_dir, options, report_dir, m)
                for p, m in zip(paths, machines, strict=True)]
    with ProcessPoolExecutor(max_workers=min(jobs, n)) as pool:
        return list(pool.map(analyze_one, paths, [parquet_dir] * n, [options] * n,
                             [report_dir] * n, machines))


def run_dask(paths: list[str], parquet_dir: str | None, options: JsonObject,
             scheduler: object, report_dir: str | None = None,
             machines: list[str | None] | None = None) -> list[JsonObject]:
    """Every file as a task on Dask distributed (``scheduler``: an address or a cluster)."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise UserError("--scheduler needs Dask distributed: pip install 'dask[distributed]'") \
            from None
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise UserError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    try:
        n = len(paths)
        futures = client.map(analyze_one, paths, [parquet_dir] * n, [options] * n,
                             [report_dir] * n, machines or [None] * n, pure=False)
        return client.gather(futures)
    finally:
        client.close()


def analyze_fleet(inputs: Iterable[str], *, parquet_dir: str | None = None,
                  options: JsonObject | None = None, jobs: int | None = None,
                  scheduler: object = None, report_dir: str | None = None) -> JsonObject:
    """Analyse every capture in ``inputs``; the fleet summary (see ``summarise``). With
    ``report_dir`` each session's own report is written under it (``sessions/``) and its
    row links it (``report``); ``write_fleet_report`` adds the fleet's."""
    files, machines = name_machines(list(inputs))
    paths = [str(p.resolve()) for p in files]
    for d in (parquet_dir, report_dir):
        if d:
            Path(d).mkdir(parents=True, exist_ok=True)
    opts = dict(options or {})
    if scheduler is not None:
        rows = run_dask(paths, parquet_dir, opts, scheduler, report_dir, machines)
    else:
        rows = run_local(paths, parquet_dir, opts, jobs, report_dir, machines)
    return summarise(rows)


def summarise(rows: list[JsonObject]) -> JsonObject:
    """Sessions sorted by machine and session, one aggregate row per machine and the
    fleet's totals (findings per severity summed in ``severities``); ``columns``: the
    families' columns (``fleet_columns``) as plain dicts; ``verdict``: the fleet in a word
    and a sentence (``verdict``)."""
    cols = fleet_columns()
    totals = [c.key for c in cols if c.total]
    rows = sorted(rows, key=lambda r: (str(r["machine"]), str(r["session"])))
    measures = list(dict.fromkeys(str(r["latency"]) for r in rows if r.get("latency")))
    machines: dict[str, JsonObject] = {}
    for r in rows:
        m = machines.setdefault(r["machine"], {
            "machine": r["machine"], "sessions": 0, "errors": 0, "damaged": 0,
            "duration_s": 0.0, "exchanges": 0, **dict.fromkeys(totals, 0),
            "severities": dict.fromkeys(SEVERITIES, 0),
            "rtt_p95_ms_worst": None, "rtt_p99_ms_worst": None, "latency": {}})
        m["sessions"] += 1
        if r["state"] == "error":
            m["errors"] += 1
            continue
        m["damaged"] += r["state"] == "damaged"
        for k in ("duration_s", "exchanges", *totals):
            m[k] += r.get(k) or 0
        for k, n in (r.get("severities") or {}).items():
            m["severities"][k] = m["severities"].get(k, 0) + n
        worst = m["latency"].setdefault(str(r.get("latency")), {"p95": None, "p99": None})
        for k in ("rtt_p95_ms", "rtt_p99_ms"):
            v = r.get(k)
            if v is not None:
                key = k + "_worst"
                m[key] = v if m[key] is None else max(m[key], v)
                q = k[4:7]
                worst[q] = v if worst[q] is None else max(worst[q], v)
    for m in machines.values():
        d = m["duration_s"]
        m["exchanges_per_s"] = m["exchanges"] / d if d > 0 else None
        for c in cols:
            if c.total and c.rate:
                m[c.rate] = m[c.key] / d if d > 0 else None
    sev = {k: sum(m["severities"].get(k, 0) for m in machines.values()) for k in SEVERITIES}
    out = {"sessions": rows, "machines": list(machines.values()),
           "totals": {"sessions": len(rows), "machines": len(machines),
                      "errors": sum(r["state"] == "error" for r in rows),
                      "damaged": sum(r["state"] == "damaged" for r in rows),
                      **{k: sum(r.get(k) or 0 for r in rows) for k in totals},
                      "exchanges": sum(r.get("exchanges") or 0 for r in rows),
                      "severities": sev},
           "columns": [asdict(c) for c in cols], "latencies": measures,
           "notes": _clock_notes(rows)}
    out["verdict"] = verdict(out)
    return out


def _clock_notes(rows: list[JsonObject]) -> list[str]:
    """What the time axis leaves out: sessions recorded on an emulator's virtual clock."""
    virtual = [str(r["session"]) for r in rows if r.get("clock") == "virtual"]
    if not virtual:
        return []
    names = ", ".join(virtual[:5]) + (" …" if len(virtual) > 5 else "")
    return [f"{count(len(virtual), 'session')} ran on an emulator's virtual clock, whose start "
            f"is no wall-clock time, so not placed in time: {names}"]


def verdict(s: JsonObject) -> dict[str, str]:
    """The fleet in a word (``INCOMPLETE``: a capture damaged or not analysed; ``HAZARD``:
    a finding of that severity; ``ERROR``: one of that; else ``CLEAN``) and a sentence
    naming the machines concerned."""
    t = s["totals"]
    sev = t["severities"]

    def where(test: Callable[[JsonObject], object]) -> str:
        names = [str(m["machine"]) for m in s["machines"] if test(m)]
        return f"on {', '.join(names[:5])}{' …' if len(names) > 5 else ''}"

    if t["errors"] or t["damaged"]:
        word = "INCOMPLETE"
        text = (f"{count(t['errors'], 'capture')} not analysed and {t['damaged']} damaged "
                + where(lambda m: m["errors"] or m["damaged"]))
    elif sev.get("hazard"):
        word = "HAZARD"
        text = (f"{count(sev['hazard'], 'hazard')} "
                + where(lambda m: m["severities"].get("hazard")))
    elif sev.get("error"):
        word = "ERROR"
        text = (f"{count(sev['error'], 'error finding')} "
                + where(lambda m: m["severities"].get("error")))
    else:
        word, text = "CLEAN", "no hazard and no error finding in any session"
    return {"word": word, "text": text}


def totals_text(counts: JsonObject, columns: list[JsonObject]) -> str:
    """The families' totals of a fleet or a machine as text: ``, 3 hazards, 10 starvations``
    (their ``summary`` columns), or nothing."""
    return "".join(f", {counts.get(c['key']) or 0} {c['label']}" for c in columns
                   if c["total"] and c["summary"])


def write_fleet_report(summary: JsonObject, out_dir: str | Path) -> dict[str, Path]:
    """``fleet.json``, ``summary.md`` and a self-contained ``index.html`` (the page pieces
    and look of a session's analysis report: the verdict first, then the plots and the
    tables, each session's row linking its own report when one was written)."""
    from conform.analysis.fleetplots import fleet_plots
    from conform.analysis.report import _clean, report_folder, template_env

    d = report_folder(out_dir)
    doc = _clean(summary)
    env = template_env()
    paths = {"json": d / "fleet.json", "markdown": d / "summary.md", "html": d / "index.html"}
    plots = fleet_plots(doc)
    paths["json"].write_text(json.dumps(doc, indent=1), "utf-8")
    ctx = {"s": doc, "fmt": _fmt, "count": count, "plots": plots, "rtt": _rtt}
    paths["markdown"].write_text(env.get_template("fleet.md.j2").render(**ctx), "utf-8")
    paths["html"].write_text(env.get_template("fleet.html.j2").render(**ctx), "utf-8")
    return paths


def fleet_datasets(parquet_dir: str | Path) -> list[str]:
    """The datasets a fleet run wrote into ``parquet_dir`` (each table's folder, a family's
    under its name), as paths to say: ``t/exchanges``, never ``t//exchanges``."""
    root = Path(parquet_dir)
    out: list[str] = []
    for d in sorted(q for q in root.glob("*") if q.is_dir() and not q.name.startswith(".")):
        subs = [q for q in sorted(d.iterdir()) if q.is_dir() and not q.name.startswith(("machine=", "."))]
        out.extend(str(q) for q in subs) if subs else out.append(str(d))
    return out or [str(root)]


def count(n: int, noun: str) -> str:
    """``1 machine``, ``2 machines``: a count and its noun, in the right number."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _rtt(r: JsonObject, measure: str) -> str:
    """A session's latency percentiles under its family's measure's column, else nothing."""
    if r.get("latency") != measure:
        return ""
    return " / ".join(_fmt(r.get(k), ".1f") for k in ("rtt_p50_ms", "rtt_p95_ms", "rtt_p99_ms"))


def _fmt(v: object, spec: str = ".2f") -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return format(v, spec)
    return str(v)
