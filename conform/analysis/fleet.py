"""Analyse many captures at once: a fleet of machines, a week of shifts.

    conform analyze captures/ --report fleet/ --parquet tables/          # all local cores
    conform analyze m1/*.mcap m2/*.mcap --scheduler tcp://sched:8786     # Dask distributed

Every capture is analysed on its own (one task per file) by a pool of local processes or by
the workers of an existing Dask distributed scheduler; each task writes its tables into one
Parquet dataset (``DIR/exchanges/machine=M/session=S.parquet``, hive partitioned, so pandas,
polars or DuckDB read the whole fleet as one table) and returns a small summary row. The
rows become the fleet summary (per machine and session: duration, exchanges, throughput,
latency percentiles, findings, and the columns each family declares, ``Family.fleet_columns``)
as HTML, Markdown and JSON.

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
from typing import Any

from conform.errors import UserError
from conform.families import FleetColumn, default_family, families, family

SUMMARY_KEYS = ("machine", "session", "family", "path", "state", "error", "duration_s", "exchanges",
                "exchanges_per_s", "findings", "rtt_p50_ms", "rtt_p95_ms", "rtt_p99_ms",
                "rtt_max_ms")  # every family's; then the families' own (``fleet_columns``)


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


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._")[:80] or "unnamed"


def machine_of(path: Path, metadata: dict[str, dict[str, str]]) -> str:
    """The machine a capture belongs to: the session's ``machine`` key, else its folder."""
    session = metadata.get("conform.session", {})
    return str(session.get("machine") or path.parent.name or session.get("hostname") or "-")


def analyze_one(path: str, parquet_dir: str | None, options: dict[str, Any]) -> dict[str, Any]:
    """One fleet task: analyse ``path``, write its Parquet part, return its summary row."""
    from conform.analysis import analyze

    p = Path(path)
    row: dict[str, Any] = dict.fromkeys(SUMMARY_KEYS) | dict.fromkeys(
        c.key for c in fleet_columns())
    row.update(machine=p.parent.name or "-", session=p.stem, path=str(p), state="error")
    other = _other_family(p, parquet_dir, options, row)
    if other is not None:
        return other
    row["family"] = default_family().name
    sink = None
    if parquet_dir:  # this capture's exchanges: one file of the fleet's dataset, as it streams
        from conform.analysis.tables import ParquetStream

        root = Path(parquet_dir)
        part = root / "exchanges" / f"machine={_safe(row['machine'])}" / f"{_safe(p.stem)}.parquet"
        sink = ParquetStream(root, only=("exchanges",), files={"exchanges": part},
                             const={"session": p.stem, "t0": None})
    a = _attempt(row, lambda: analyze(p, whatif_replays=False, parquet=sink, **options))
    if a is None:
        return row
    row.update(a.fleet_row())
    row["machine"] = machine_of(p, a.raw.metadata)
    if sink is not None and row["machine"] != p.parent.name:  # named by the metadata
        d = Path(parquet_dir) / "exchanges" / f"machine={_safe(row['machine'])}"
        d.mkdir(parents=True, exist_ok=True)
        for path in a.tables.values():
            path.replace(d / path.name)
    return row


def _other_family(p: Path, parquet_dir: str | None, options: dict[str, Any],
                  row: dict[str, Any]) -> dict[str, Any] | None:
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
    machine = machine_of(p, {"conform.session": meta})
    base = Path(parquet_dir or ".") / d.family
    tmp = base / f".{_safe(machine)}-{_safe(p.stem)}"
    a = _attempt(row, lambda: family(d.family).analyze(  # a family may stream its tables there
        str(p), variant=options.get("variant"), detected=d.why,
        parquet=str(tmp) if parquet_dir else None))
    if a is None:
        if parquet_dir:
            shutil.rmtree(tmp, ignore_errors=True)
        return row
    row.update(a.fleet_row())
    row["machine"] = machine
    if parquet_dir:
        for table in a.write_tables(str(tmp)).values():
            dest = base / table.stem / f"machine={_safe(row['machine'])}" / f"{_safe(p.stem)}.parquet"
            dest.parent.mkdir(parents=True, exist_ok=True)
            table.replace(dest)
        shutil.rmtree(tmp, ignore_errors=True)
    return row


def _attempt(row: dict[str, Any], run: Callable[[], Any]) -> Any:
    """``run()``'s analysis, or None with the row's error set: one bad file must not end a
    fleet run."""
    try:
        return run()
    except UserError as exc:
        row["error"] = str(exc)
    except Exception as exc:  # noqa: BLE001 - reported in the row
        row["error"] = f"{type(exc).__name__}: {exc}"
    return None


Runner = Callable[[list[str], str | None, dict[str, Any]], list[dict[str, Any]]]


def run_local(paths: list[str], parquet_dir: str | None, options: dict[str, Any],
              jobs: int | None = None) -> list[dict[str, Any]]:
    """Every file on a pool of local processes (all cores by default)."""
    jobs = jobs or os.cpu_count() or 1
    if jobs == 1 or len(paths) == 1:
        return [analyze_one(p, parquet_dir, options) for p in paths]
    with ProcessPoolExecutor(max_workers=min(jobs, len(paths))) as pool:
        return list(pool.map(analyze_one, paths, [parquet_dir] * len(paths),
                             [options] * len(paths)))


def run_dask(paths: list[str], parquet_dir: str | None, options: dict[str, Any],
             scheduler: Any) -> list[dict[str, Any]]:
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
        futures = client.map(analyze_one, paths, parquet_dir=parquet_dir, options=options,
                             pure=False)
        return client.gather(futures)
    finally:
        client.close()


def analyze_fleet(inputs: Iterable[str], *, parquet_dir: str | None = None,
                  options: dict[str, Any] | None = None, jobs: int | None = None,
                  scheduler: Any = None) -> dict[str, Any]:
    """Analyse every capture in ``inputs``; the fleet summary (see ``summarise``)."""
    paths = [str(p.resolve()) for p in expand_inputs(inputs)]
    if parquet_dir:
        Path(parquet_dir).mkdir(parents=True, exist_ok=True)
    opts = dict(options or {})
    if scheduler is not None:
        rows = run_dask(paths, parquet_dir, opts, scheduler)
    else:
        rows = run_local(paths, parquet_dir, opts, jobs)
    return summarise(rows)


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Sessions sorted by machine and session, one aggregate row per machine and the
    fleet's totals; ``columns``: the families' columns (``fleet_columns``) as plain dicts."""
    cols = fleet_columns()
    totals = [c.key for c in cols if c.total]
    rows = sorted(rows, key=lambda r: (str(r["machine"]), str(r["session"])))
    machines: dict[str, dict[str, Any]] = {}
    for r in rows:
        m = machines.setdefault(r["machine"], {
            "machine": r["machine"], "sessions": 0, "errors": 0, "damaged": 0,
            "duration_s": 0.0, "exchanges": 0, **dict.fromkeys(totals, 0),
            "rtt_p95_ms_worst": None, "rtt_p99_ms_worst": None})
        m["sessions"] += 1
        if r["state"] == "error":
            m["errors"] += 1
            continue
        m["damaged"] += r["state"] == "damaged"
        for k in ("duration_s", "exchanges", *totals):
            m[k] += r.get(k) or 0
        for k in ("rtt_p95_ms", "rtt_p99_ms"):
            v = r.get(k)
            if v is not None:
                key = k + "_worst"
                m[key] = v if m[key] is None else max(m[key], v)
    for m in machines.values():
        d = m["duration_s"]
        m["exchanges_per_s"] = m["exchanges"] / d if d > 0 else None
        for c in cols:
            if c.total and c.rate:
                m[c.rate] = m[c.key] / d if d > 0 else None
    return {"sessions": rows, "machines": list(machines.values()),
            "totals": {"sessions": len(rows), "machines": len(machines),
                       "errors": sum(r["state"] == "error" for r in rows),
                       **{k: sum(r.get(k) or 0 for r in rows) for k in totals},
                       "exchanges": sum(r.get("exchanges") or 0 for r in rows)},
            "columns": [asdict(c) for c in cols]}


def totals_text(counts: dict[str, Any], columns: list[dict[str, Any]]) -> str:
    """The families' totals of a fleet or a machine as text: ``, 3 hazards, 10 starvations``
    (their ``summary`` columns), or nothing."""
    return "".join(f", {counts.get(c['key']) or 0} {c['label']}" for c in columns
                   if c["total"] and c["summary"])


def write_fleet_report(summary: dict[str, Any], out_dir: str | Path) -> dict[str, Path]:
    """``fleet.json``, ``summary.md`` and a self-contained ``index.html``."""
    from conform.analysis.report import _clean, _env, report_folder

    d = report_folder(out_dir)
    doc = _clean(summary)
    env = _env()
    paths = {"json": d / "fleet.json", "markdown": d / "summary.md", "html": d / "index.html"}
    paths["json"].write_text(json.dumps(doc, indent=1), "utf-8")
    ctx = {"s": doc, "fmt": _fmt, "count": count}
    paths["markdown"].write_text(env.get_template("fleet.md.j2").render(**ctx), "utf-8")
    paths["html"].write_text(env.get_template("fleet.html.j2").render(**ctx), "utf-8")
    return paths


def count(n: int, noun: str) -> str:
    """``1 machine``, ``2 machines``: a count and its noun, in the right number."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _fmt(v: Any, spec: str = ".2f") -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return format(v, spec)
    return str(v)
