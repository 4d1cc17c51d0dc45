"""What a GVE analysis gives ``conform analyze`` (``conform.families.AnalysisResult``): the
lines it prints, its report (the GVE templates in templates/ on the engine's shared pieces,
with the GVE plots), its Parquet tables and its row of a fleet summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from conform.analysis.report import base_context, findings_document, render_report
from conform.capture.session import escape_bytes
from conform.errors import UserError

TEMPLATES = Path(__file__).with_name("templates")
SHOWN = ("hazard", "error")  # severities listed one by one under the counts


def summary_lines(a: Any) -> list[str]:
    """The session in a line, the capture's damage, the notes, the findings by kind and
    every hazard and error."""
    m = a.metrics
    out = [f"{a.path}: {m['exchanges']} exchanges in {m['duration_s']:.3f} s "
           f"({m['exchanges_per_s']:.1f}/s), {m['vectors_accepted']} vectors, "
           f"baud {int(m['baud']['used'])}"]
    damage = a.raw.status.describe()
    if damage:
        out.append(f"capture damaged: {damage}; analysed what is intact")
    out += [f"note: {note}" for note in a.notes]
    counts = m.get("finding_counts", {})
    out.append("findings: " + (", ".join(f"{k} {n}" for k, n in counts.items()) if counts
                               else "none"))
    out += [f"  {f.t:10.4f}s {f.severity:7} {f.kind}: {f.message}" for f in a.findings
            if f.severity in SHOWN]
    return out


def write_report(a: Any, out_dir: str | Path) -> dict[str, Path]:
    ctx = base_context(a) | {"plots": a.plots(), "hazards": a.metrics.get("hazards", 0),
                             "status": a.raw.status}
    return render_report(out_dir, TEMPLATES, ctx, findings_document(a))


def fleet_row(a: Any) -> dict[str, Any]:
    """The engine's fleet columns and the family's (``GveFamily.fleet_columns``)."""
    m = a.metrics
    rtt = m.get("latency", {}).get("rtt", {})
    q = m.get("queue") or {}
    return {
        "state": "clean" if a.raw.status.clean else "damaged",
        "duration_s": m["duration_s"], "exchanges": m["exchanges"],
        "vectors_accepted": m["vectors_accepted"], "exchanges_per_s": m["exchanges_per_s"],
        "vectors_per_s": m["vectors_per_s"], "hazards": m["hazards"],
        "findings": dict(m.get("finding_counts", {})),
        "rtt_p50_ms": _ms(rtt.get("median")), "rtt_p95_ms": _ms(rtt.get("p95")),
        "rtt_p99_ms": _ms(rtt.get("p99")), "rtt_max_ms": _ms(rtt.get("max")),
        "starvations": q.get("starvations"), "starved_s": q.get("starved_s"),
        "standstill_s": q.get("standstill_s"),
    }


def _ms(v: Any) -> float | None:
    return None if v is None else round(float(v) * 1000, 4)


def write_tables(a: Any, out_dir: str | Path, row_group: int | None = None
                 ) -> dict[str, Path]:
    """The exchange, frame, series and queue-depth tables, streamed in row groups
    (``conform.analysis.tables``). A streamed analysis kept no tables: it wrote them while
    it ran (``analyze(…, parquet=DIR)``), and those are the ones returned."""
    if not a.whole:
        if a.tables:
            return dict(a.tables)
        raise UserError(f"{a.path}: the capture was streamed, not kept: analyse it with "
                        "--parquet to write its tables")
    d = Path(out_dir)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{d}: cannot create the folder: {exc.strerror}") from None
    from conform.analysis.tables import ROW_GROUP, relative_times, write_frame, write_table
    from conform.families.gve.analysis.columns import TIMES

    rows = row_group or ROW_GROUP

    def exchange_rows(part: Any, lo: int, hi: int) -> Any:
        part = relative_times(part, a.t0, TIMES["exchanges"])
        bodies = a.host.lines.bodies.slice(lo, hi - lo).to_pylist()
        part["command"] = [escape_bytes(b) for b in bodies]
        return part

    out = {"exchanges": write_frame(d / "exchanges.parquet", a.exchanges, rows,
                                    extra=exchange_rows)}
    for direction in ("host", "unit"):  # a slice of lines at a time
        out[f"frames_{direction}"] = write_table(
            d / f"frames_{direction}.parquet", len(a.host if direction == "host" else a.unit),
            lambda lo, hi, w=direction: a.frames(w, lo, hi), frame_categories(a, direction),
            rows)
    out["series"] = write_frame(d / "series.parquet", a.series, rows)
    if a.queue is not None:
        import pandas as pd

        q = a.queue
        out["queue_depth"] = write_frame(d / "queue_depth.parquet",
                                         pd.DataFrame({"t": q.depth_t - a.t0, "depth": q.depth}), rows)
    return out


def frame_categories(a: Any, direction: str) -> dict[str, list[Any] | None]:
    """The category lists of a frames table, from the decoded columns (no table built)."""
    from conform.analysis.tables import categories_of

    d = a.host if direction == "host" else a.unit
    cols = {"direction": np.array([direction], object), "kind": d.kind, "name": d.name,
            "checksum_status": a.checksum_names, "detail": d.detail}
    if direction == "host":
        cols["packet_role"] = a.exchanges["packet_role"].to_numpy()
    cats: dict[str, list[Any] | None] = {k: categories_of(v) for k, v in cols.items()}
    cats["text"] = None
    return cats
