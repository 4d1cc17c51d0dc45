"""Captured sessions -> pandas tables, metrics, findings and reports (``conform analyze``)."""

from conform.analysis.analyze import Analysis, analyze
from conform.analysis.findings import Finding
from conform.analysis.report import findings_document, write_parquet, write_report

__all__ = ["Analysis", "Finding", "analyze", "findings_document", "write_parquet",
           "write_report"]
