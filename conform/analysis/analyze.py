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
from typing import Any

import numpy as np
import pandas as pd

from conform.analysis import exchanges as exm
from conform.analysis import frames as fr
from conform.analysis.columns import isin, release_memory
from conform.analysis.findings import Context, Finding, Findings, protocol_findings, recovery_analysis
from conform.analysis.positions import check_positions
from conform.analysis.queue import QueueReplay, replay, supply_consumption, whatif
from conform.analysis.rawread import RawCapture, read_raw
from conform.capture.session import escape_bytes
from conform.errors import UserError

STANDARD_BAUDS = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)
DEFAULT_VARIANT = "gve64-v19"
MIN_BAUD, MAX_BAUD = 50, 100_000_000  # a claimed rate outside this is not a baud rate
Step = Callable[[str], None]


@dataclass
class Analysis:
    path: str
    raw: RawCapture
    variant: Any
    dialect: Any
    baud: float | None
    host: fr.DecodedLines
    unit: fr.DecodedLines
    exchanges: pd.DataFrame
    unsolicited: np.ndarray
    findings: list[Finding]
    metrics: dict[str, Any]
    series: pd.DataFrame
    queue: QueueReplay | None
    t0: float
    notes: list[str] = field(default_factory=list)
    time_range: tuple[float, float] | None = None  # plots over time: seconds from the start

    def frames(self, direction: str, lo: int = 0, hi: int | None = None) -> pd.DataFrame:
        """The decoded lines ``lo:hi`` of one direction as a DataFrame (text escaped)."""
        d = self.host if direction == "host" else self.unit
        sl = slice(lo, len(d) if hi is None else hi)
        df = frames_frame(d, self.t0, sl)
        if direction == "host":
            df["packet"] = self.exchanges["packet"].to_numpy()[sl]
            df["packet_role"] = self.exchanges["packet_role"].to_numpy()[sl]
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
        return escape_bytes(self.host.raw(i))

    def unit_text(self, i: int) -> str:
        return escape_bytes(self.unit.raw(i))

    def hazards(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "hazard"]

    def kinds(self) -> dict[str, int]:
        return dict(self.metrics.get("finding_counts", {}))


def frames_frame(d: fr.DecodedLines, t0: float, sl: slice = slice(None)) -> pd.DataFrame:
    lo, hi, _ = sl.indices(len(d))
    bodies = d.lines.bodies.slice(lo, max(hi - lo, 0)).to_pylist()
    return pd.DataFrame({
        "direction": d.direction,
        "line": np.arange(lo, max(hi, lo)),
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
        "text": [escape_bytes(b) for b in bodies],
    })


def _session_value(raw: RawCapture, key: str) -> str:
    return str(raw.metadata.get("conform.session", {}).get(key, "") or "")


def _dialect_from(spec: Any, text: str) -> Any:
    choices = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        k, _, v = part.partition("=")
        choices[k.strip()] = v.strip()
    return spec.dialect(choices)


def _round_baud(b: float) -> int:
    return min(STANDARD_BAUDS, key=lambda s: abs(np.log(s / b)))


def baud_evidence(raw: RawCapture) -> float | None:
    """A lower bound on the true baud: bytes that arrived between two reads took that long."""
    best = []
    for d in (raw.host, raw.unit):
        if d.chunks < 3:
            continue
        dt = np.diff(d.t_read)
        n = d.length[1:]
        ok = (dt > 0) & (n >= 4)
        if ok.sum() >= 3:
            rates = 10.0 * n[ok] / dt[ok]
            best.append(float(np.quantile(rates, 0.98)))
    return max(best) if best else None


def slope_baud(ex: pd.DataFrame) -> float | None:
    """The baud from how answer time grows with answer length (10 bits a byte)."""
    ok = ex["status"].to_numpy() == "answered"
    if ok.sum() < 10:
        return None
    y = (ex["t_ans_last"].to_numpy() - ex["t_cmd_last"].to_numpy())[ok]
    x = ex["ans_bytes"].to_numpy()[ok]
    lens = np.unique(x)
    pts = []
    for L in lens.tolist():
        sel = y[x == L]
        if len(sel) >= 3:
            pts.append((L, float(np.quantile(sel, 0.05))))
    if len(pts) < 2 or pts[-1][0] - pts[0][0] < 3:
        return None
    px, py = np.array(pts).T
    slope = np.polyfit(px, py, 1)[0]
    if slope <= 0:
        return None
    return 10.0 / slope


def analyze(path: str | os.PathLike[str], *, variant: str | None = None,
            baud: float | None = None, dialect: str | None = None,
            progress: Callable[[int, int], None] | None = None, step: Step | None = None,
            whatif_replays: bool = True) -> Analysis:
    """Analyse one capture file (see the module docstring)."""
    from conform.families.gve.spec import load_spec

    def say(name: str) -> None:
        release_memory()
        if step is not None:
            step(name)

    say("reading")
    raw = read_raw(path, progress)
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

    say("decoding")
    mode = dia["A1"]
    hl = fr.split_lines(raw.host.data, mode)
    ul = fr.split_lines(raw.unit.data, mode)
    parser = _parser(var, dia)

    # a direction whose capture gives first-byte times equal to read times had no wire to
    # cross (the sender's pty of a proxy): those times stay right whatever the baud
    host_exact = bool(len(raw.host.t_first)) and bool(
        np.all(np.abs(raw.host.t_read - raw.host.t_first) < 1e-5))

    def timed(b: float, trust: bool) -> tuple:
        ht = fr.line_times(raw.host, hl, fr.chunk_first_times(raw.host, b, trust or host_exact))
        ut = fr.line_times(raw.unit, ul, fr.chunk_first_times(raw.unit, b, trust))
        return ht, ut

    ht, ut = timed(declared, True)
    ev_idx, ev_state = fr.mode_events(raw.host.data, hl)
    init = fr.infer_initial_mode(raw.host.data, hl, int(ev_idx[0]) if len(ev_idx) else -1)
    host_mode = _step(ev_idx, ev_state, np.arange(len(hl)), init)
    host = fr.decode_host(raw.host, hl, ht, var, dia, parser, host_mode)
    # answers: the mode after the last switching command the tap saw before them
    hr, ur = exm.merged_rank(host, _order_only(raw.unit, ul, ut))
    ev_rank = hr[ev_idx] if len(ev_idx) else np.zeros(0, np.int64)
    unit_mode = _step(ev_rank, ev_state, ur, init, strict=True)
    unit = fr.decode_unit(raw.unit, ul, ut, unit_mode)
    packets = exm.find_packets(host)
    # what the per-read tables tell is taken now, and they are let go before the exchange
    # table is built (the peak of the analysis); a baud that needs re-timing reads again
    low = baud_evidence(raw)
    gaps = _offset_gaps(raw)
    unit_data = raw.unit.data
    raw.release()
    release_memory()
    ex, unsolicited = exm.build_exchanges(host, unit, packets, declared, (hr, ur))
    del hr, ur

    # is the baud the capture claims possible?
    used = declared
    slope = slope_baud(ex)
    est = None
    if low is not None and low > declared * 1.3:
        est = _round_baud(max(low, slope or 0))
    elif slope is not None and (slope < declared / 1.5 or slope > declared * 1.5) and baud is None:
        est = _round_baud(slope)
    if est is not None and est != declared:
        used = float(est)
        raw = _reread(path, raw)
        ht, ut = timed(used, False)
        raw.release()
        host.t_first, host.t_last = ht
        unit.t_first, unit.t_last = ut
        ex, unsolicited = exm.build_exchanges(host, unit, packets, used)

    _check_answer_shapes(ex, unit, unit_data, var)
    del unit_data

    t_all = np.concatenate([host.t_first, unit.t_first])
    t_all = t_all[np.isfinite(t_all)]
    t0 = float(t_all.min()) if len(t_all) else 0.0
    t_end = float(np.concatenate([host.t_last, unit.t_last]).max()) if len(t_all) else 0.0
    out = Findings(t0)
    _capture_findings(raw, gaps, out, t0, declared, used, source, low, slope)

    say("findings")
    ctx = Context(ex, lambda i: escape_bytes(host.raw(i)), lambda i: escape_bytes(unit.raw(i)),
                  used, dict(spec.errors))
    protocol_findings(ctx, host, unit, unsolicited, out)
    rec = recovery_analysis(ctx, out)
    pos = check_positions(ctx, unit, rec, out)
    del ctx  # its motion units (a row per vector) are not needed by the replay

    say("queue replay")
    accepted = accepted_vectors(ex, rec["recovered"])
    rep: QueueReplay | None = None
    try:
        rep = replay(ex, accepted, host.result, var)
    except Exception as exc:  # noqa: BLE001 - a replay failure must not lose the analysis
        notes.append(f"queue replay failed: {type(exc).__name__}: {exc}")
    if rep is not None:
        _starvation_findings(rep, out)
        if whatif_replays:
            try:
                rep.whatif = whatif(ex, accepted, host.result, var, used, rep)
            except Exception as exc:  # noqa: BLE001
                notes.append(f"what-if replay failed: {type(exc).__name__}: {exc}")
        notes.extend(rep.notes[:10])

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
    metrics, series = compute_metrics(ex, host, unit, used, t0, t_end, rep, accepted)
    metrics["baud"] = {"declared": declared, "source": source, "used": used,
                       "lower_bound_from_reads": low, "from_answer_lengths": slope}
    metrics["positions"] = pos
    metrics["finding_counts"] = dict(sorted(out.counts.items()))
    metrics["hazards"] = sum(out.counts.get(k, 0) for k in ("blind-resend", "double-move",
                                                             "lost-vector"))
    metrics["capture"] = {"complete": raw.status.complete, "problem": raw.status.problem,
                          "damaged_chunks": raw.status.damaged_chunks,
                          "bytes": raw.status.size, "topics": raw.topics,
                          "variant": var.id, "dialect_changes": dia.changed()}
    return Analysis(str(path), raw, var, dia, used, host, unit, ex, unsolicited, out.sorted(),
                    metrics, series, rep, t0, notes)


_FREE_ANSWERS = {">", "?", "Q", "Y", "EFR", "EUR", "@", "J"}


def _check_answer_shapes(ex: pd.DataFrame, unit: fr.DecodedLines, data: np.ndarray,
                         var: Any) -> None:
    """An OK answer with the wrong number of fields for its command is garbled (§13.7)."""
    if len(unit) == 0:
        return
    commas = np.flatnonzero(data == fr.COMMA)  # a few per line, not a count per byte
    nf = (np.searchsorted(commas, unit.lines.end) - np.searchsorted(commas, unit.lines.start))
    nf = nf - ((unit.checksum != fr.CS_NONE) & (unit.checksum != fr.CS_MISSING))
    want = {cid: len(c.answer) for cid, c in var.commands.items() if cid not in _FREE_ANSWERS}
    want["*E"] = 1
    names = ex["name"].to_numpy()
    a = ex["answer_frame"].to_numpy()
    expect = pd.Series(names, dtype=object).map(want).fillna(-1).to_numpy(np.int64)
    ok = (a >= 0) & (ex["answer_kind"].to_numpy() == fr.ANSWER) & (expect >= 0)
    ok &= ex["code"].to_numpy() == 0
    bad = np.flatnonzero(ok & (nf[np.maximum(a, 0)] != expect))
    if len(bad) == 0:
        return
    for r in bad.tolist():
        u = int(a[r])
        unit.kind[u] = fr.GARBLED
        unit.detail[u] = f"{expect[r]} field(s) expected after a {names[r]} command"
    ex.loc[bad, "answer_kind"] = fr.GARBLED
    ex.loc[bad, "code"] = -1
    ex["uncertain"] = exm.uncertain_mask(ex)


def _parser(var: Any, dia: Any) -> Any:
    from conform.families.gve.protocol import CommandParser

    return CommandParser(var, dia)


def _order_only(d: Any, lines: fr.Lines, times: tuple) -> fr.DecodedLines:
    """Just enough of a DecodedLines to rank unit lines before they are decoded."""
    n = len(lines)
    z = np.zeros(n, object)
    return fr.DecodedLines("unit", lines, times[0], times[1], fr._term_order(d, lines), z, z,
                           np.zeros(n, np.int64), np.zeros(n, bool), np.zeros(n, np.int8),
                           np.zeros(n, bool), z, np.zeros((n, 4), np.int64))


def _step(ev_pos: np.ndarray, ev_state: np.ndarray, at: np.ndarray, init: bool,
          strict: bool = False) -> np.ndarray:
    """The state set by the last event strictly before each position."""
    if len(ev_pos) == 0:
        return np.full(len(at), init, bool)
    k = np.searchsorted(ev_pos, at, side="left") - 1
    return np.where(k >= 0, ev_state[np.maximum(k, 0)] == 1, init)


def accepted_vectors(ex: pd.DataFrame, recovered: np.ndarray | None = None) -> np.ndarray:
    """Vectors the unit took: answered 0, or inside a packet whose answer counts them, or
    (``recovered``) uncertain ones that the sender checked with ``@``/``>`` and moved on."""
    name = ex["name"].to_numpy()
    is_vec = isin(name, ("C", "L")) & (ex["kind"].to_numpy() == "command")
    packet = ex["packet"].to_numpy()
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


def _reread(path: str | os.PathLike[str], raw: RawCapture) -> RawCapture:
    """The bytes and per-read tables again (they were let go before pairing)."""
    again = read_raw(path)
    return RawCapture(raw.status, raw.metadata, again.host, again.unit, raw.link_events,
                      raw.topics)


def _offset_gaps(raw: RawCapture) -> list[tuple[str, float, int]]:
    """(direction, read time of the first, count) of the reads whose offset does not
    follow the previous one."""
    found = []
    for d in (raw.host, raw.unit):
        if d.chunks > 1:
            claimed = d.offset
            real = np.concatenate([[0], np.cumsum(d.length)[:-1]])
            gaps = np.flatnonzero((claimed >= 0) & (claimed != real))
            if len(gaps):
                found.append((d.name, float(d.t_read[gaps[0]]), int(len(gaps))))
    return found


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


def _starvation_findings(rep: QueueReplay, out: Findings) -> None:
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

    out.many("starvation", np.arange(len(ev)), "warning", mk, limit=10)


def compute_metrics(ex: pd.DataFrame, host: fr.DecodedLines, unit: fr.DecodedLines,
                    baud: float | None, t0: float, t_end: float, rep: QueueReplay | None,
                    accepted: np.ndarray) -> tuple[dict[str, Any], pd.DataFrame]:
    duration = max(t_end - t0, 1e-9)
    answered = ex["status"].to_numpy() == "answered"
    n_ex = int(answered.sum())
    n_vec = int(accepted.sum())
    hb = int(ex["cmd_bytes"].sum())
    ub = int((unit.lines.end - unit.lines.start + unit.lines.term).sum()) if len(unit) else 0
    m: dict[str, Any] = {
        "duration_s": duration,
        "frames": {"host": len(host), "unit": len(unit)},
        "exchanges": n_ex,
        "commands": len(ex),
        "vectors_accepted": n_vec,
        "exchanges_per_s": n_ex / duration,
        "vectors_per_s": n_vec / duration,
        "bytes": {"host": hb, "unit": ub},
        "bytes_per_s": {"host": hb / duration, "unit": ub / duration},
        "utilisation": {"host": hb * 10 / baud / duration if baud else None,
                        "unit": ub * 10 / baud / duration if baud else None},
        "status": {k: int(v) for k, v in ex["status"].value_counts().items()},
        "codes": {int(k): int(v) for k, v in ex.loc[answered, "code"].value_counts().items()},
    }
    lat = {}
    for col in ("rtt", "unit_time", "host_time", "wire_cmd", "wire_ans"):
        v = ex[col].to_numpy()[answered]
        v = v[np.isfinite(v)]
        if len(v):
            q = np.quantile(v, [0.5, 0.95, 0.99])
            lat[col] = {"median": float(q[0]), "p95": float(q[1]), "p99": float(q[2]),
                        "max": float(v.max()), "mean": float(v.mean())}
    m["latency"] = lat
    # the two columns it needs, not a copy of the answered rows of the whole table
    by = pd.Series(ex["rtt"].to_numpy()[answered]).groupby(
        ex["name"].to_numpy()[answered], dropna=True)
    m["latency_by_command"] = {str(k): {"n": int(g.size), "median": float(g.median()),
                                        "max": float(g.max())} for k, g in by}
    nb = int(min(600, max(10, duration)))
    edges = np.linspace(t0, t0 + duration, nb + 1)
    width = np.diff(edges)
    t_cmd = ex["t_cmd_first"].to_numpy()
    exc, _ = np.histogram(t_cmd[answered], bins=edges)
    vec_t = ex["t_cmd_last"].to_numpy()[accepted]
    vc, _ = np.histogram(vec_t, bins=edges)
    hbs, _ = np.histogram(host.t_last, bins=edges,
                          weights=host.lines.end - host.lines.start + host.lines.term)
    ubs, _ = np.histogram(unit.t_last, bins=edges,
                          weights=unit.lines.end - unit.lines.start + unit.lines.term)
    series = pd.DataFrame({
        "t": edges[:-1] - t0, "exchanges_per_s": exc / width, "vectors_per_s": vc / width,
        "host_bytes_per_s": hbs / width, "unit_bytes_per_s": ubs / width,
    })
    if baud:
        series["utilisation_host"] = series["host_bytes_per_s"] * 10 / baud
        series["utilisation_unit"] = series["unit_bytes_per_s"] * 10 / baud
    if rep is not None:
        sc = supply_consumption(rep, edges)
        series["supplied_per_s"] = sc["supplied_per_s"].to_numpy()
        series["consumed_per_s"] = sc["consumed_per_s"].to_numpy()
        dur = rep.ends - rep.starts
        m["queue"] = {
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
    return m, series


def _time_mean(t: np.ndarray, v: np.ndarray) -> float:
    if len(t) < 2:
        return float(v[0]) if len(v) else 0.0
    dt = np.diff(t)
    total = dt.sum()
    return float((v[:-1] * dt).sum() / total) if total > 0 else float(v.mean())
