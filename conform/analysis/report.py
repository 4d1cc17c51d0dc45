"""Write an analysis out: ``index.html`` (self-contained), ``summary.md``, ``findings.json``
and, on request, Parquet tables."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from conform.capture.session import escape_bytes
from conform.errors import UserError

TEMPLATES = Path(__file__).with_name("templates")


def _clean(x: Any, finite: bool = True) -> Any:
    """Plain Python: numpy scalars to Python; NaN/inf to None for JSON (``finite``), kept
    as floats for the templates (which format them as ``nan``/``inf``)."""
    if isinstance(x, dict):
        return {str(k): _clean(v, finite) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v, finite) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if finite and isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def findings_document(a: Any) -> dict[str, Any]:
    return _clean({
        "capture": a.path,
        "variant": a.variant.id,
        "findings": [f.to_dict() for f in a.findings],
        "metrics": a.metrics,
        "notes": a.notes,
    })


def _env() -> Any:
    import jinja2

    from conform.report.render import TEMPLATES as SHARED  # pieces every analysis report shares

    return jinja2.Environment(loader=jinja2.ChoiceLoader([jinja2.FileSystemLoader(str(TEMPLATES)),
                                                          jinja2.FileSystemLoader(str(SHARED))]),
                              autoescape=jinja2.select_autoescape(("html", "html.j2"), default=False),
                              trim_blocks=True, lstrip_blocks=True)


def _fmt_ms(v: Any) -> str:
    return "–" if v is None or v != v else f"{v * 1000:.3f}"


def _context(a: Any, plots: dict[str, str]) -> dict[str, Any]:
    m = _clean(a.metrics, finite=False)
    by_sev: dict[str, int] = {}
    for f in a.findings:
        by_sev[f.severity] = by_sev.get(f.severity, 0) + 1
    return {
        "a": a, "m": m, "plots": plots, "findings": a.findings, "by_sev": by_sev,
        "counts": m.get("finding_counts", {}), "ms": _fmt_ms,
        "hazards": m.get("hazards", 0), "notes": a.notes,
        "status": a.raw.status,
        "code_meaning": getattr(a, "code_meaning", None),   # the family's, when it has one
    }


def report_folder(out_dir: str | Path) -> Path:
    """The report folder, created if needed (``UserError`` if it cannot be)."""
    d = Path(out_dir)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{d}: cannot create the report folder: {exc.strerror}") from None
    return d


def write_report(a: Any, out_dir: str | Path) -> dict[str, Path]:
    from conform.analysis.plots import all_plots

    d = report_folder(out_dir)
    plots = all_plots(a)
    env = _env()
    ctx = _context(a, plots)
    paths = {"html": d / "index.html", "markdown": d / "summary.md",
             "json": d / "findings.json"}
    paths["html"].write_text(env.get_template("report.html.j2").render(**ctx), "utf-8")
    paths["markdown"].write_text(env.get_template("summary.md.j2").render(**ctx), "utf-8")
    paths["json"].write_text(json.dumps(findings_document(a), indent=1), "utf-8")
    return paths


def write_parquet(a: Any, out_dir: str | Path, row_group: int | None = None
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

    rows = row_group or ROW_GROUP
    times = ("t_cmd_first", "t_cmd_last", "t_ans_first", "t_ans_last")

    def exchange_rows(part: Any, lo: int, hi: int) -> Any:
        part = relative_times(part, a.t0, times)
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


