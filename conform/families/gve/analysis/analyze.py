"""The analyser's entry point: a capture file in, tables, metrics and findings out.

    a = analyze("run.mcap")
    a.exchanges            # pandas DataFrame, one row per command line
    a.frames("host")       # decoded lines of one direction
    a.findings             # list[Finding], sorted by time
    a.metrics              # dict: latency, throughput, queue, counts

Steps: read the raw chunks (``rawread``), choose the baud (the capture's claim, checked
against what the bytes show), cut and decode lines (``frames``), pair them into exchanges
(``exchanges``), time them, replay the queue (``queue``), detect findings (``findings``,
``positions``). Bad input is analysed as far as it goes and the problem becomes a finding.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from conform.analysis.rawread import RawCapture
from conform.analysis.stream import RawStream, ReadStats, read_raw
from conform.analysis.tables import ParquetStream
from conform.capture.session import escape_bytes
from conform.errors import UserError
from conform.families.gve.analysis import exchanges as exm
from conform.families.gve.analysis import frames as fr
from conform.families.gve.analysis.columns import TIMES, isin, packet_numbers, release_memory
from conform.families.gve.analysis.findings import (
    HAZARDS,
    Context,
    Finding,
    Findings,
    QueueFull,
    Shifted,
    protocol_findings,
    recovery_analysis,
)
from conform.families.gve.analysis.metrics import Metrics
from conform.families.gve.analysis.plots import PlotData
from conform.families.gve.analysis.positions import PositionCheck
from conform.families.gve.analysis.queue import QueueReplay, StreamReplay, supply_consumption, whatif

STANDARD_BAUDS = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)
DEFAULT_VARIANT = "gve64-v19"
MIN_BAUD, MAX_BAUD = 50, 100_000_000  # a claimed rate outside this is not a baud rate
Step = Callable[[str], None]


@dataclass
class Analysis:
    """What ``analyze`` found. ``findings``, ``metrics`` and ``series`` cover the whole
    capture always. The whole tables (``exchanges``, ``host``, ``unit``, the replay's
    ``queue``) are kept for captures of up to ``KEEP_ROWS`` command lines (``whole``); a
    longer one is streamed and has ``plot`` (bounded series for the report's plots) and
    ``tables`` (the Parquet files written as it streamed, when asked for) instead."""

    checksum_names: ClassVar[np.ndarray] = fr.CHECKSUM_NAMES  # the report's frames tables
    path: str
    raw: RawCapture
    variant: Any
    dialect: Any
    baud: float | None
    host: fr.DecodedLines | None
    unit: fr.DecodedLines | None
    exchanges: pd.DataFrame | None
    unsolicited: np.ndarray
    findings: list[Finding]
    metrics: dict[str, Any]
    series: pd.DataFrame
    queue: QueueReplay | None
    t0: float
    notes: list[str] = field(default_factory=list)
    time_range: tuple[float, float] | None = None  # plots over time: seconds from the start
    plot: PlotData | None = None
    tables: dict[str, Any] = field(default_factory=dict)

    def code_meaning(self, code: Any) -> str:
        """What an answer code of the report's code table means (GVE64 §13.7: bit 3 INTA,
        bits 2..0 the error); -1 is the analyser's own: no code could be read."""
        try:
            n = int(code)
        except (TypeError, ValueError):
            return ""
        if n < 0:
            return "no code could be read: a garbled answer, or one missing its fields"
        from conform.families.gve.spec import load_spec

        err = load_spec().errors.get(n & 7)
        text = err.meaning if err is not None else "not in the tables"
        return text + ("; INTA set (an input interrupt is pending)" if n & 8 else "")

    @property
    def whole(self) -> bool:
        return self.exchanges is not None

    def _need_whole(self) -> None:
        if not self.whole:
            raise UserError(f"{self.path}: more than {KEEP_ROWS} command lines: the tables "
                            "were streamed, not kept (write them with --parquet)")

    def frames(self, direction: str, lo: int = 0, hi: int | None = None) -> pd.DataFrame:
        """The decoded lines ``lo:hi`` of one direction as a DataFrame (text escaped)."""
        self._need_whole()
        assert self.exchanges is not None
        d = self.host if direction == "host" else self.unit
        assert d is not None
        sl = slice(lo, len(d) if hi is None else hi)
        df = frames_frame(d, self.t0, sl)
        if direction == "host":
            for k in PACKET_COLUMNS:
                df[k] = self.exchanges[k].to_numpy()[sl]
        return df

    def chunks(self, direction: str) -> pd.DataFrame:
        """The raw chunks of one direction as read: offsets, lengths, times (from t0);
        read again from the file (the analysis does not keep them)."""
        raw = read_raw(self.path) if self.raw.released else self.raw
        d = raw.direction(direction)
        return pd.DataFrame({"direction": direction, "start": d.start, "length": d.length,
                             "offset": d.offset, "t_read": d.t_read - self.t0,
                             "t_first": d.t_first - self.t0, "file_order": d.order})

    def host_text(self, i: int) -> str:
        self._need_whole()
        assert self.host is not None
        return escape_bytes(self.host.raw(i))

    def unit_text(self, i: int) -> str:
        self._need_whole()
        assert self.unit is not None
        return escape_bytes(self.unit.raw(i))

    def hazards(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "hazard"]

    def kinds(self) -> dict[str, int]:
        return dict(self.metrics.get("finding_counts", {}))

    # what the engine asks of any family's analysis (conform.families.AnalysisResult)

    def summary_lines(self) -> list[str]:
        from conform.families.gve.analysis.output import summary_lines

        return summary_lines(self)

    def plots(self) -> dict[str, str]:
        from conform.families.gve.analysis.plots import gve_plots

        return gve_plots(self)

    def write_report(self, directory: str | os.PathLike[str]) -> dict[str, Any]:
        from conform.families.gve.analysis.output import write_report

        return write_report(self, directory)

    def write_tables(self, directory: str | os.PathLike[str], row_group: int | None = None
                     ) -> dict[str, Any]:
        from conform.families.gve.analysis.output import write_tables

        return write_tables(self, directory, row_group)

    def fleet_row(self) -> dict[str, Any]:
        from conform.families.gve.analysis.output import fleet_row

        return fleet_row(self)


def frames_frame(d: fr.DecodedLines, t0: float, sl: slice = slice(None), base: int = 0,
                 arrow_text: bool = False) -> pd.DataFrame:
    """Lines ``sl`` of ``d`` as a table; ``base``: the capture's number of ``d``'s line 0;
    ``arrow_text``: the text as an Arrow column (for Parquet: no Python string per line)."""
    from conform.analysis.tables import escaped

    lo, hi, _ = sl.indices(len(d))
    raw = d.lines.bodies.slice(lo, max(hi - lo, 0))
    text = pd.arrays.ArrowExtensionArray(escaped(raw)) if arrow_text else [
        escape_bytes(b) for b in raw.to_pylist()]
    return pd.DataFrame({
        "direction": d.direction,
        "line": np.arange(lo, max(hi, lo)) + base,
        "offset": d.lines.start[sl],
        "length": (d.lines.end - d.lines.start + d.lines.term)[sl],
        "t_first": d.t_first[sl] - t0,
        "t_last": d.t_last[sl] - t0,
        "kind": d.kind[sl],
        "name": d.name[sl],
        "code": d.code[sl],
        "inta": d.inta[sl],
        "checksum_status": fr.CHECKSUM_NAMES[d.checksum[sl].astype(np.int64)],
        "checksum_mode": d.checksum_mode[sl],
        "detail": d.detail[sl],
        "text": text,
    })


def _session_value(raw: RawCapture, key: str) -> str:
    return str(raw.metadata.get("conform.session", {}).get(key, "") or "")


def _dialect_from(spec: Any, text: str) -> Any:
    choices = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        k, _, v = part.partition("=")
        choices[k.strip()] = v.strip()
    return spec.dialect(choices)


PACKET_COLUMNS = ("packet", "packet_role")  # a host line's packet, in its frames table
CODED = frozenset({"packet_role"})  # its text columns written dictionary-encoded in Parquet
KEEP_ROWS = 200_000  # command lines up to which the whole tables are kept (``Analysis``)
FORCE_ROWS = 262_144  # rows waiting behind an undecided vector before it is judged anyway


def _round_baud(b: float) -> int:
    return min(STANDARD_BAUDS, key=lambda s: abs(np.log(s / b)))


class _Session:
    """One pass over a capture: windows of exchanges in, findings and summaries out.

    A window's rows join the rows carried from the last one (the table ``T``): from the
    last motion unit already judged, or the last command that expected an answer, whichever
    comes first. The detectors run over ``T`` and report only the rows it owns now: up to
    the last motion unit (recovery needs the unit after each one; the vectors of a packet
    wait for its ``*E``). Positions, the queue replay, the metrics and the Parquet tables
    take the owned rows in order.
    """

    def __init__(self, var: Any, baud: float | None, errors: dict[int, Any], keep_rows: int,
                 parquet: Any = None) -> None:
        self.var, self.baud, self.errors = var, baud, errors
        self.out = Findings()
        self.polls = QueueFull()
        self.positions = PositionCheck()
        self.replay = StreamReplay(var, keep=keep_rows > 0)
        self.metrics = Metrics()
        self.keep_rows = keep_rows
        self.keep = keep_rows > 0
        self.kept: dict[str, list[Any]] = {"ex": [], "host": [], "unit": [], "acc": []}
        self.unsolicited: list[np.ndarray] = []
        self.parquet = parquet
        if parquet is not None:
            self.replay.sink = lambda t, d: parquet.rows("queue_depth", _depth(t, d))
        self.T: pd.DataFrame | None = None
        self.Th: fr.DecodedLines | None = None
        self.Tu: fr.DecodedLines | None = None
        self.Tc = np.zeros(0, np.int64)
        self.tail_g = self.unit_tail_g = self.own_lo_g = 0
        self.rows = 0
        self.recovered = 0

    def window(self, w: exm.Window) -> None:
        for d, base in ((w.host, w.host_offset), (w.unit, w.unit_offset)):
            d.lines.start = d.lines.start + base  # stream offsets from here on
            d.lines.end = d.lines.end + base
        self.unsolicited.append(w.unsolicited)
        if self.T is None:
            self.T, self.Th, self.Tu, self.Tc = w.ex, w.host, w.unit, w.cmd_row
        else:
            assert self.Th is not None and self.Tu is not None
            self.T = pd.concat([self.T, w.ex], ignore_index=True)
            self.Th = fr.DecodedLines.join([self.Th, w.host])
            self.Tu = fr.DecodedLines.join([self.Tu, w.unit])
            self.Tc = np.concatenate([self.Tc, w.cmd_row])
        self.rows += len(w.ex)
        release_memory()  # freed heap goes back once it adds up, not onto the next peaks
        if self.keep and self.rows > self.keep_rows:
            self.keep = False
            self.kept = {k: [] for k in self.kept}
            self.replay.stop_keeping()
        self._round(w.final)

    def _round(self, final: bool) -> None:  # noqa: PLR0915 - the steps in order
        ex, th, tu = self.T, self.Th, self.Tu
        assert ex is not None and th is not None and tu is not None
        n = len(ex)
        ctx = Context(ex, lambda i: escape_bytes(th.raw(i)), lambda i: escape_bytes(tu.raw(i)),
                      self.baud, self.errors)
        ctx.base, ctx.unit_base = self.tail_g, self.unit_tail_g
        a = ex["answer_frame"].to_numpy()
        ctx.answer = np.where(a >= 0, a - self.unit_tail_g, -1)
        units = ctx.motion_units()["row"].to_numpy()
        own_lo = self.own_lo_g - self.tail_g
        if final:
            own_hi = n
        elif len(units) and units[-1] >= own_lo:
            own_hi = _group_start(ex, int(units[-1]))
            if n - own_hi > FORCE_ROWS:
                own_hi = n - 1
        else:
            own_hi = n - 1
        if not final:  # a packet not closed yet: its vectors wait for its *E
            packet = ex["packet"].to_numpy()
            inside = np.flatnonzero(packet >= 0)
            if len(inside) and ex["packet_role"].to_numpy()[inside[-1]] != "end":
                own_hi = min(own_hi, int(np.flatnonzero(packet == packet[inside[-1]])[0]))
        if own_hi <= own_lo and not final:
            return
        own_host = np.zeros(n, bool)
        own_host[own_lo:own_hi] = True
        lo_g, hi_g = self.own_lo_g, self.tail_g + own_hi
        cr = self.Tc
        own_unit = ((cr >= lo_g) & ((cr < hi_g) | final)) | ((cr < 0) & (lo_g == 0))
        view = Shifted(self.out, self.tail_g, self.unit_tail_g, own_host, own_unit)
        protocol_findings(ctx, th, tu, np.flatnonzero(cr < 0), view)
        decide = (units >= own_lo) & (units < own_hi)
        rec = recovery_analysis(ctx, view, decide, self.polls)
        self.positions.feed(ctx, tu, rec, self.out, own_lo, own_hi, self.tail_g)
        acc = accepted_vectors(ex, rec["recovered"])
        rows = ex.iloc[own_lo:own_hi]
        acc_own = acc[own_lo:own_hi]
        ou = np.flatnonzero(own_unit)
        u_lo, u_hi = (int(ou[0]), int(ou[-1]) + 1) if len(ou) else (0, 0)
        hsub, usub = th.take(own_lo, own_hi), tu.take(u_lo, u_hi)
        if self.parquet is not None:
            self.parquet.write(rows, hsub, usub, self.unit_tail_g + u_lo, frames_frame,
                               {k: rows[k].to_numpy() for k in PACKET_COLUMNS})
        self.replay.feed(ex, acc, th.result, own_lo, own_hi, self.tail_g)
        self.metrics.feed_rows(rows, acc_own)
        self.metrics.feed_lines(hsub)
        self.metrics.feed_lines(usub)
        if self.keep:
            self.kept["ex"].append(rows)
            self.kept["host"].append(hsub)
            self.kept["unit"].append(usub)
            self.kept["acc"].append(acc_own)
        self.own_lo_g = hi_g
        if final:
            self.T = self.Th = self.Tu = None
            return
        # carried: from the last row owned, or the last command expecting an answer
        exp = np.flatnonzero(isin(ctx.status[:own_hi], ("answered", "unanswered")))
        k = max(0, min(own_hi - 1, int(exp[-1]) if len(exp) else own_hi - 1))
        keep_u = int(np.searchsorted(cr, self.tail_g + k, side="left"))
        self.T = ex.iloc[k:].reset_index(drop=True)
        self.Th = th.take(k, n, compact=True)
        self.Tu = tu.take(keep_u, len(tu), compact=True)
        self.Tc = cr[keep_u:]
        self.tail_g += k
        self.unit_tail_g += keep_u

    def finish(self) -> None:
        self.replay.finish()


def _group_start(ex: pd.DataFrame, r: int) -> int:
    """The first row of the motion unit ending at ``r`` (a packet's ``*S``)."""
    if ex["packet_role"].to_numpy()[r] != "end":
        return r
    packet = ex["packet"].to_numpy()
    return int(np.flatnonzero(packet == packet[r])[0])


@dataclass
class _Pass:
    session: _Session
    raw: RawCapture
    stats: dict[str, ReadStats]
    windows: int


def _run_pass(path: str | os.PathLike[str], var: Any, dia: Any, baud: float, trust: bool,
              host_exact: bool, errors: dict[int, Any], keep: int, parquet: Any,
              progress: Any, reads_per_part: int | None, window_lines: int | None,
              first: tuple[RawStream, Any] | None = None) -> _Pass:
    """Read, decode, pair and judge the capture once, timed at ``baud``."""
    rs, parts = first if first is not None else (None, None)
    if rs is None:
        rs = RawStream(path, progress, reads_per_part)
        parts = rs.parts()
    st = exm.ExchangeStream(var, dia, _parser(var, dia), baud, trust, host_exact,
                            window_lines or exm.WINDOW_LINES)
    session = _Session(var, baud, errors, keep, parquet)
    stats = {"host": ReadStats("host"), "unit": ReadStats("unit")}
    count = 0
    for part in parts:
        stats[part.name].feed(part)
        st.feed(part)
        for w in st.windows():
            session.window(w)
            count += 1
    st.end()
    for w in st.windows():
        session.window(w)
        count += 1
    session.finish()
    return _Pass(session, rs.capture(), stats, count)


def analyze(path: str | os.PathLike[str], *, variant: str | None = None,
            baud: float | None = None, dialect: str | None = None,
            progress: Callable[[int, int], None] | None = None, step: Step | None = None,
            whatif_replays: bool = True, parquet: str | os.PathLike[str] | ParquetStream | None = None,
            keep_rows: int | None = None, reads_per_part: int | None = None,
            window_lines: int | None = None) -> Analysis:
    """Analyse one capture file (see the module docstring).

    ``parquet``: a folder to write the tables into as they stream (``report.ParquetStream``);
    ``keep_rows``: keep the whole tables (``Analysis.exchanges`` …) up to this many command
    lines (``KEEP_ROWS``); ``reads_per_part`` and ``window_lines`` bound the raw reads taken
    at a time and the host lines decoded and paired at a time (the result never depends on
    them: tests make them tiny).
    """
    from conform.families.gve.spec import load_spec

    def say(name: str) -> None:
        release_memory()
        if step is not None:
            step(name)

    say("reading")
    rs = RawStream(path, progress, reads_per_part)
    parts = rs.parts()
    head = next(parts, None)  # the session metadata comes before the first raw chunk
    raw = rs.capture()

    def chained() -> Any:
        if head is not None:
            yield head
        yield from parts

    spec = load_spec()
    notes: list[str] = []
    vid = variant or _session_value(raw, "variant") or DEFAULT_VARIANT
    try:
        var = spec.variant(vid)
    except UserError:
        notes.append(f"variant {vid!r} unknown; decoded as {DEFAULT_VARIANT}")
        var = spec.variant(DEFAULT_VARIANT)
    if not (variant or _session_value(raw, "variant")):
        notes.append(f"the capture names no variant; decoded as {var.id}")
    dia = _dialect_from(spec, dialect or _session_value(raw, "dialect"))
    declared = baud
    source = "option"
    if declared is not None and not MIN_BAUD <= declared <= MAX_BAUD:
        raise UserError(f"baud {declared:g}: must be between {MIN_BAUD} and {MAX_BAUD}")
    if declared is None:
        text = _session_value(raw, "baud")
        try:
            declared = float(text) or None
            source = "capture"
        except ValueError:
            declared = None
        if declared is not None and not MIN_BAUD <= declared <= MAX_BAUD:
            notes.append(f"the capture's baud {text[:40]!r} is not a usable rate; ignored")
            declared = None
    if declared is None:
        declared = float(var.default_baud)
        source = "variant default"
        notes.append(f"the capture names no baud; assumed {int(declared)}")

    keep = KEEP_ROWS if keep_rows is None else keep_rows
    errors = dict(spec.errors)
    sink = _sink(parquet)
    say("decoding, pairing, findings")
    p = _run_pass(path, var, dia, declared, True, False, errors, keep, sink, progress,
                  reads_per_part, window_lines, (rs, chained()))
    raw = p.raw
    bounds = [b for b in (p.stats["host"].baud_bound(), p.stats["unit"].baud_bound())
              if b is not None]
    low = max(bounds) if bounds else None
    slope = p.session.metrics.slope_baud()
    used = declared
    est = None
    if low is not None and low > declared * 1.3:
        est = _round_baud(max(low, slope or 0))
    elif slope is not None and (slope < declared / 1.5 or slope > declared * 1.5) and baud is None:
        est = _round_baud(slope)
    if est is not None and est != declared:
        used = float(est)
        say("re-timing at the estimated baud")
        host_exact = p.stats["host"].reads > 0 and p.stats["host"].exact
        sink = _sink(parquet, sink)
        p = _run_pass(path, var, dia, used, False, host_exact, errors, keep, sink, None,
                      reads_per_part, window_lines)
    s = p.session
    t0 = s.metrics.start()
    out = s.out
    n_before = len(out.items)
    gaps = [g for g in (p.stats["host"].gap(), p.stats["unit"].gap()) if g is not None]
    _capture_findings(raw, gaps, out, t0, declared, used, source, low, slope)
    out.items[:] = out.items[n_before:] + out.items[:n_before]  # as first found
    s.polls.report(out, s.metrics.hb, s.metrics.t_cmd_hi - s.metrics.t_cmd_lo
                   if s.metrics.commands else float("nan"))
    pos = s.positions.finish(out)

    say("queue replay")
    whole = s.keep
    ex = host = unit = None
    accepted = np.zeros(0, bool)
    if whole:
        ex = pd.concat(s.kept["ex"], ignore_index=True) if s.kept["ex"] else None
        host = fr.DecodedLines.join(s.kept["host"]) if s.kept["host"] else None
        unit = fr.DecodedLines.join(s.kept["unit"]) if s.kept["unit"] else None
        accepted = np.concatenate(s.kept["acc"]) if s.kept["acc"] else np.zeros(0, bool)
    rep_stream = s.replay
    # kept: the streamed replay's whole arrays (the same completions, depth and notes as
    # ``replay`` over the whole table, control commands or not: tests/test_analysis_control)
    rep: QueueReplay | None = rep_stream.result() if whole else None
    whatif_rows: list[dict[str, Any]] = []
    if rep is not None and whole and whatif_replays and ex is not None:
        try:
            whatif_rows = whatif(ex, accepted, host.result, var, used, rep)
        except Exception as exc:  # noqa: BLE001
            notes.append(f"what-if replay failed: {type(exc).__name__}: {exc}")
    elif not whole and whatif_replays:
        r = rep_stream  # the scenarios from the summaries, without the simulated replays
        whatif_rows = r.inputs.rows(used, r.durations.median() if r.durations.n else np.nan,
                                    r.starved, r.end_max - r.push_min if r.completed else 0.0)
    if rep is not None:
        rep.whatif = whatif_rows
        notes.extend(rep.notes[:10])
        _starvation_findings(_events(rep), out)
    else:
        notes.extend(rep_stream.notes[:10])
        _starvation_findings(rep_stream, out)

    say("metrics")
    for link in raw.link_events:
        kind = str(link.get("kind", ""))
        if kind in ("disconnect", "reconnect") and link.get("side") == "host" \
                and _session_value(raw, "capture_method") == "proxy":
            # the proxy's own pty: the sender closed or reopened its port, nothing was lost
            notes.append(f"sender {'closed' if kind == 'disconnect' else 'reopened'} its port "
                         f"at {float(link.get('t', t0)) - t0:.3f} s")
            continue
        if kind in ("disconnect", "reconnect", "error"):
            out.add("reset" if kind == "reconnect" else "capture-damaged",
                    float(link.get("t", t0)), "warning",
                    f"link {kind} ({link.get('side', '')}): {link.get('detail', '')}",
                    cause=f"link-{kind}")
    metrics, series = s.metrics.compute(used, rep_stream)
    if rep is not None and rep_stream.control_row >= 0:
        metrics["queue"] = _queue_metrics(rep, t0)
        sc = supply_consumption(rep, np.linspace(t0, t0 + metrics["duration_s"],
                                                 len(series) + 1))
        series["supplied_per_s"] = sc["supplied_per_s"].to_numpy()
        series["consumed_per_s"] = sc["consumed_per_s"].to_numpy()
    else:
        metrics["queue"] = rep_stream.metrics(t0, whatif_rows)
    metrics["baud"] = {"declared": declared, "source": source, "used": used,
                       "lower_bound_from_reads": low, "from_answer_lengths": slope}
    metrics["positions"] = pos
    metrics["finding_counts"] = dict(sorted(out.counts.items()))
    metrics["hazards"] = sum(out.counts.get(k, 0) for k in HAZARDS)
    metrics["capture"] = {"complete": raw.status.complete, "problem": raw.status.problem,
                          "damaged_chunks": raw.status.damaged_chunks,
                          "bytes": raw.status.size, "topics": raw.topics,
                          "variant": var.id, "dialect_changes": dia.changed()}
    out.finish(t0)
    if sink is not None and rep is not None:
        sink.rows("queue_depth", _depth(rep.depth_t, rep.depth))
    tables = sink.finish(t0, series) if sink is not None else {}
    unsolicited = np.concatenate(s.unsolicited) if s.unsolicited else np.zeros(0, np.int64)
    plot = PlotData.of(s.metrics, rep_stream, t0) if not whole else None
    return Analysis(str(path), raw, var, dia, used, host, unit, ex, unsolicited,
                    out.sorted(), metrics, series, rep, t0, notes, plot=plot, tables=tables)


def _sink(parquet: Any, old: ParquetStream | None = None) -> ParquetStream | None:
    """A ``ParquetStream`` for a folder (or the one given), started afresh."""
    if old is not None:  # a second pass writes the tables again
        for w in old.writers.values():
            w.close()
        old.writers, old.t0 = {}, None
    sink = parquet if parquet is None or isinstance(parquet, ParquetStream) \
        else ParquetStream(parquet)
    if sink is not None:
        sink.coded |= CODED
        sink.times |= TIMES
    return sink


def _depth(t: np.ndarray, depth: np.ndarray) -> pd.DataFrame:
    """Rows of the ``queue_depth`` table: the replayed queue's depth from time ``t`` on."""
    return pd.DataFrame({"t": t, "depth": depth})


def _events(rep: QueueReplay) -> Any:
    """A whole replay's starvations in the shape ``_starvation_findings`` reads."""

    class _E:
        starvations = rep.starvations
        starved = len(rep.starvations)

    return _E


def _queue_metrics(rep: QueueReplay, t0: float) -> dict[str, Any]:
    """The queue metrics of a whole replay (the Python executor's)."""
    dur = rep.ends - rep.starts
    return {
        "capacity": rep.capacity,
        "vectors_replayed": rep.vectors,
        "vectors_completed": int(len(rep.ends)),
        "max_depth": int(rep.depth.max()) if len(rep.depth) else 0,
        "mean_depth": float(_time_mean(rep.depth_t, rep.depth)),
        "starvations": len(rep.starvations),
        "starved_s": float(sum(e["gap"] for e in rep.starvations)),
        "standstill_s": float(sum(e["stop"] for e in rep.starvations)),
        "median_vector_s": float(np.median(dur)) if len(dur) else None,
        "motion_end_s": float(rep.ends.max() - t0) if len(rep.ends) else None,
        "whatif": rep.whatif,
    }


def _time_mean(t: np.ndarray, v: np.ndarray) -> float:
    if len(t) < 2:
        return float(v[0]) if len(v) else 0.0
    dt = np.diff(t)
    total = dt.sum()
    return float((v[:-1] * dt).sum() / total) if total > 0 else float(v.mean())


def _parser(var: Any, dia: Any) -> Any:
    from conform.families.gve.protocol import CommandParser

    return CommandParser(var, dia)


def accepted_vectors(ex: pd.DataFrame, recovered: np.ndarray | None = None) -> np.ndarray:
    """Vectors the unit took: answered 0, or inside a packet whose answer counts them, or
    (``recovered``) uncertain ones that the sender checked with ``@``/``>`` and moved on."""
    name = ex["name"].to_numpy()
    is_vec = isin(name, ("C", "L")) & (ex["kind"].to_numpy() == "command")
    packet = packet_numbers(ex)
    ok = (ex["status"].to_numpy() == "answered") & (ex["code"].to_numpy() == 0)
    if recovered is not None:
        ok = ok | recovered
    acc = is_vec & (packet < 0) & ok
    role = ex["packet_role"].to_numpy()
    ends = np.flatnonzero(role == "end")
    if len(ends):
        members = np.flatnonzero(is_vec & (role == "member"))
        npk = int(packet.max()) + 1
        limit = np.zeros(npk, np.int64)  # members accepted per packet
        code = ex["code"].to_numpy()
        st = ex["status"].to_numpy()
        for r in ends.tolist():
            if st[r] == "answered" or (recovered is not None and recovered[r]):
                limit[packet[r]] = 1 << 30 if code[r] == 0 or (
                    recovered is not None and recovered[r]) else 0
        if len(members):
            pk = packet[members]
            first = np.searchsorted(pk, pk, side="left")
            rank = np.arange(len(members)) - first
            acc[members] = rank < limit[pk]
    return acc


def _capture_findings(raw: RawCapture, gaps: list[tuple[str, float, int]], out: Findings,
                      t0: float, declared: float, used: float, source: str,
                      low: float | None, slope: float | None) -> None:
    st = raw.status
    if not st.complete:
        out.add("capture-damaged", t0, "warning",
                f"the capture is incomplete ({st.problem}); analysed what is intact",
                problem=st.problem)
    for note in st.notes[:5]:
        out.add("capture-damaged", t0, "warning", note)
    for name, t, count in gaps:
        out.add("capture-damaged", t, "warning",
                f"{name} stream: {count} chunk(s) whose offset does not follow "
                "the previous one (bytes missing or repeated)", gaps=count)
    if used != declared:
        why = (f"bytes arrived faster than {int(declared)} baud allows (at least "
               f"{low:.0f} baud)" if low and low > declared * 1.3 else
               f"answer times grow with their length as at about {slope:.0f} baud")
        out.add("baud-mismatch", t0, "warning",
                f"the {source} says {int(declared)} baud but {why}; timed as {int(used)} baud",
                declared=declared, used=used)


def _starvation_findings(rep: Any, out: Findings) -> None:
    ev = rep.starvations

    def mk(i: int) -> tuple:
        e = ev[i]
        when = (f"arrived {e['gap'] * 1000:.1f} ms after the previous one ended"
                if e["gap"] > 0 else "arrived only while the previous one was braking")
        return (e["t"], f"the queue ran dry: the next vector {when}, too late for the "
                f"junction, so the motion braked to rest (standstill {e['stop'] * 1000:.1f} "
                "ms with the T pause) where it could have passed at the B speed",
                [f"host:{e['row']}"] if e["row"] >= 0 else [],
                {"gap_s": e["gap"], "standstill_s": e["stop"]})

    # a long replay keeps its first events and counts the rest: only those are listed
    out.many("starvation", np.arange(rep.starved), "warning", mk, limit=10)
