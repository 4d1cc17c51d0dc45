"""Analysis of grbl traffic: lines paired with their ok/error:N, realtime bytes out of band,
the streaming method, receive-buffer overflow hazards, errors, alarms, status polling and
planner starvation.

The core, :func:`analyze_streams`, takes the two directions as timed chunks (sans-I/O, testable
in-process); :func:`analyze_capture` reads them from a capture file. Pairing follows the
protocol (interface.md): every line the sender ends with LF or CR gets exactly one ``ok`` or
``error:N``, in order; realtime bytes never do and never occupy the receive buffer. The bytes
in flight are what a character-counting sender must keep within the receive buffer: the bytes
of every line sent and not yet answered (grbl's own streaming example counts the same). When
they could exceed the buffer, a byte may be lost on the hardware: a hazard.
"""

from __future__ import annotations

import re
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.analysis.result import (
    Finding,
    ResultBase,
    capture_variant,
    findings_table,
    per_s,
    save_tables,
)
from conform.families.grbl.protocol.codec import split_host, split_unit
from conform.families.grbl.spec.load import GrblSpec, load_grbl

MAX_LISTED = 50
DEFAULT_VARIANT = "grbl-1.1f"
Chunk = tuple[float, bytes]


@dataclass(slots=True)
class Exchange:
    line: int
    text: str
    size: int
    t_sent: float
    answer: str | None = None
    t_answer: float | None = None
    lines_in_flight: int = 0
    bytes_in_flight: int = 0
    t_gone: float | None = None     # unanswered, flushed from grbl's buffer by a reset
    after_realtime: bool = False    # an empty line right after a realtime byte ("?\n")


@dataclass
class GrblAnalysis(ResultBase):
    exchanges: list[Exchange]
    findings: list[Finding]
    metrics: dict[str, Any]
    realtime: list[tuple[float, int]] = field(default_factory=list)  # (t, byte), absolute t
    reports: list[tuple[float, str]] = field(default_factory=list)  # status reports (t, text)
    t0: float = 0.0  # the session's start (its first byte either way): findings' and plots' 0

    def findings_document(self) -> dict[str, Any]:
        """``conform analyze --json``: the document GVE's analysis prints (capture, variant,
        findings with kind and severity, metrics, notes; conform.analysis.report)."""
        return {"capture": self.path, "variant": self.variant,
                "findings": [f.to_dict() for f in self.findings],
                "metrics": self.metrics, "notes": self.notes}

    # what the engine asks of any family's analysis (conform.families.AnalysisResult)

    def summary_lines(self) -> list[str]:
        """What ``conform analyze`` prints: the session in a line, then findings and notes."""
        m = self.metrics
        out = [f"{m['lines']} lines, {m['answered']} answered ({m['ok']} ok, {m['errors']} "
               f"error) in {m['duration_s']:.3f} s; streaming {m['streaming_method']}, at most "
               f"{m['max_bytes_in_flight']} bytes in flight (receive buffer {m['rx_buffer']}); "
               f"{m['status_polls']} status polls ({m['poll_rate_hz']:.1f}/s)"]
        return out + self.findings_lines()

    def write_report(self, directory: str) -> dict[str, Path]:
        return write_report(self, directory)

    def write_tables(self, directory: str) -> dict[str, Path]:
        return write_parquet(self, directory)

    def fleet_row(self) -> dict[str, Any]:
        """This session's row of a fleet summary (conform.analysis.fleet): lines stand for
        exchanges, motion lines for vectors; the latency is line to ok/error."""
        m = self.metrics
        rtt = sorted(e.t_answer - e.t_sent for e in self.exchanges if e.t_answer is not None)
        motion = sum(1 for e in self.exchanges if e.answer == "ok" and is_motion(e.text))
        return self.fleet_row_of(
            m["lines"], m["lines_per_s"], [_pct_ms(rtt, q) for q in (0.50, 0.95, 0.99, 1.0)],
            vectors_accepted=motion, vectors_per_s=per_s(motion, m["duration_s"]),
            starvations=m.get("finding_counts", {}).get("planner-starved", 0))


REACTION_S = 0.1
"""Seconds a host needs to read an answer and act on it: a line it sends sooner after
``error:N`` arrived was decided before the error was read, not sent in spite of it."""


def _pct_ms(ordered: list[float], q: float) -> float | None:
    """The q-quantile of sorted seconds, in ms (nearest rank), or None without values."""
    if not ordered:
        return None
    return round(ordered[min(len(ordered) - 1, max(0, round(q * len(ordered)) - 1))] * 1000, 4)


class _Out:
    def __init__(self) -> None:
        self.items: list[Finding] = []
        self.counts: dict[str, int] = {}

    def add(self, kind: str, t: float, severity: str, message: str, clause: str = "",
            **extra: Any) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if self.counts[kind] <= MAX_LISTED:
            self.items.append(Finding(kind, round(t, 6), severity, message, clause, extra))


def _byte_times(chunks: list[tuple[float, float, bytes]]) -> tuple[bytes, Any]:
    """All bytes of a direction and each byte's arrival time (spread from first to last)."""
    import numpy as np

    chunks = [c for c in chunks if c[2]]
    if not chunks:
        return b"", np.zeros(0)
    n = np.array([len(c[2]) for c in chunks], np.int64)
    t_read = np.array([c[1] for c in chunks], float)
    t_first = np.array([c[0] for c in chunks], float)
    t_first = np.where(np.isnan(t_first), t_read, t_first)
    step = np.where((n > 1) & (t_read > t_first), (t_read - t_first) / np.maximum(n - 1, 1), 0.0)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    k = np.arange(int(n.sum())) - np.repeat(first, n)
    return b"".join(c[2] for c in chunks), np.repeat(t_first, n) + np.repeat(step, n) * k

def analyze_streams(host: list[Chunk] | list[tuple[float, float, bytes]],
                    unit: list[Chunk] | list[tuple[float, float, bytes]], *,
                    variant: str = DEFAULT_VARIANT, spec: GrblSpec | None = None,
                    path: str = "", detected: str = "") -> GrblAnalysis:
    """Analyse grbl traffic given as (t, bytes) or (t_first, t_read, bytes) chunks."""
    spec = spec or load_grbl()
    v = spec.variant(variant)
    hb, ht = _byte_times([c if len(c) == 3 else (c[0], c[0], c[1]) for c in host])
    ub, ut = _byte_times([c if len(c) == 3 else (c[0], c[0], c[1]) for c in unit])
    lines, realtime = split_host(hb, spec)
    ht, ut = ht.tolist(), ut.tolist()
    ulines, _rest = split_unit(ub, spec)
    out = _Out()
    t0 = min([*ht[:1], *ut[:1]], default=0.0)

    def rel(t: float) -> float:
        return t - t0

    # pair answers with lines, in order
    rt_at = {r.offset for r in realtime}
    exchanges = [Exchange(i, ln.data.decode("latin-1"), ln.size, ht[ln.end],
                          after_realtime=not ln.data and ln.end - 1 in rt_at)
                 for i, ln in enumerate(lines)]
    answers = [(ut[u.end], u) for u in ulines if u.kind in ("ok", "error", "banner")]
    k = 0
    flushed: list[Exchange] = []   # lines the last banner seemed to flush, not yet answered
    for t_ans, u in answers:
        if u.kind == "banner":
            # a reset empties grbl's buffers: what was sent before it is never answered
            flushed = []
            while k < len(exchanges) and exchanges[k].t_sent < t_ans:
                exchanges[k].t_gone = t_ans
                flushed.append(exchanges[k])
                k += 1
            continue
        if flushed and flushed[0].t_sent <= t_ans and (
                k >= len(exchanges) or exchanges[k].t_sent > t_ans + 1e-9):
            # an answer no later line can have: the banner was on its way (a slow link)
            # while the line went out, so grbl took the line after it started
            e = flushed.pop(0)
            e.t_gone, e.answer, e.t_answer = None, u.text, t_ans
            continue
        if k >= len(exchanges):
            out.add("unsolicited-answer", rel(t_ans), "warning",
                    f"{u.text!r} answers no line the sender wrote",
                    "interface.md §Grbl Response Messages")
            continue
        if exchanges[k].t_sent > t_ans + 1e-9:
            out.add("unsolicited-answer", rel(t_ans), "warning",
                    f"{u.text!r} came before line {k} ({exchanges[k].text!r}) was complete",
                    "interface.md §Grbl Response Messages")
            continue
        exchanges[k].answer, exchanges[k].t_answer = u.text, t_ans
        k += 1

    # bytes and lines in flight when each line was complete: everything sent so far minus
    # the lines answered strictly before it (vectorised: answers sorted by time)
    import numpy as np

    sizes = np.fromiter((e.size for e in exchanges), np.int64, len(exchanges))
    t_sent = np.fromiter((e.t_sent for e in exchanges), float, len(exchanges))
    done = [(e.t_answer if e.t_answer is not None else e.t_gone, e.size) for e in exchanges
            if e.t_answer is not None or e.t_gone is not None]
    done.sort()
    t_done = np.fromiter((d[0] for d in done), float, len(done))
    cum = np.concatenate([[0], np.cumsum([d[1] for d in done], dtype=np.int64)])
    j = np.searchsorted(t_done, t_sent, side="left")
    in_bytes = (np.cumsum(sizes) - cum[j]).tolist()
    in_lines = (np.arange(1, len(exchanges) + 1) - j).tolist()
    for e, b, n in zip(exchanges, in_bytes, in_lines, strict=True):
        e.bytes_in_flight, e.lines_in_flight = b, n

    # overflow hazards: episodes where what is in flight could exceed the receive buffer
    limit = v.rx_buffer
    episode: list[Exchange] = []
    for e in [*exchanges, None]:
        if e is not None and e.bytes_in_flight > limit:
            episode.append(e)
            continue
        if episode:
            worst = max(episode, key=lambda x: x.bytes_in_flight)
            out.add("rx-overflow-hazard", rel(episode[0].t_sent), "hazard",
                    f"{worst.bytes_in_flight} bytes in flight (receive buffer {limit}) from line "
                    f"{episode[0].line} {episode[0].text!r}; {len(episode)} lines sent over the "
                    "limit: grbl loses what does not fit",
                    v.cite.get("rx_buffer", ""), first_line=episode[0].line,
                    max_bytes=worst.bytes_in_flight, lines=len(episode))
            episode = []

    # errors, alarms, resets
    meaning = {n: c.name for n, c in spec.errors.items()}
    last_sent = exchanges[-1].t_sent if exchanges else 0.0
    for e in exchanges:
        if e.answer and e.answer.startswith("error:"):
            code = int(e.answer[6:])
            # lines go out in time order; one sent within REACTION_S of the error's arrival was
            # already on its way (the sender had not read the error yet)
            later = last_sent > (e.t_answer or e.t_sent) + REACTION_S
            goes_on = "the sender went on" if later else "the sender stopped after it"
            out.add("error-response", rel(e.t_answer or e.t_sent), "error",
                    f"line {e.line} {e.text!r}: error:{code} "
                    f"({meaning.get(code, 'unknown code')}); {goes_on}",
                    spec.errors[code].cite if code in spec.errors else "", code=code)
    for u in ulines:
        t = ut[u.end]
        if u.kind == "alarm":
            name = spec.alarms[u.code].name if u.code in spec.alarms else "unknown alarm"
            out.add("alarm", rel(t), "error", f"ALARM:{u.code} ({name})",
                    spec.alarms[u.code].cite if u.code in spec.alarms else "", code=u.code,
                    t_abs=t)
        elif u.kind == "banner" and rel(t) > 0.5:
            asked = any(0 <= t - ht[r.offset] < 0.5 for r in realtime if r.byte == 0x18)
            out.add("reset", rel(t), "info" if asked else "warning",
                    "soft reset by the sender (Ctrl-X)" if asked else
                    f"grbl restarted unasked: {u.text!r}", "interface.md §Start Up Message")
    unanswered = [e for e in exchanges if e.answer is None]
    if unanswered:
        flushed = sum(1 for e in unanswered if e.t_gone is not None)
        out.add("unanswered-lines", rel(unanswered[0].t_sent), "error",
                f"{len(unanswered)} lines got no ok/error, the first line {unanswered[0].line} "
                f"{unanswered[0].text!r} (lost bytes, a reset, or the capture ended)"
                + (f"; {flushed} of them were flushed by a reset" if flushed else ""),
                "interface.md §Grbl Response Messages", count=len(unanswered), flushed=flushed)

    # streaming method, from what the sender awaits: a send-response sender writes each job
    # line (g-code, a jog) only after an answer came since its previous one; a counting one
    # writes several back to back while the buffer has room. Empty lines (stream.py's wake-up,
    # a sync) and '$' queries a polling thread sends ($G, $#) take buffer room, counted above
    # for the hazard, but are not the job; their answers still count as answers (a sender that
    # takes a $G's ok for a job line's is still sending one line per answer). Realtime bytes
    # ('?') are no lines at all.
    max_lines = max((e.lines_in_flight for e in exchanges), default=0)
    max_bytes = max((e.bytes_in_flight for e in exchanges), default=0)
    over = sum(1 for e in exchanges if e.bytes_in_flight > limit)
    job_at = np.fromiter((i for i, e in enumerate(exchanges) if is_job_line(e.text)), np.int64)
    job = [exchanges[i] for i in job_at.tolist()]
    job_done = np.sort(np.fromiter((_done_at(e) for e in job), float, len(job)))
    job_sent = np.fromiter((e.t_sent for e in job), float, len(job))
    job_in_flight = np.arange(1, len(job) + 1) - np.searchsorted(job_done, job_sent, "left")
    max_job_lines = int(job_in_flight.max()) if len(job) else 0
    # a sender that counts waits for an answer before it sends more once the buffer is full:
    # beyond its first fill, it sends about one line per answer, in groups as the answers come
    # (a slow sender reads several oks at once and writes as many lines in one go). One that
    # does not count keeps sending while the buffer is full, whatever comes back. The content
    # decides, not the read timing: the job lines sent beyond one per answer while more bytes
    # were in flight than the buffer holds. (Bytes in flight alone would mislead: after a byte
    # is lost or a line goes out uncounted, every later count looks inflated; such a sender
    # still sends one line per answer.)
    n_done = np.searchsorted(t_done, t_sent, side="right")
    paced = int(np.count_nonzero(np.diff(n_done) > 0)) if len(exchanges) > 1 else 0
    share = paced / (len(exchanges) - 1) if len(exchanges) > 1 else 1.0
    beyond = _lines_beyond_answers(n_done[job_at])
    back_to_back = int(beyond.sum())
    # a proxy reads the two directions apart: on a loaded machine an ok may be stamped just
    # after the line its sender wrote on reading it, so a send-response line now and then
    # looks one ahead of its answer; never two, and a counting sender's first fill is more
    most_ahead = max((len(run) for run in "".join(map(str, beyond.tolist())).split("0")),
                     default=0)
    beyond_full = sum(1 for e, b in zip(job, beyond.tolist(), strict=True)
                      if b and e.bytes_in_flight > limit)
    # the steady state tells as well: once the planner is full and its answers pace the
    # sender, a counting one keeps a buffer's worth of job lines unanswered at every send, a
    # send-response one its line alone (two where an ok was stamped late). Its first fill
    # alone can look paced: on a loaded machine it may write the burst a line at a time, each
    # answered by an idle planner before the next. Two things inflate the depth, and are
    # allowed for: a sender may take a $G's ok for its job line's and go one line ahead for
    # good (grbl-streamer does), so each answer to a non-job line during the job is taken off;
    # a lost answer shifts the in-order pairing for every later line, so only when every line
    # was answered.
    keeps_ahead = False
    if len(job) and not unanswered:
        other_done = np.sort(np.fromiter(
            (d for e in exchanges if not is_job_line(e.text)
             and (d := _done_at(e)) > job_sent[0]), float))
        credit = np.searchsorted(other_done, job_sent, "left")
        keeps_ahead = float(np.median(job_in_flight - credit)) >= 3
    if not hb and not ub:
        method = "empty"
    elif not job:
        method = "none"
    elif not keeps_ahead and (back_to_back == 0
                              or (most_ahead <= 1 and back_to_back <= len(job) // 4)):
        method = "send-response"
    elif beyond_full <= len(job) // 4:
        method = "character-counting"
    else:
        method = "unbounded"
    if method == "unbounded":
        out.add("streaming-method", 0.0, "warning",
                f"lines were sent without waiting for answers and without keeping within the "
                f"{limit}-byte receive buffer (at most {max_bytes} bytes in flight)",
                v.cite.get("rx_buffer", ""))
    elif method == "character-counting" and over:
        out.add("streaming-method", 0.0, "warning",
                f"character counting that overshot the {limit}-byte receive buffer at {over} "
                f"lines (at most {max_bytes} bytes): something is sent outside the count, such "
                "as a polling thread's $G or a realtime byte followed by a newline",
                v.cite.get("rx_buffer", ""))

    # status polling and the reports
    polls = [ht[r.offset] for r in realtime if r.byte == 0x3F]
    reports = [(ut[u.end], u.text) for u in ulines if u.kind == "status"]
    intervals = [b - a for a, b in zip(polls, polls[1:], strict=False)]
    rate = (len(polls) - 1) / (polls[-1] - polls[0]) if len(polls) > 1 and polls[-1] > polls[0] else 0.0
    _starvation(exchanges, reports, v.planner_blocks, rel, out)

    duration = max([*ht[-1:], *ut[-1:]], default=t0) - t0
    rt_counts: dict[str, int] = {}
    for r in realtime:
        name = spec.realtime[r.byte].name if r.byte in spec.realtime else f"0x{r.byte:02X}"
        rt_counts[name] = rt_counts.get(name, 0) + 1
    findings = sorted(out.items, key=lambda f: f.t)
    metrics = {
        "family": "grbl", "variant": v.id, "lines": len(exchanges),
        "answered": len(exchanges) - len(unanswered),
        "ok": sum(1 for e in exchanges if e.answer == "ok"),
        "errors": sum(1 for e in exchanges if e.answer and e.answer.startswith("error:")),
        "alarms": out.counts.get("alarm", 0), "duration_s": duration,
        "lines_per_s": per_s(len(exchanges), duration),
        "streaming_method": method, "paced_share": round(share, 3),
        "max_lines_in_flight": max_lines, "max_job_lines_in_flight": max_job_lines,
        "job_lines_back_to_back": back_to_back,
        "max_bytes_in_flight": max_bytes, "rx_buffer": limit, "planner_blocks": v.planner_blocks,
        "realtime_bytes": rt_counts, "status_polls": len(polls), "status_reports": len(reports),
        "poll_rate_hz": rate,
        "poll_interval_median_s": statistics.median(intervals) if intervals else None,
        "finding_counts": dict(sorted(out.counts.items())),
        "hazards": out.counts.get("rx-overflow-hazard", 0),
    }
    return GrblAnalysis(path, "grbl", v.id, detected, exchanges, findings, metrics,
                        realtime=[(ht[r.offset], r.byte) for r in realtime], reports=reports,
                        t0=t0)


def is_job_line(text: str) -> bool:
    """A line the sender streams as part of a job (g-code, a jog), not an empty line or a
    ``$`` command/query (``$G``, ``$#``, ``$X``, ``$10=2``...)."""
    return bool(text) and (not text.startswith("$") or text.upper().startswith("$J="))


def _lines_beyond_answers(answered_before: Any) -> Any:
    """Which job lines went out beyond one per answer (1 for each such line, in send order):
    the lines sent after the same number of answers form a group, and a group may hold as many
    lines as answers came since the group before (the first line needs none); the lines past
    that are its last ones. A send-response sender stays at 0 even when two answers arrive in
    one read; a counting one fills the buffer in a burst, then keeps to about one per answer
    however the answers are grouped."""
    import numpy as np

    flags = np.zeros(len(answered_before), np.int64)
    if len(answered_before) < 2:
        return flags
    values, start, sizes = np.unique(answered_before, return_index=True, return_counts=True)
    gain = np.diff(values, prepend=values[0] - 1)
    for s, n, g in zip(start.tolist(), sizes.tolist(), gain.tolist(), strict=True):
        if n > g:
            flags[s + g:s + n] = 1
    return flags


def _done_at(e: Exchange) -> float:
    t = e.t_answer if e.t_answer is not None else e.t_gone
    return float("inf") if t is None else t


_AXIS_WORD = re.compile(r"[XYZ][-+.\d]")
_NOT_MOTION = re.compile(r"G0*(?:10|28\.1|30\.1|92(?:\.1)?|43\.1)(?![\d.])")


def is_motion(line: str) -> bool:
    """A line that moves the machine: a jog, or g-code with axis words (modal G0-G3 moves
    need no G word) that is not one of the axis commands that only store or set offsets
    (G10, G28.1, G30.1, G92, G43.1). ``G21`` is not ``G2``."""
    text = "".join(line.split()).upper()
    if text.startswith("$"):
        return text.startswith("$J=")
    return bool(_AXIS_WORD.search(text)) and not _NOT_MOTION.search(text)


def _starvation(exchanges: list[Exchange], reports: list[tuple[float, str]], blocks: int,
                rel: Any, out: _Out) -> None:
    """The planner ran dry mid-job: a report says Idle (or Bf: shows every block free while
    running) after the first motion line and before the sender's last line."""
    motion = [e for e in exchanges if is_motion(e.text)]
    if len(motion) < 2:
        return
    t_first, t_last = motion[0].t_answer or motion[0].t_sent, motion[-1].t_sent
    for t, text in reports:
        if not (t_first < t < t_last):
            continue
        fields = text.strip("<>").split("|")
        state = fields[0]
        bf = next((f[3:] for f in fields if f.startswith("Bf:")), None)
        free = int(bf.split(",")[0]) if bf else None
        if state == "Idle" or (state == "Run" and free is not None and free >= blocks):
            out.add("planner-starved", rel(t), "warning",
                    f"the planner ran dry mid-job ({text}): the sender did not keep it fed",
                    "interface.md §Buffer State; planner.h BLOCK_BUFFER_SIZE")


def analyze_capture(path: str, *, variant: str | None = None, detected: str = "",
                    **_ignored: Any) -> GrblAnalysis:
    """Analyse a capture file of grbl traffic."""
    from conform.analysis.stream import read_raw

    return analyze_raw(read_raw(path), path, variant=variant, detected=detected)


def analyze_raw(raw: Any, path: str, *, variant: str | None = None, detected: str = ""
                ) -> GrblAnalysis:
    """Analyse the raw directions of a capture already read (conform.analysis.rawread)."""
    spec = load_grbl()
    vid, notes = capture_variant(raw.metadata, variant, spec.variants, DEFAULT_VARIANT, "grbl")

    def chunks(d: Any) -> list[tuple[float, float, bytes]]:
        data = d.data.tobytes()
        return [(float(f), float(r), data[s:s + n]) for s, n, f, r in
                zip(d.start.tolist(), d.length.tolist(), d.t_first.tolist(), d.t_read.tolist(),
                    strict=True)]

    a = analyze_streams(chunks(raw.host), chunks(raw.unit), variant=vid, spec=spec, path=path,
                        detected=detected)
    a.add_notes(notes, raw.status)
    return a


def write_report(a: GrblAnalysis, directory: str) -> dict[str, Path]:
    """index.html (:mod:`.htmlreport`), findings.json and summary.md in ``directory``."""
    from conform.families.grbl.analysis.htmlreport import render_html

    head = [f"# grbl capture analysis: {a.path}", "", f"family: grbl ({a.detected})"]
    return a.report_files(directory, lambda: a.summary_markdown(head), lambda: render_html(a))


def write_parquet(a: GrblAnalysis, directory: str) -> dict[str, Path]:
    """exchanges.parquet (one row per line sent) and findings.parquet in ``directory``."""
    import pyarrow as pa

    ex = a.exchanges
    t0 = min((e.t_sent for e in ex), default=0.0)
    return save_tables(directory, {
        "exchanges": pa.table({
            "line": [e.line for e in ex], "text": [e.text for e in ex],
            "bytes": [e.size for e in ex], "t_sent": [e.t_sent - t0 for e in ex],
            "answer": [e.answer for e in ex],
            "t_answer": [None if e.t_answer is None else e.t_answer - t0 for e in ex],
            "lines_in_flight": [e.lines_in_flight for e in ex],
            "bytes_in_flight": [e.bytes_in_flight for e in ex]}),
        "findings": findings_table(a.findings),
    })
