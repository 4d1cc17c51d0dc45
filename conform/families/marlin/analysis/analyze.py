"""Analysis of Marlin traffic: which numbered lines the unit accepted (replaying queue.cpp's
rules over what the host sent, kept in step by the unit's own ``Last Line:``), ok latency,
throughput, resends and resend storms, line-number gaps and repeats, checksum errors, busy
periods, planner starvation (ADVANCED_OK's P field), and lines run twice or never.

The core, :func:`analyze_streams`, takes the two directions as timed chunks (sans-I/O);
:func:`analyze_capture` reads them from a capture file.

What the unit accepted: a numbered line is taken when its number is the last one + 1 (or it
carries M110) and its checksum is right; a line the unit rejects is answered
``Error:... Last Line: L`` and ``Resend: L+1``, which also says that every line sent before it
with a number above L was not taken (gcode_line_error empties the receive buffer). A reset
(``start``) or an accepted M110 begins a new numbering: the same line (number and text) taken
again in a later numbering ran twice — **confirmed** when the unit had answered it ok the first
time, **possible** when its ok never came. A sender that sends the text of an unanswered line
again under the next number after a timeout makes a **possible** double too. A line never
taken is **confirmed** never run when the session went on past it, **possible** when the
capture ended first.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any

from conform.analysis.result import ResultBase, capture_variant, per_s
from conform.families.marlin.analysis.core import MAX_KEPT, MAX_LISTED, Analyser, merged
from conform.families.marlin.analysis.records import (
    CLAUSE_Q,
    Chunk,
    Finding,
    HostLine,
    iter_lines,
    parse_host,
)

__all__ = ["CLAUSE_Q", "Finding", "HostLine", "MarlinAnalysis", "analyze_capture",
           "analyze_streams", "iter_lines", "timed_lines"]
DEFAULT_VARIANT = "marlin-2.1"


@dataclass
class MarlinAnalysis(ResultBase):
    lines: list[HostLine]
    findings: list[Finding]
    metrics: dict[str, Any]
    motion: int = 0                     # motion lines taken (G0-G3)
    lines_kept: bool = False            # ``lines`` holds every host line
    tables: dict[str, Path] | None = None   # the tables written as the capture streamed
    plotted: Any = None                 # analysis/series.py Plotted: what the report draws

    def summary_lines(self) -> list[str]:
        m = self.metrics
        out = [f"{m['host_lines']} host lines ({m['numbered']} numbered), {m['accepted']} "
               f"accepted, {m['oks']} ok in {m['duration_s']:.3f} s ({m['lines_per_s']:.1f} "
               f"lines/s); ok latency p50 {m['ok_p50_ms']} ms, p95 {m['ok_p95_ms']} ms",
               f"resends {m['resends']} (ratio {m['resend_ratio']:.3f}), storms {m['storms']}, "
               f"checksum errors {m['checksum_errors']}, line-number errors "
               f"{m['line_number_errors']}, busy {m['busy_s']:.1f} s in {m['busy_periods']} "
               f"periods; ran twice: {m['twice_confirmed']} confirmed, {m['twice_possible']} "
               f"possible; never ran: {m['never_confirmed']} confirmed, {m['never_possible']} "
               "possible"]
        return out + self.findings_lines(MAX_LISTED)

    def write_report(self, directory: str) -> dict[str, Path]:
        from conform.families.marlin.analysis.report import write_report

        return write_report(self, directory)

    def write_tables(self, directory: str) -> dict[str, Path]:
        """The tables in ``directory``: those written as the capture streamed when they went
        there, else written from the lines kept, else the capture analysed again into it."""
        from conform.families.marlin.analysis.report import write_parquet

        if self.tables is None and not self.lines_kept and self.path:
            again = analyze_capture(self.path, variant=self.variant, detected=self.detected,
                                    parquet=directory)
            assert again.tables is not None
            return again.tables
        return write_parquet(self, directory)

    def fleet_row(self) -> dict[str, Any]:
        m = self.metrics
        return self.fleet_row_of(
            m["host_lines"], m["lines_per_s"],
            [m["ok_p50_ms"], m["ok_p95_ms"], m["ok_p99_ms"], m["ok_max_ms"]],
            vectors_accepted=self.motion, vectors_per_s=per_s(self.motion, m["duration_s"]),
            starvations=m["planner_empty"])

def timed_lines(chunks: Iterable[Chunk]) -> list[Chunk]:
    return list(iter_lines(chunks))


def analyze_streams(host: Iterable[Chunk], unit: Iterable[Chunk], *,
                    variant: str = DEFAULT_VARIANT, path: str = "", detected: str = "",
                    keepalive: float = 2.0, planner_blocks: int = 15, keep_lines: bool = False,
                    parquet: str | Path | None = None) -> MarlinAnalysis:
    """One pass over both directions (``core.Analyser``). ``keep_lines``: keep every host
    line in ``lines`` (a short session, as check-sender's); ``parquet``: write the lines
    table to that folder as the lines settle, and the findings table at the end."""
    from conform.families.marlin.analysis.report import LineTable

    hosts = (parse_host(t, raw) for t, raw in iter_lines(host))
    units = iter_lines(unit)
    first_h = next(hosts, None)
    first_u = next(units, None)
    t0 = min([x.t for x in (first_h,) if x is not None]
             + [u[0] for u in (first_u,) if u is not None], default=0.0)
    kept: list[HostLine] = []
    table = LineTable(Path(parquet), first_h.t if first_h else 0.0) if parquet else None

    def on_line(x: HostLine) -> None:
        if keep_lines:
            kept.append(x)
        if table is not None:
            table.add(x)

    core = Analyser(t0, keepalive, planner_blocks,
                    on_line if keep_lines or table is not None else None)

    def again(first: Any, rest: Iterator[Any]) -> Iterator[Any]:
        return chain([first], rest) if first is not None else rest

    t_last = t0
    try:
        for t, x, line in merged(again(first_h, hosts), again(first_u, units)):
            t_last = t
            if x is not None:
                core.host(x)
            else:
                core.unit(t, line)
        findings, metrics = core.finish(t_last)
    finally:
        if table is not None:
            table.close()
    a = MarlinAnalysis(path, "marlin", variant, detected, kept, findings, metrics)
    a.motion = core.motion
    a.plotted = core.plotted
    a.lines_kept = keep_lines
    if core.dropped:
        a.notes.append(f"{core.dropped} findings not listed (counted in finding_counts; "
                       f"the first {MAX_KEPT} of each group are listed)")
    if table is not None:
        a.tables = table.finish_findings(findings)
    return a


def analyze_capture(path: str, *, variant: str | None = None, detected: str = "",
                    keep_lines: bool = False, parquet: str | Path | None = None,
                    **_ignored: Any) -> MarlinAnalysis:
    """Analyse a capture file of Marlin traffic (``analyze_streams`` says what
    ``keep_lines`` and ``parquet`` do)."""
    from conform.analysis.stream import RawStream
    from conform.families.marlin.spec import load_marlin

    rs = RawStream(path)
    parts = rs.parts()
    head = next(parts, None)   # the session metadata comes before the first raw chunk
    spec = load_marlin()
    vid, notes = capture_variant(rs.capture().metadata, variant, spec.variants, DEFAULT_VARIANT,
                                 "Marlin")
    v = spec.variant(vid)
    waiting: dict[str, deque[Any]] = {"host": deque(), "unit": deque()}
    if head is not None:
        waiting[head.name].append(head)

    def chunks(name: str) -> Iterator[Chunk]:
        """One direction's reads in order, the file's parts taken as they come (the other
        direction's parts wait for its reader)."""
        while True:
            while waiting[name]:
                d = waiting[name].popleft()
                data = d.data.tobytes()
                for s, n, r in zip(d.start.tolist(), d.length.tolist(), d.t_read.tolist(),
                                   strict=True):
                    yield float(r), data[s:s + n]
            part = next(parts, None)
            if part is None:
                return
            waiting[part.name].append(part)

    a = analyze_streams(chunks("host"), chunks("unit"), variant=vid, path=path,
                        detected=detected, keepalive=float(v.keepalive or 2),
                        planner_blocks=v.planner_blocks, keep_lines=keep_lines, parquet=parquet)
    for _ in parts:            # the rest of the file (its status), if a direction ended first
        pass
    a.add_notes(notes, rs.capture().status)
    return a


