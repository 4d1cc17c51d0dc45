"""Captured sessions -> tables, metrics, findings and reports (``conform analyze``).

The engine's side of the analysis: reading captures (``rawread``, ``stream``), mergeable
summaries, Parquet tables, plots, reports and fleets. What the traffic means is a family's
(``Family.analyze`` in conform.families); the GVE analyser is conform.families.gve.analysis.
"""

from typing import Any

from conform.analysis.report import findings_document, write_parquet, write_report


def analyze(path: Any, **options: Any) -> Any:
    """A capture analysed by the default family, which judges every capture no other family
    claims: ``conform analyze`` first hands other families' captures to them
    (conform.families.capture_hook)."""
    from conform.families import default_family

    return default_family().analyze(path, **options)


__all__ = ["analyze", "findings_document", "write_parquet", "write_report"]
