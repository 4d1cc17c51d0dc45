"""What the analyses of the line-based families share: the finding record, and a base for
their results with the parts of ``conform.families.AnalysisResult`` that do not depend on the
protocol: the findings line and the serious findings ``conform analyze`` prints, the JSON
document of ``findings.json``, ``summary.md``, the findings table and the engine's columns of
a fleet row. A family keeps what is its own: its metrics, its headline, its HTML report and
its other tables."""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import KW_ONLY, asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from conform.jsondoc import JsonObject

if TYPE_CHECKING:
    from conform.analysis.rawread import ReadStatus

SERIOUS = ("hazard", "error")
"""The severities ``conform analyze`` lists one by one under the findings line."""


@dataclass
class Finding:
    """Something the analysis found, ``t`` s into the session, with the clause it rests on
    and whatever else it knows (``extra``: the line, the code...)."""

    kind: str
    t: float
    severity: str         # info | warning | error | hazard
    message: str
    clause: str = ""
    extra: dict[str, object] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        """Its fields, ``extra``'s keys in place of ``extra`` (the ``--json`` shape)."""
        d = asdict(self)
        d.update(d.pop("extra"))
        return d


class Reported(Protocol):
    """What the engine's report pieces read of any family's analysis: its findings, metrics
    (``finding_counts``...) and notes (a plot that failed adds one)."""

    @property
    def findings(self) -> Sequence[Finding]: ...

    @property
    def metrics(self) -> JsonObject: ...

    @property
    def notes(self) -> list[str]: ...


@dataclass
class ResultBase:
    """A family's analysis result: the capture's ``path``, the ``family``, the ``variant``
    analysed, how the family was ``detected``, the ``notes`` on the analysis and whether the
    capture file was whole (``complete``; both keyword-only, after the family's fields). The
    family's dataclass adds its records, ``findings`` and ``metrics`` (at least
    ``duration_s``, ``hazards`` and ``finding_counts``), and brings ``summary_lines``,
    ``write_report`` and ``write_tables`` built on the helpers here."""

    path: str
    family: str
    variant: str
    detected: str
    _: KW_ONLY
    notes: list[str] = field(default_factory=list)
    complete: bool = True
    if TYPE_CHECKING:   # the family's fields, after its own records
        findings: list[Finding]
        metrics: JsonObject

    def kinds(self) -> dict[str, int]:
        """How many findings of each kind (all of them, listed or not)."""
        return dict(self.metrics.get("finding_counts", {}))

    def hazards(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "hazard"]

    def to_json(self) -> dict[str, object]:
        """``findings.json``: the analysis as a document, named by its family."""
        return {"format": f"conform-{self.family}-analysis/1", "path": self.path,
                "family": self.family, "variant": self.variant, "detected": self.detected,
                "metrics": self.metrics, "findings": [asdict(f) for f in self.findings],
                "notes": self.notes}

    def findings_lines(self, most: int | None = None) -> list[str]:
        """The end of ``summary_lines``: the count of each kind, the serious findings (at
        most ``most``) and the notes."""
        counts = self.metrics.get("finding_counts", {})
        out = ["findings: " + (", ".join(f"{k} {n}" for k, n in counts.items()) or "none")]
        out += [f"  {f.t:10.4f}s {f.severity:7} {f.kind}: {f.message}" for f in self.findings
                if f.severity in SERIOUS][:most]
        return out + [f"note: {note}" for note in self.notes]

    def summary_markdown(self, head: Sequence[str], tail: Sequence[str] = ()) -> str:
        """``summary.md``: ``head`` (title, family), every metric, every finding, ``tail``."""
        lines = [*head, ""]
        lines += [f"- {k}: {v}" for k, v in self.metrics.items() if k != "finding_counts"]
        lines += ["", "## Findings", ""]
        lines += [f"- {f.t:.4f} s {f.severity} {f.kind}: {f.message} [{f.clause}]"
                  for f in self.findings] or ["none"]
        return "\n".join([*lines, *tail]) + "\n"

    def report_files(self, directory: str, summary: Callable[[], str],
                     html: Callable[[], str]) -> dict[str, Path]:
        """``findings.json``, ``summary.md`` and ``index.html`` in ``directory`` (the last two
        made by the family), as ``write_report`` returns them."""
        from conform.report.render import write_files

        d = write_files(directory, {
            "findings.json": lambda: json.dumps(self.to_json(), indent=1, default=str),
            "summary.md": summary, "index.html": html})
        return {"json": d / "findings.json", "md": d / "summary.md", "html": d / "index.html"}

    def fleet_row_of(self, exchanges: int, exchanges_per_s: float,
                     rtt_ms: Sequence[float | None], **own: object) -> dict[str, object]:
        """A fleet row (``fleet_row``): the engine's columns from the metrics, ``exchanges``
        and their rate, the p50/p95/p99/max round trip in ms, then the family's ``own``."""
        p50, p95, p99, top = rtt_ms
        return {"family": self.family, "state": "clean" if self.complete else "damaged",
                "duration_s": self.metrics["duration_s"], "exchanges": exchanges,
                "exchanges_per_s": exchanges_per_s, "hazards": self.metrics["hazards"],
                "findings": self.kinds(), "rtt_p50_ms": p50, "rtt_p95_ms": p95,
                "rtt_p99_ms": p99, "rtt_max_ms": top, **own}


    def add_notes(self, notes: Sequence[str], status: ReadStatus) -> None:
        """``notes`` from reading the capture, then whether the file was whole (``status``:
        conform.analysis.rawread's ``complete`` and ``problem``)."""
        self.notes += notes
        if not status.complete:
            self.complete = False
            self.notes.append(f"capture incomplete: {status.problem}")


def capture_variant(metadata: JsonObject, asked: str | None, known: Collection[str],
                    default: str, title: str) -> tuple[str, list[str]]:
    """The variant to analyse a capture as: the one ``asked`` for, else the one its session
    metadata names, else ``default``; a name ``known`` lacks falls back to ``default`` with a
    note (``title``: the family, as the note names it)."""
    vid = asked or str(metadata.get("conform.session", {}).get("variant", "") or "")
    if vid in known:
        return vid, []
    note = f"variant {vid!r} is not a {title} variant; analysed as {default}"
    return default, [note] if vid else []


def per_s(n: float, seconds: float) -> float:
    """``n`` per second over ``seconds`` (0 over no time)."""
    return n / seconds if seconds > 0 else 0.0


def findings_table(findings: Sequence[Finding]) -> Any:
    """The findings as an Arrow table (``findings.parquet``): time, kind, severity, message
    and clause."""
    import pyarrow as pa

    return pa.table({"t": [f.t for f in findings], "kind": [f.kind for f in findings],
                     "severity": [f.severity for f in findings],
                     "message": [f.message for f in findings],
                     "clause": [f.clause for f in findings]})


def save_tables(directory: str | Path, tables: Mapping[str, Any]) -> dict[str, Path]:
    """Each Arrow table as ``<name>.parquet`` in ``directory`` (created if needed); a folder
    that cannot be written is a one-line ``UserError``."""
    import pyarrow.parquet as pq

    from conform.errors import UserError

    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
        for name, table in tables.items():
            pq.write_table(table, d / f"{name}.parquet")
    except OSError as exc:
        raise UserError(f"{d}: cannot write the tables: {exc.strerror or exc}") from None
    return {name: d / f"{name}.parquet" for name in tables}
