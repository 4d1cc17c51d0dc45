"""The GVE analyser: a capture of GVE traffic -> decoded lines, exchanges, the queue replay,
metrics and findings (docs/analysis.md); the family's ``analyze``. Reading the capture, the
streaming parts, mergeable summaries, Parquet tables, plots and reports are the engine's
(conform.analysis)."""

from conform.families.gve.analysis.analyze import Analysis, analyze
from conform.families.gve.analysis.findings import Finding

__all__ = ["Analysis", "Finding", "analyze"]
