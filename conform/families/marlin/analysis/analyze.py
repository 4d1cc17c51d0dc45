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

import re
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from functools import reduce
from operator import xor
from pathlib import Path
from typing import Any

MAX_LISTED = 50
DEFAULT_VARIANT = "marlin-2.1"
STORM_WINDOW = 0.5         # s: resend requests this close together belong to one storm
STORM_MIN = 3              # requests that make a storm
RESEND_TIMEOUT = 1.0       # s without an ok before a sender's repeat counts as a timeout resend
Chunk = tuple[float, bytes]
CLAUSE_Q = "queue.cpp get_serial_commands / gcode_line_error"


@dataclass
class Finding:
    kind: str
    t: float
    severity: str         # info | warning | error | hazard
    message: str
    clause: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(slots=True)
class HostLine:
    t: float
    n: int | None
    text: str              # the command (after N, before *)
    raw_size: int
    checksum_ok: bool | None
    epoch: int = 0
    accepted: bool = False
    t_ok: float | None = None
    repeat: bool = False   # the same number sent again (a resend)


@dataclass
class MarlinAnalysis:
    path: str
    variant: str
    detected: str
    lines: list[HostLine]
    findings: list[Finding]
    metrics: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    family: str = "marlin"
    complete: bool = True

    def kinds(self) -> dict[str, int]:
        return dict(self.metrics.get("finding_counts", {}))

    def to_json(self) -> dict[str, Any]:
        return {"format": "conform-marlin-analysis/1", "path": self.path, "family": self.family,
                "variant": self.variant, "detected": self.detected, "metrics": self.metrics,
                "findings": [asdict(f) for f in self.findings], "notes": self.notes}

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
        counts = m.get("finding_counts", {})
        out.append("findings: " + (", ".join(f"{k} {n}" for k, n in counts.items()) or "none"))
        out += [f"  {f.t:10.4f}s {f.severity:7} {f.kind}: {f.message}" for f in self.findings
                if f.severity in ("hazard", "error")][:MAX_LISTED]
        return out + [f"note: {note}" for note in self.notes]

    def write_report(self, directory: str) -> dict[str, Path]:
        from conform.families.marlin.analysis.report import write_report

        return write_report(self, directory)

    def write_tables(self, directory: str) -> dict[str, Path]:
        from conform.families.marlin.analysis.report import write_parquet

        return write_parquet(self, directory)

    def fleet_row(self) -> dict[str, Any]:
        m = self.metrics
        motion = sum(1 for x in self.lines if x.accepted and x.text[:2] in ("G0", "G1", "G2",
                                                                            "G3"))
        d = m["duration_s"]
        return {"family": self.family, "state": "clean" if self.complete else "damaged",
                "duration_s": d, "exchanges": m["host_lines"], "vectors_accepted": motion,
                "exchanges_per_s": m["lines_per_s"], "vectors_per_s": motion / d if d > 0 else 0.0,
                "hazards": m["hazards"], "findings": dict(m.get("finding_counts", {})),
                "rtt_p50_ms": m["ok_p50_ms"], "rtt_p95_ms": m["ok_p95_ms"],
                "rtt_p99_ms": m["ok_p99_ms"], "rtt_max_ms": m["ok_max_ms"],
                "starvations": m["planner_empty"]}


def iter_lines(chunks: Iterable[tuple[float, bytes]]) -> Iterator[tuple[float, bytes]]:
    """Lines (ended by LF or CR, empty ones dropped) with the time of the chunk that ended
    them, one at a time."""
    rest = b""
    for t, data in chunks:
        buf = rest + data
        parts = buf.replace(b"\r", b"\n").split(b"\n")
        rest = parts.pop()
        for p in parts:
            if p:
                yield t, p


def timed_lines(chunks: Iterable[tuple[float, bytes]]) -> list[tuple[float, bytes]]:
    return list(iter_lines(chunks))


_NUMBERED = re.compile(rb"N(-?\d*)")
_SECOND_N = re.compile(rb"N(-?\d+)")


def _parse(t: float, raw: bytes) -> HostLine:
    """What queue.cpp sees of one host line: the comment cut at ';' (a checksum after it is
    gone), N and the checksum checked."""
    cut = raw.find(b";")
    body = (raw if cut < 0 else raw[:cut]).lstrip(b" ")
    star = body.rfind(b"*")
    text = body if star < 0 else body[:star]
    if body[:1] != b"N":
        return HostLine(t, None, text.decode("latin-1").strip(), len(raw), None)
    m = _NUMBERED.match(body)
    digits = m.group(1) if m else b""
    n = int(digits) if digits not in (b"", b"-") else 0
    if b"M110" in body:
        second = _SECOND_N.search(body, 4)
        if second:
            n = int(second.group(1))
    ok = False
    if star >= 0:
        tail = body[star + 1:].strip()
        ok = tail.isdigit() and int(tail) == reduce(xor, body[:star], 0)
    return HostLine(t, n, text[m.end() if m else 1:].decode("latin-1").strip(), len(raw), ok)


def _pct_ms(ordered: list[float], q: float) -> float | None:
    if not ordered:
        return None
    return round(ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000.0, 3)


def analyze_streams(host: list[Chunk], unit: list[Chunk], *, variant: str = DEFAULT_VARIANT,
                    path: str = "", detected: str = "", keepalive: float = 2.0,
                    planner_blocks: int = 15) -> MarlinAnalysis:
    hl = [_parse(t, raw) for t, raw in iter_lines(host)]
    ul = iter_lines(unit)
    findings: list[Finding] = []
    first_unit = next(ul, None)
    starts = [x.t for x in hl[:1]] + ([first_unit[0]] if first_unit else [])
    t0 = min(starts, default=0.0)
    last_n = 0
    epoch = 0
    sent_max = 0
    asked: int | None = None          # the number the last Resend: asked for
    pending: list[HostLine] = []      # accepted or unnumbered, waiting for their ok
    in_error = 0                      # ok lines that belong to an error triple
    resends: list[tuple[float, int]] = []
    oks = errors_cs = errors_ln = errors_nocs = 0
    busy: list[float] = []
    planner_free: list[int] = []
    latency: list[float] = []
    t_last = t0
    for t, kind, x, line in _merged(hl, first_unit, ul):
        t_last = t
        if kind == 1:
            x.epoch = epoch
            if x.n is None:
                x.accepted = True
                pending.append(x)
                continue
            if x.n <= sent_max and not x.text.startswith("M110"):
                x.repeat = True
                if asked is None or x.n < asked:
                    findings.append(Finding("repeat-unasked", t - t0, "warning",
                                            f"N{x.n} sent again without a Resend: asking for it "
                                            "(the unit ignores the last two numbers silently)",
                                            CLAUSE_Q))
            elif x.n > sent_max + 1 and sent_max and not x.text.startswith("M110"):
                findings.append(Finding("number-gap", t - t0, "error",
                                        f"N{x.n} sent after N{sent_max}: numbers skipped",
                                        CLAUSE_Q))
            sent_max = max(sent_max, x.n) if not x.text.startswith("M110") else x.n
            m110 = x.text.startswith("M110") or " M110" in x.text
            if (x.n == last_n + 1 or m110) and x.checksum_ok:
                last_n = x.n
                x.accepted = True
                pending.append(x)
                if m110:
                    epoch += 1
            continue
        if line.startswith("ok"):
            oks += 1
            if in_error:
                in_error -= 1
                continue
            if " P" in line and " B" in line:
                try:
                    planner_free.append(int(line.split(" P", 1)[1].split()[0]))
                except ValueError:
                    pass
            if pending:
                x = pending.pop(0)
                x.t_ok = t
                latency.append(t - x.t)
        elif line.startswith("Error:"):
            if "Last Line:" in line:
                try:
                    last = int(line.rsplit("Last Line:", 1)[1])
                except ValueError:
                    continue
                if "checksum" in line:
                    errors_cs += 1
                elif "Line Number" in line:
                    errors_ln += 1
                else:
                    errors_nocs += 1
                for x in pending[:]:
                    if x.n is not None and x.n > last and x.t_ok is None:
                        x.accepted = False
                        pending.remove(x)
                last_n = last
                in_error += 1
            elif "halted" in line:
                findings.append(Finding("halted", t - t0, "error", "the unit halted (M112 or "
                                        "kill()): it answers nothing until reset",
                                        "MarlinCore.cpp kill()"))
        elif line.startswith("Resend:"):
            try:
                asked = int(line.split(":", 1)[1])
            except ValueError:
                continue
            resends.append((t, asked))
        elif line.startswith("echo:busy:"):
            busy.append(t)
        elif line == "start":
            epoch += 1
            last_n = sent_max = 0
            asked = None
            pending.clear()
            findings.append(Finding("reset", t - t0, "warning", "the unit restarted (start): "
                                    "line numbers begin again at 1, queued lines are lost",
                                    "MarlinCore.cpp setup()"))
    duration = t_last - t0
    findings += _storms(resends, hl, t0)
    twice_c, twice_p = _twice(hl, findings, t0)
    never_c, never_p = _never(hl, findings, t0)
    periods, busy_s = _busy(busy, keepalive)
    empty = sum(1 for p in planner_free if p >= planner_blocks)
    if periods:
        findings.append(Finding("busy", (busy[0] - t0), "info", f"{periods} busy periods, "
                                f"{busy_s:.1f} s in all", "gcode.cpp host_keepalive"))
    numbered = sum(1 for x in hl if x.n is not None)
    latency.sort()
    counts: dict[str, int] = {}
    for f in findings:
        counts[f.kind] = counts.get(f.kind, 0) + 1
    metrics = {
        "host_lines": len(hl), "numbered": numbered, "accepted": sum(x.accepted for x in hl),
        "oks": oks, "duration_s": round(duration, 6),
        "lines_per_s": round(len(hl) / duration, 3) if duration > 0 else 0.0,
        "ok_p50_ms": _pct_ms(latency, 0.5), "ok_p95_ms": _pct_ms(latency, 0.95),
        "ok_p99_ms": _pct_ms(latency, 0.99), "ok_max_ms": _pct_ms(latency, 1.0),
        "resends": len(resends),
        "resend_ratio": round(len(resends) / numbered, 6) if numbered else 0.0,
        "storms": counts.get("resend-storm", 0), "checksum_errors": errors_cs,
        "line_number_errors": errors_ln, "no_checksum_errors": errors_nocs,
        "busy_periods": periods, "busy_s": round(busy_s, 3), "planner_empty": empty,
        "twice_confirmed": twice_c, "twice_possible": twice_p, "never_confirmed": never_c,
        "never_possible": never_p, "repeats": sum(x.repeat for x in hl),
        "hazards": twice_c + never_c, "finding_counts": counts,
    }
    return MarlinAnalysis(path, variant, detected, hl, findings, metrics)


def _merged(hl: list[HostLine], first: tuple[float, bytes] | None,
            rest: Iterator[tuple[float, bytes]]) -> Iterator[tuple[float, int, Any, str]]:
    """Both directions in time order, the unit's line first at the same time (a host answering
    it cannot have sent before it came): (t, 0, None, unit line) or (t, 1, host line, "")."""
    u = first
    i = 0
    n = len(hl)
    while i < n or u is not None:
        if u is not None and (i >= n or u[0] <= hl[i].t):
            yield u[0], 0, None, u[1].decode("latin-1")
            u = next(rest, None)
        else:
            yield hl[i].t, 1, hl[i], ""
            i += 1


def _storms(resends: list[tuple[float, int]], hl: list[HostLine], t0: float) -> list[Finding]:
    """Runs of Resend: requests (each within STORM_WINDOW of the last) in which the unit took
    fewer lines than it asked to be sent again: the link makes no progress."""
    from bisect import bisect_left, bisect_right

    taken_at = [x.t for x in hl if x.accepted and x.n is not None] if resends else []
    out = []
    i = 0
    while i < len(resends):
        j = i
        while j + 1 < len(resends) and resends[j + 1][0] - resends[j][0] <= STORM_WINDOW:
            j += 1
        taken = (bisect_right(taken_at, resends[j][0]) - bisect_left(taken_at, resends[i][0])
                 if j > i else 0)
        if j - i + 1 >= STORM_MIN and taken < j - i + 1:
            asked = [n for _, n in resends[i:j + 1]]
            out.append(Finding("resend-storm", resends[i][0] - t0, "error",
                               f"{j - i + 1} Resend: requests in {resends[j][0] - resends[i][0]:.2f}"
                               f" s (asked for N{min(asked)}..N{max(asked)}, most N"
                               f"{max(set(asked), key=asked.count)})", CLAUSE_Q,
                               {"start": resends[i][0] - t0, "end": resends[j][0] - t0,
                                "requests": j - i + 1, "asked": sorted(set(asked))[:MAX_LISTED]}))
        i = j + 1
    return out


def _twice(hl: list[HostLine], findings: list[Finding], t0: float) -> tuple[int, int]:
    seen: dict[tuple[int, str], HostLine] = {}
    confirmed = possible = 0
    prev: HostLine | None = None
    for x in hl:
        if not x.accepted or x.n is None:
            continue
        key = (x.n, x.text)
        first = seen.get(key)
        if first is not None and first.epoch != x.epoch and not x.text.startswith("M110"):
            sure = first.t_ok is not None
            confirmed += sure
            possible += not sure
            findings.append(Finding("ran-twice", x.t - t0, "hazard" if sure else "warning",
                                    f"N{x.n} {x.text!r} ran {'twice' if sure else 'possibly twice'}"
                                    f" (taken at {first.t - t0:.3f} s"
                                    f"{', answered ok' if sure else ', its ok never came'}, "
                                    f"again after the numbering began anew)", CLAUSE_Q,
                                    {"n": x.n, "confirmed": sure}))
        elif (prev is not None and prev.text == x.text and prev.n is not None
              and x.n == prev.n + 1 and (prev.t_ok is None or prev.t_ok > x.t)
              and x.t - prev.t >= RESEND_TIMEOUT):
            possible += 1
            findings.append(Finding("ran-twice", x.t - t0, "warning",
                                    f"N{x.n} repeats N{prev.n}'s {x.text!r} after "
                                    f"{x.t - prev.t:.1f} s without an ok: possibly run twice",
                                    CLAUSE_Q, {"n": x.n, "confirmed": False}))
        seen.setdefault(key, x)
        prev = x
    return confirmed, possible


def _never(hl: list[HostLine], findings: list[Finding], t0: float) -> tuple[int, int]:
    taken = {(x.n, x.text) for x in hl if x.accepted and x.n is not None}
    last_taken_t = max((x.t for x in hl if x.accepted), default=0.0)
    reported: set[tuple[int, str]] = set()
    confirmed = possible = 0
    for x in hl:
        if x.n is None or x.accepted or (x.n, x.text) in taken or (x.n, x.text) in reported:
            continue
        if x.text.startswith("M110"):
            continue
        reported.add((x.n, x.text))
        sure = x.t < last_taken_t
        confirmed += sure
        possible += not sure
        findings.append(Finding("never-ran", x.t - t0, "hazard" if sure else "warning",
                                f"N{x.n} {x.text!r} was sent but never taken"
                                + ("" if sure else " (the capture ends first)"), CLAUSE_Q,
                                {"n": x.n, "confirmed": sure}))
    return confirmed, possible


def _busy(times: list[float], interval: float) -> tuple[int, float]:
    periods = 0
    total = 0.0
    start = prev = None
    for t in times:
        if prev is None or t - prev > interval * 1.5:
            if start is not None:
                total += prev - start + interval
            periods += 1
            start = t
        prev = t
    if start is not None and prev is not None:
        total += prev - start + interval
    return periods, total


def analyze_capture(path: str, *, variant: str | None = None, detected: str = "",
                    **_ignored: Any) -> MarlinAnalysis:
    """Analyse a capture file of Marlin traffic."""
    from conform.analysis.stream import read_raw
    from conform.families.marlin.spec import load_marlin

    raw = read_raw(path)
    session = raw.metadata.get("conform.session", {})
    spec = load_marlin()
    vid = variant or str(session.get("variant", "") or "")
    notes = []
    if vid not in spec.variants:
        if vid:
            notes.append(f"variant {vid!r} is not a Marlin variant; analysed as {DEFAULT_VARIANT}")
        vid = DEFAULT_VARIANT
    v = spec.variant(vid)

    def chunks(d: Any) -> list[Chunk]:
        data = d.data.tobytes()
        return [(float(r), data[s:s + n]) for s, n, r in
                zip(d.start.tolist(), d.length.tolist(), d.t_read.tolist(), strict=True)]

    a = analyze_streams(chunks(raw.host), chunks(raw.unit), variant=vid, path=path,
                        detected=detected, keepalive=float(v.keepalive or 2),
                        planner_blocks=v.planner_blocks)
    a.notes += notes
    if not raw.status.complete:
        a.complete = False
        a.notes.append(f"capture incomplete: {raw.status.problem}")
    return a


