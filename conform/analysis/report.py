"""Write an analysis out: ``index.html`` (self-contained), ``summary.md``, ``findings.json``
and, on request, Parquet tables.

The engine's part of every family's analysis report: the shared template pieces (page head,
severity badges, the findings table: conform/report/templates/analysis_pieces.html.j2), the
context every report has (the analysis, its metrics, findings by severity, notes) and the
writing of the three files. A family's analysis brings its own ``report.html.j2`` and
``summary.md.j2`` (its sections and plots, built on those pieces) through ``render_report``;
``write_report`` and ``write_parquet`` ask the analysis itself (``AnalysisResult`` in
conform.families)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from conform.errors import UserError

if TYPE_CHECKING:
    import jinja2

    from conform.analysis.result import Reported
    from conform.families import AnalysisResult

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


def findings_document(a: Any) -> dict[str, object]:
    return _clean({
        "capture": a.path,
        "variant": a.variant.id,
        "findings": [f.to_dict() for f in a.findings],
        "metrics": a.metrics,
        "notes": a.notes,
    })


def template_env(*folders: Path) -> jinja2.Environment:
    """Templates from ``folders`` (a family's) first, then the engine's and the shared
    pieces."""
    import jinja2

    from conform.report.render import TEMPLATES as SHARED  # pieces every analysis report shares

    loaders = [jinja2.FileSystemLoader(str(d)) for d in (*folders, TEMPLATES, SHARED)]
    return jinja2.Environment(loader=jinja2.ChoiceLoader(loaders),
                              autoescape=jinja2.select_autoescape(("html", "html.j2"), default=False),
                              trim_blocks=True, lstrip_blocks=True)


def fmt_ms(v: float | None) -> str:
    return "–" if v is None or v != v else f"{v * 1000:.3f}"


def severity_counts(findings: Iterable[Any]) -> dict[str, int]:
    """How many findings of each severity, in the order they first appear."""
    by_sev: dict[str, int] = {}
    for f in findings:
        by_sev[f.severity] = by_sev.get(f.severity, 0) + 1
    return by_sev


def base_context(a: Reported) -> dict[str, object]:
    """What every analysis report's templates get: the analysis ``a``, its metrics ``m``
    (plain, non-finite kept), ``findings``, their number per severity and per kind, the
    notes and ``ms`` (seconds as milliseconds)."""
    m = _clean(a.metrics, finite=False)
    return {"a": a, "m": m, "findings": a.findings, "by_sev": severity_counts(a.findings),
            "counts": m.get("finding_counts", {}), "ms": fmt_ms, "notes": a.notes,
            "code_meaning": getattr(a, "code_meaning", None)}   # the family's, when it has one


def report_folder(out_dir: str | Path) -> Path:
    """The report folder, created if needed (``UserError`` if it cannot be)."""
    d = Path(out_dir)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{d}: cannot create the report folder: {exc.strerror}") from None
    return d


def render_report(out_dir: str | Path, templates: Path, context: dict[str, object],
                  document: dict[str, object]) -> dict[str, Path]:
    """A family's report: ``index.html`` and ``summary.md`` from its ``templates`` folder
    (``report.html.j2``, ``summary.md.j2``) with ``context`` (``base_context`` and its own
    keys), and ``document`` as ``findings.json``."""
    d = report_folder(out_dir)
    env = template_env(templates)
    paths = {"html": d / "index.html", "markdown": d / "summary.md",
             "json": d / "findings.json"}
    paths["html"].write_text(env.get_template("report.html.j2").render(**context), "utf-8")
    paths["markdown"].write_text(env.get_template("summary.md.j2").render(**context), "utf-8")
    paths["json"].write_text(json.dumps(document, indent=1), "utf-8")
    return paths


def write_report(a: AnalysisResult, out_dir: str | Path) -> dict[str, Path]:
    """The report of any family's analysis (its ``write_report``)."""
    return a.write_report(str(out_dir))


def write_parquet(a: Any, out_dir: str | Path, row_group: int | None = None
                  ) -> dict[str, Path]:
    """The tables of any family's analysis (its ``write_tables``; ``row_group``: rows per
    Parquet row group, for a family that takes it)."""
    if row_group is None:
        return a.write_tables(out_dir)
    return a.write_tables(out_dir, row_group=row_group)
