"""The files of a Marlin capture analysis: index.html, summary.md and findings.json (the
report), lines.parquet and findings.parquet (the tables)."""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from conform.errors import UserError


def _summary(a: Any) -> str:
    lines = [f"# Marlin capture analysis: {a.path}", "", f"family: marlin, variant {a.variant} "
             f"({a.detected})", ""]
    lines += [f"- {k}: {v}" for k, v in a.metrics.items() if k != "finding_counts"]
    lines += ["", "## Findings", ""]
    lines += [f"- {f.t:.4f} s {f.severity} {f.kind}: {f.message} [{f.clause}]"
              for f in a.findings] or ["none"]
    return "\n".join(lines + [""] + [f"note: {n}" for n in a.notes]) + "\n"


def _html(a: Any) -> str:
    e = html.escape
    rows = "".join(f"<tr><td>{e(k)}</td><td>{e(str(v))}</td></tr>" for k, v in a.metrics.items()
                   if k != "finding_counts")
    found = "".join(f"<tr class='{e(f.severity)}'><td>{f.t:.4f}</td><td>{e(f.severity)}</td>"
                    f"<td>{e(f.kind)}</td><td>{e(f.message)}</td><td>{e(f.clause)}</td></tr>"
                    for f in a.findings[:2000])
    return ("<!doctype html><html><head><meta charset='utf-8'><title>Marlin capture analysis"
            "</title><style>body{font-family:sans-serif}td{padding:2px 8px}.hazard{background:"
            "#fdd}.error{background:#fee}</style></head><body>"
            f"<h1>Marlin capture analysis</h1><p>{e(a.path)} — variant {e(a.variant)} "
            f"({e(a.detected)})</p><p>{'<br>'.join(e(x) for x in a.summary_lines()[:2])}</p>"
            f"<h2>Metrics</h2><table>{rows}</table><h2>Findings ({len(a.findings)})</h2>"
            "<table><tr><th>t (s)</th><th>severity</th><th>kind</th><th>what</th><th>source"
            f"</th></tr>{found}</table></body></html>\n")


def write_json(a: Any) -> str:
    """findings.json: the analysis as its JSON document."""
    return json.dumps(a.to_json(), indent=1, default=str)


def write_report(a: Any, directory: str) -> dict[str, Path]:
    from conform.report.render import write_files

    d = write_files(directory, {"findings.json": lambda: write_json(a), "summary.md":
                                lambda: _summary(a), "index.html": lambda: _html(a)})
    return {"json": d / "findings.json", "md": d / "summary.md", "html": d / "index.html"}


def write_parquet(a: Any, directory: str) -> dict[str, Path]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    d = Path(directory)
    x = a.lines
    t0 = min((h.t for h in x), default=0.0)
    tables = {
        "lines": pa.table({
            "t_sent": [h.t - t0 for h in x], "n": [h.n for h in x], "text": [h.text for h in x],
            "bytes": [h.raw_size for h in x], "checksum_ok": [h.checksum_ok for h in x],
            "epoch": [h.epoch for h in x], "accepted": [h.accepted for h in x],
            "repeat": [h.repeat for h in x],
            "t_ok": [None if h.t_ok is None else h.t_ok - t0 for h in x]}),
        "findings": pa.table({
            "t": [f.t for f in a.findings], "kind": [f.kind for f in a.findings],
            "severity": [f.severity for f in a.findings],
            "message": [f.message for f in a.findings], "clause": [f.clause for f in a.findings]}),
    }
    try:
        d.mkdir(parents=True, exist_ok=True)
        for name, table in tables.items():
            pq.write_table(table, d / f"{name}.parquet")
    except OSError as exc:
        raise UserError(f"{d}: cannot write the tables: {exc.strerror or exc}") from None
    return {name: d / f"{name}.parquet" for name in tables}
