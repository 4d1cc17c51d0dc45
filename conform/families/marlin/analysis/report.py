"""The files of a Marlin capture analysis: index.html, summary.md and findings.json (the
report), lines.parquet and findings.parquet (the tables)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from conform.errors import UserError


def _summary(a: Any) -> str:
    from conform.families.marlin.analysis.htmlreport import figures, verdict

    word, sentence = verdict(a)
    return a.summary_markdown(
        [f"# Marlin capture analysis: {a.path}", "",
         f"family: marlin, variant {a.variant} ({a.detected})", "", f"**{word}:** {sentence}",
         "", *(f"- {what}: {value}" for what, value in figures(a)), "", "## Metrics"],
        ["", *(f"note: {n}" for n in a.notes)])


def _html(a: Any) -> str:
    from conform.families.marlin.analysis.htmlreport import render_html

    return render_html(a)


def write_report(a: Any, directory: str) -> dict[str, Path]:
    return a.report_files(directory, lambda: _summary(a), lambda: _html(a))


LINE_SCHEMA = (("t_sent", "float64"), ("n", "int64"), ("text", "string"), ("bytes", "int64"),
               ("checksum_ok", "bool_"), ("epoch", "int64"), ("accepted", "bool_"),
               ("repeat", "bool_"), ("t_ok", "float64"))
ROWS = 65_536   # rows per row group of lines.parquet


class LineTable:
    """lines.parquet written ``ROWS`` host lines at a time as their fate settles (one row per
    line in send order, times from the first host line), findings.parquet at the end."""

    def __init__(self, directory: Path, t0: float) -> None:
        import pyarrow as pa

        self.dir, self.t0 = directory, t0
        self.schema = pa.schema([(k, getattr(pa, v)()) for k, v in LINE_SCHEMA])
        self.cols: dict[str, list[Any]] = {k: [] for k, _ in LINE_SCHEMA}
        self.writer: Any = None
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"{directory}: cannot create the folder: {exc.strerror}") from None

    def add(self, h: Any) -> None:
        c = self.cols
        c["t_sent"].append(h.t - self.t0)
        c["n"].append(h.n)
        c["text"].append(h.text)
        c["bytes"].append(h.raw_size)
        c["checksum_ok"].append(h.checksum_ok)
        c["epoch"].append(h.epoch)
        c["accepted"].append(h.accepted)
        c["repeat"].append(h.repeat)
        c["t_ok"].append(None if h.t_ok is None else h.t_ok - self.t0)
        if len(c["n"]) >= ROWS:
            self.flush()

    def flush(self) -> None:
        import pyarrow as pa

        from conform.analysis.tables import open_writer

        try:
            if self.writer is None:
                self.writer = open_writer(self.dir / "lines.parquet", self.schema)
            self.writer.write_table(pa.table(self.cols, schema=self.schema))
        except OSError as exc:
            raise UserError(f"{self.dir}: cannot write the tables: {exc.strerror or exc}"
                            ) from None
        self.cols = {k: [] for k in self.cols}

    def close(self) -> None:
        if self.cols["n"] or self.writer is None:
            self.flush()
        self.writer.close()

    def finish_findings(self, findings: list[Any]) -> dict[str, Path]:
        from conform.analysis.result import findings_table, save_tables

        save_tables(self.dir, {"findings": findings_table(findings)})
        return {"lines": self.dir / "lines.parquet", "findings": self.dir / "findings.parquet"}


def write_parquet(a: Any, directory: str) -> dict[str, Path]:
    """The tables of ``a`` in ``directory`` (see ``MarlinAnalysis.write_tables``)."""
    import shutil

    d = Path(directory)
    if a.tables is not None:
        src = a.tables["lines"].parent
        if src.resolve() != d.resolve():
            d.mkdir(parents=True, exist_ok=True)
            for p in a.tables.values():
                shutil.copyfile(p, d / p.name)
        return {k: d / p.name for k, p in a.tables.items()}
    if a.lines_kept:
        table = LineTable(d, min((h.t for h in a.lines), default=0.0))
        for h in a.lines:
            table.add(h)
        table.close()
        return table.finish_findings(a.findings)
    raise UserError("the Marlin analysis kept no lines and wrote no tables: ask for the "
                    "tables when analysing (parquet=)")
