"""grbl's side of ``conform diagnose``: its analysis as neutral facts, the host's bytes as
grbl's serial receive ring and line reader would have taken them, and the resume point.

Reception model (grbl 1.1f serial.c, protocol.c): the receive ring holds ``rx_buffer`` bytes
(RX_BUFFER_SIZE, config.h); the serial interrupt drops a byte that finds it full, silently
(serial.c ``serial_rx_buffer_tail`` check in the RX ISR) and takes realtime bytes out of band
so they never occupy it. The main loop takes bytes out of the ring as fast as it can until a
line ends (protocol.c ``protocol_main_loop``); it then executes the line, which blocks while
the planner is full, and answers ``ok``/``error:N`` after it (report.c). So from a line's end
until its answer the ring only fills; the answers in the capture are the clock of what the
unit took. Lines longer than the line buffer are answered error:11 (protocol.c
LINE_FLAG_OVERFLOW); spaces, ``( )`` and ``;`` comments are filtered, letters upper-cased.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from conform.diagnosis.facts import Event, Exchange, Facts, ParsedLine, ResumePoint
from conform.families.grbl.analysis.analyze import DEFAULT_VARIANT, analyze_raw, is_motion
from conform.families.grbl.protocol.codec import split_host, split_unit
from conform.families.grbl.protocol.gcode import GcodeError, Modal, parse, strip_line
from conform.families.grbl.spec.load import load_grbl

EVENT_OF = {  # analysis finding kind -> neutral event kind
    "rx-overflow-hazard": "overflow", "error-response": "error-answer", "alarm": "alarm",
    "planner-starved": "starved", "unsolicited-answer": "noise",
}
HOLD_STATES = ("Hold", "Door")
RUN_STATES = ("Run", "Jog", "Home")
END_WORD = ("M2", "M30")
SOFT_RESET = 0x18
STATE_ERRORS = (8, 9)   # refused for the machine's state ($ while moving, locked): not damage


def _chunks(d: Any) -> list[tuple[float, float, bytes]]:
    data = d.data.tobytes()
    return [(float(f) if f == f else float(r), float(r), data[s:s + n]) for s, n, f, r in
            zip(d.start.tolist(), d.length.tolist(), d.t_first.tolist(), d.t_read.tolist(),
                strict=True)]


def _t0(raw: Any) -> float:
    firsts = [c[0] for d in (raw.host, raw.unit) for c in _chunks(d)[:1]]
    return min(firsts, default=0.0)


def _variant(raw: Any, variant: str | None) -> str:
    spec = load_grbl()
    vid = variant or str(raw.metadata.get("conform.session", {}).get("variant", "") or "")
    return vid if vid in spec.variants else DEFAULT_VARIANT


def facts(raw: Any, path: str, *, variant: str | None = None, analysis: Any = None) -> Facts:
    vid = analysis.variant if analysis is not None else _variant(raw, variant)
    a = analysis if analysis is not None else analyze_raw(raw, path, variant=vid)
    t0 = _t0(raw)
    ex = [Exchange(e.line, e.text, e.t_sent - t0,
                   None if e.t_answer is None else e.t_answer - t0, e.answer,
                   None if e.answer is None else e.answer == "ok", is_motion(e.text),
                   e.bytes_in_flight) for e in a.exchanges]
    events = []
    for f in a.findings:
        kind = EVENT_OF.get(f.kind)
        if f.kind == "reset":
            kind = "reset"
        elif f.kind == "streaming-method":    # a misuse only where the buffer overflowed
            kind = "misuse" if "without" in f.message and \
                a.metrics.get("max_bytes_in_flight", 0) > a.metrics.get("rx_buffer", 1 << 30) \
                else None
        if kind is None:
            continue
        events.append(Event(f.t, kind, f.message, f.clause,
                            line=f.extra.get("first_line"),
                            extra={k: v for k, v in f.extra.items() if k in ("code", "lines")}))
    # holding with lines waiting: the unit will not take them until it is resumed
    for t_abs, text in a.reports:
        state = text.strip("<>").split("|")[0].split(":")[0]
        t = t_abs - t0
        waiting = any(e.t_sent <= t and (e.t_answer is None or e.t_answer > t) for e in ex)
        if state in HOLD_STATES and waiting:
            events.append(Event(t, "hold", f"the unit reports {text} with lines waiting "
                                "for their answer", "interface.md §Machine State"))
        elif state == "Idle":
            events.append(Event(t, "idle", f"the unit reports {text}",
                                "interface.md §Machine State (Idle: nothing to run)"))
        elif state in RUN_STATES:
            events.append(Event(t, "running", f"the unit reports {text}",
                                "interface.md §Machine State"))
    # the host's own soft reset: it stops the job and empties the planner (protocol.c
    # protocol_exec_rt_system, mc_reset)
    for t_abs, byte in a.realtime:
        if byte == SOFT_RESET:
            events.append(Event(t_abs - t0, "halt", "the host sent a soft reset (Ctrl-X)"
                                + (" after a feed hold (!)" if any(
                                    b == 0x21 and 0 <= t_abs - u < 5.0
                                    for u, b in a.realtime) else ""),
                                "interface.md §Realtime commands (0x18 soft reset)"))
    resets = tuple(t_abs - t0 for t_abs, byte in a.realtime if byte == SOFT_RESET)
    events += _refused_valid(ex, load_grbl().variant(vid), resets)
    events += _deaf(a, t0)
    for e in ex:
        words = {w for w in _words(e.text)}
        if words & set(END_WORD) and e.accepted:
            events.append(Event(e.t_sent, "job-end", f"program end `{e.text}`",
                                "gcode: M2/M30 program end", line=e.n))
    v = load_grbl().variant(vid)
    return Facts("grbl", vid, path, a.metrics["duration_s"], ex, events, t0=t0,
                 rx_capacity=v.rx_buffer, queue_capacity=v.planner_blocks,
                 queue_unit="planner blocks", answer_time=0.5, notes=list(a.notes))


DEAF_MIN = 3            # unanswered polls in a row that make a deaf stretch
POLL_ANSWER_S = 0.25    # a status report answers a ``?`` within this


def _deaf(a: Any, t0: float) -> list[Event]:
    """Stretches where ``?`` polls got no status report: grbl answers ``?`` from its main
    loop within milliseconds whatever it is doing, a full planner included (protocol.c
    protocol_exec_rt_system, called while the planner waits for room), so polls without
    reports mean nothing reached it or nothing came back: the link."""
    polls = [t for t, b in a.realtime if b == 0x3F]
    reports = sorted(t for t, _ in a.reports)
    import bisect

    out: list[Event] = []
    run: list[float] = []
    for t in [*polls, None]:
        if t is not None:
            k = bisect.bisect_left(reports, t)
            if k >= len(reports) or reports[k] - t > POLL_ANSWER_S:
                run.append(t)
                continue
            if not run:
                continue
        if len(run) >= DEAF_MIN and run[-1] - run[0] >= 0.5:
            k = bisect.bisect_right(reports, run[-1])
            back = reports[k] - t0 if k < len(reports) else None
            out.append(Event(run[0] - t0, "deaf", f"{len(run)} status polls from "
                             f"{run[0] - t0:.3f} s to {run[-1] - t0:.3f} s got no report"
                             + (f"; reports came back at {back:.3f} s" if back is not None
                                else "; none came back"),
                             "protocol.c protocol_exec_rt_system (answers ? at once)",
                             t_end=run[-1] - t0, extra={"back": back}))
        run = []
    return out


def _refused_valid(ex: list[Exchange], v: Any, resets: tuple[float, ...] = ()) -> list[Event]:
    """Proof of a loss on the wire: an ``error:N`` to a line grbl's parser takes as sent (in
    the modal state the lines before it left, back to the defaults at each soft reset:
    gcode.c gc_init from mc_reset): only damage on the way explains it. Lines refused for the
    machine's state (alarm lock, ``$`` while moving) prove nothing, nor does a line too long
    for grbl's line buffer as sent (protocol.c: the overflow flag, ``error:11``)."""
    out: list[Event] = []
    state: tuple[Any, Any] = (Modal(), [0.0, 0.0, 0.0])
    later = sorted(resets)
    for e in ex:
        text = strip_line(e.text.encode("latin-1"))[0]
        while later and later[0] <= e.t_sent:
            later.pop(0)
            state = (Modal(), state[1])
        if len(text) >= v.line_max:
            continue
        valid, _why = _check(text, *state, v)
        if e.accepted and valid:
            state = valid
        if e.accepted is False and valid and text and not text.startswith("$") and \
                _code(e.answer) not in STATE_ERRORS and e.t_answer is not None:
            out.append(Event(e.t_answer, "loss", f"line {e.n + 1} `{e.text}` answered "
                             f"`{e.answer}` though grbl's parser takes it as sent: it arrived "
                             "damaged", "protocol.c: error:N only for a line it cannot take",
                             line=e.n, extra={"proof": "refused though valid"}))
    return out


def _code(answer: str | None) -> int | None:
    try:
        return int((answer or "").split(":", 1)[1])
    except (IndexError, ValueError):
        return None


def _words(text: str) -> list[str]:
    line, _ = strip_line(text.encode("latin-1"))
    out, cur = [], ""
    for ch in line:
        if "A" <= ch <= "Z" and cur:
            out.append(cur)
            cur = ""
        cur += ch
    if cur:
        out.append(cur)
    return [w[0] + str(int(float(w[1:]))) if w[1:].replace(".", "", 1).isdigit() and
            float(w[1:]).is_integer() else w for w in out if len(w) > 1]


# ------------------------------------------------------------------ reception


@dataclass
class _Read:
    """One line as grbl's reader assembled it: its characters and their host offsets."""

    chars: list[int] = field(default_factory=list)       # host offsets of every byte taken
    text: list[str] = field(default_factory=list)        # filtered, upper-cased
    overflow: bool = False
    paren: bool = False
    semi: bool = False


def _host_and_unit(raw: Any) -> tuple[bytes, list[float], bytes, list[float]]:
    from conform.families.grbl.analysis.analyze import _byte_times

    hb, ht = _byte_times(_chunks(raw.host))
    ub, ut = _byte_times(_chunks(raw.unit))
    return hb, ht.tolist(), ub, ut.tolist()


def replay_reception(hb: bytes, ht: list[float], answers: list[float], *, rx: int,
                     line_max: int, realtime: Any, crlf_two: bool = True
                     ) -> tuple[list[_Read], list[int]]:
    """The lines grbl's reader took, in order, and the host offsets of the bytes the full
    ring dropped. ``answers``: times the unit's ok/error answers left it (sorted)."""
    ring: deque[int] = deque()
    cur = _Read()
    taken: list[_Read] = []
    dropped: list[int] = []
    blocked = False
    after_cr = False
    k = 0

    def take(off: int) -> bool:
        """One byte into the line reader; True when it ended a line."""
        nonlocal cur, after_cr
        c = hb[off]
        was_cr, after_cr = after_cr, c == 0x0D
        if c == 0x0A and was_cr and not crlf_two:
            return False
        cur.chars.append(off)
        if c in (0x0A, 0x0D):
            taken.append(cur)
            cur = _Read()
            return True
        ch = chr(c)
        if cur.paren:
            cur.paren = ch != ")"
        elif cur.semi or ch <= " " or ch == "/" or c == 0x7F:
            pass
        elif ch == "(":
            cur.paren = True
        elif ch == ";":
            cur.semi = True
        elif len(cur.text) >= line_max:
            cur.overflow = True
        else:
            cur.text.append(ch.upper())
        return False

    def drain() -> None:
        nonlocal blocked
        while ring and not blocked:
            blocked = take(ring.popleft())

    for off, t in enumerate(ht):
        while k < len(answers) and answers[k] <= t:
            k += 1
            blocked = False
            drain()
        b = hb[off]
        if b in realtime or b > 0x7F:
            continue
        if not blocked and not ring:
            blocked = take(off)
        elif len(ring) >= rx:
            dropped.append(off)
        else:
            ring.append(off)
    while k < len(answers):
        k += 1
        blocked = False
        drain()
    return taken, dropped


def reception(raw: Any, *, variant: str | None = None) -> list[ParsedLine]:
    """Every host line grbl would not have read as sent (see the module docstring)."""
    spec = load_grbl()
    v = spec.variant(_variant(raw, variant))
    hb, ht, ub, ut = _host_and_unit(raw)
    ulines, _ = split_unit(ub, spec)
    byte_time = 10.0 / v.baud
    answers = sorted(ut[u.end] - (u.end - u.start + 1) * byte_time
                     for u in ulines if u.kind in ("ok", "error"))
    taken, dropped = replay_reception(hb, ht, answers, rx=v.rx_buffer, line_max=v.line_max,
                                      realtime=spec.realtime,
                                      crlf_two=v.crlf_is_two_lines)
    lines, _rt = split_host(hb, spec)
    t0 = _t0(raw)
    line_of = {}
    for i, ln in enumerate(lines):
        line_of[ln.end] = i
    ends = [ln.end for ln in lines]
    import bisect

    def host_line(off: int) -> int:
        return bisect.bisect_left(ends, off)

    lost = set(dropped)
    out: list[ParsedLine] = []
    modal, position = Modal(), [0.0, 0.0, 0.0]
    seen: set[int] = set()
    for r in taken:
        src = sorted({host_line(o) for o in r.chars if host_line(o) < len(lines)})
        seen.update(src)
        text = "".join(r.text)
        sent = " | ".join(lines[i].data.decode("latin-1") for i in src)
        damaged = any(o in lost for i in src for o in range(lines[i].start, lines[i].end + 1))
        t = ht[r.chars[-1]] - t0
        valid, why = _check(text, modal, position, v)
        parts = f"parts of lines {', '.join(str(i + 1) for i in src)}" if len(src) > 1 \
            else f"line {src[0] + 1 if src else '?'} with bytes missing"
        if r.overflow:
            out.append(ParsedLine("truncated", src, sent, text, t,
                                  f"longer than the {v.line_max}-character line buffer: "
                                  "error:11"))
        elif (len(src) > 1 or damaged) and valid:
            out.append(ParsedLine("damaged-valid", src, sent, text, t,
                                  f"{parts} (bytes lost in the full receive buffer) read as "
                                  "one valid line: executed as read, not as sent"))
        elif len(src) > 1:
            out.append(ParsedLine("merged", src, sent, text, t,
                                  f"the end of line {src[0] + 1} was lost in the full receive "
                                  f"buffer: read with what followed as one line; {why}"))
        elif damaged:
            out.append(ParsedLine("damaged", src, sent, text, t,
                                  f"bytes lost in the full receive buffer; {why}"))
        if valid is not None and valid:
            modal, position = valid
    _compare_echoes(taken, ulines, ut, t0, lines, host_line, out, modal_check=(v,))
    for i, ln in enumerate(lines):
        span = range(ln.start, ln.end + 1)
        if i in seen or not any(o in lost for o in span):
            continue
        if all(o in lost for o in span if hb[o] not in spec.realtime):
            out.append(ParsedLine("dropped", [i], ln.data.decode("latin-1"), "",
                                  ht[ln.end] - t0, "every byte lost in the full receive "
                                  "buffer"))
        else:
            out.append(ParsedLine("truncated", [i], ln.data.decode("latin-1"),
                                  "".join(chr(hb[o]) for o in span if o not in lost),
                                  ht[ln.end] - t0, "its end was lost in the full receive "
                                  "buffer: the unit still waits for the rest of the line"))
    return sorted(out, key=lambda p: (p.host[0] if p.host else 0, p.t))


def _compare_echoes(taken: list[_Read], ulines: list[Any], ut: list[float], t0: float,
                    lines: list[Any], host_line: Any, out: list[ParsedLine],
                    modal_check: tuple[Any]) -> None:
    """Where the build echoes (REPORT_ECHO_LINE_RECEIVED: ``[echo:LINE]`` for every line read,
    filtered, before it runs; protocol.c protocol_main_loop), the k-th echo is the k-th line
    read: what grbl really got. An echo that is not the host's line (filtered the same way)
    shows a change on the way the model above cannot see (noise rather than overflow)."""
    echoes = [(ut[u.end] - t0, u.text[6:-1]) for u in ulines if u.kind == "echo"]
    if not echoes:
        return
    listed = {(tuple(p.host), p.parsed): p for p in out}
    state: tuple[Modal, list[float]] = (Modal(), [0.0, 0.0, 0.0])
    for r, (t, echo) in zip(taken, echoes, strict=False):
        valid, why = _check(echo, *state, modal_check[0])     # grbl's state, line by line
        if valid:
            state = valid
        src = sorted({host_line(o) for o in r.chars if host_line(o) < len(lines)})
        model = "".join(r.text)
        p = listed.get((tuple(src), model))
        if p is not None:
            p.echo = echo
        sent = [strip_line(lines[i].data)[0] for i in src]
        if echo in sent or (p is not None and echo == model):
            continue
        out.append(ParsedLine("damaged-valid" if valid else "damaged", src,
                              " | ".join(lines[i].data.decode("latin-1") for i in src), echo, t,
                              "grbl's [echo:] shows the line arrived changed"
                              + ("; still a valid line, executed as received" if valid else
                                 f"; {why}"), echo))


def _check(text: str, modal: Modal, position: list[float], v: Any) -> tuple[Any, str]:
    """(new modal state and position, "") when grbl's parser takes ``text``; (None, why)."""
    if not text or text.startswith("$"):
        return (modal, position), ""
    try:
        block = parse(text, modal, position, tool_max=v.tool_max,
                      line_number_max=v.line_number_max)
    except GcodeError as exc:
        return None, f"refused: error:{exc.code}"
    return (block.modal, list(block.target) if block.target is not None else position), ""


# ------------------------------------------------------------------ resume point


def resume_state(raw: Any, f: Facts, *, variant: str | None = None) -> ResumePoint | None:
    """Where the job can go on: the lines the unit acknowledged ran unless an alarm, a reset
    or a hold stopped the planner after them (grbl executes what it planned); then the last
    status report's position tells how far it got."""
    spec = load_grbl()
    v = spec.variant(_variant(raw, variant))
    job = [e for e in f.exchanges if not e.text.lstrip().startswith("$")]
    if not job:
        return None
    acked = [e for e in job if e.accepted]
    last_ack = acked[-1] if acked else None
    modal, position = Modal(), [0.0, 0.0, 0.0]
    ends: dict[int, tuple[Modal, list[float]]] = {}
    for e in f.exchanges:
        if not e.accepted:
            continue
        ok, _ = _check(strip_line(e.text.encode("latin-1"))[0], modal, position, v)
        if ok:
            modal, position = ok
        ends[e.n] = (modal, list(position))
    t_ack = last_ack.t_sent if last_ack is not None else 0.0
    stops = [ev for ev in f.events if ev.kind in ("alarm", "reset", "hold") and ev.t >= t_ack]
    evidence = []
    executed = last_ack.n if last_ack else None
    uncertain: list[int] = []
    if stops and last_ack is not None:
        stop = stops[0]
        evidence.append(f"{stop.kind} at {stop.t:.3f} s after the last acknowledged line was "
                        "sent: the planner did not run its lines out")
        if stop.kind == "alarm":
            evidence.append("clear the alarm first ($X, or $H where homing is on) and check "
                            "the position: grbl loses it on an alarm in motion")
        reports = _positions(raw, f.t0, stop.t, spec)
        segments = []
        prev = [0.0, 0.0, 0.0]
        for e in acked:
            if e.n in ends:
                segments.append((e.n, prev, ends[e.n][1]))
                prev = ends[e.n][1]
        done, moving = _progress(reports, segments)
        executed = done
        if reports:
            evidence.append(f"last reported machine position {reports[-1][1]} at "
                            f"{reports[-1][0]:.3f} s"
                            + (f": on the way of line {moving + 1}" if moving is not None
                               else ""))
        else:
            evidence.append("no status report: how far the planner got is unknown")
        uncertain = [e.n for e in acked if executed is None or e.n > executed]
    else:
        evidence.append("no alarm, reset or hold after the last acknowledged line: grbl runs "
                        "every line it acknowledged (planner.c)")
    lost = [ev.line for ev in f.events if ev.kind in ("overflow", "loss") and ev.line is not None]
    if lost and last_ack is not None and min(lost) <= last_ack.n:
        # past a lost byte grbl's answers no longer pair with the host's lines one to one
        first = min(lost)
        before = [e.n for e in acked if e.n < first]
        executed = before[-1] if before else None
        uncertain = [e.n for e in job if first <= e.n <= last_ack.n]
        evidence.append(f"bytes were lost in the receive buffer from line {first + 1}: from "
                        "there the answers do not pair with the host's lines one to one, so "
                        "every acknowledged line after it is uncertain")
    evidence.append("the preamble's G0 is one straight rapid: raise Z first if the tool is in "
                    "the material")
    unacked = [e.n for e in job if last_ack is None or e.n > last_ack.n]
    state_modal, state_pos = ends.get(executed, (Modal(), [0.0, 0.0, 0.0])) \
        if executed is not None else (Modal(), [0.0, 0.0, 0.0])
    preamble, named = _preamble(state_modal, state_pos)
    resume_from = (uncertain[0] if uncertain else
                   (unacked[0] if unacked else f.exchanges[-1].n + 1))
    nxt = (f"(`{f.exchanges[resume_from].text}`)" if resume_from < len(f.exchanges) else
           "(the first line the host never sent)")
    cmd = f"send the preamble, then the job from line {resume_from + 1} {nxt}"

    return ResumePoint(executed, last_ack.n if last_ack else None, uncertain, preamble,
                       resume_from, cmd, evidence, named)


def _close(a: list[float], b: list[float], tol: float = 0.002) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=False))


def _positions(raw: Any, t0: float, until: float, spec: Any
               ) -> list[tuple[float, list[float]]]:
    """(t, machine position) of every status report up to ``until`` (+0.1 s)."""
    ub, ut = _host_and_unit(raw)[2:]
    out = []
    wco = [0.0, 0.0, 0.0]
    for u in split_unit(ub, spec)[0]:
        t = ut[u.end] - t0
        if u.kind != "status" or t > until + 0.1:
            continue
        fields = dict(p.split(":", 1) for p in u.text.strip("<>").split("|")[1:] if ":" in p)
        try:
            if "WCO" in fields:
                wco = [float(x) for x in fields["WCO"].split(",")[:3]]
            if "MPos" in fields:
                out.append((t, [float(x) for x in fields["MPos"].split(",")[:3]]))
            elif "WPos" in fields:
                out.append((t, [float(x) + w for x, w in
                                zip(fields["WPos"].split(",")[:3], wco, strict=False)]))
        except ValueError:
            continue        # a damaged report says nothing
    return out


def _on_segment(p: list[float], a: list[float], b: list[float], tol: float = 0.002) -> bool:
    d = [y - x for x, y in zip(a, b, strict=True)]
    n2 = sum(x * x for x in d)
    k = 0.0 if n2 == 0 else max(0.0, min(1.0, sum((q - x) * y for q, x, y in
                                                  zip(p, a, d, strict=True)) / n2))
    return all(abs(q - (x + k * y)) <= tol for q, x, y in zip(p, a, d, strict=True))


def _progress(reports: list[tuple[float, list[float]]],
              segments: list[tuple[int, list[float], list[float]]]
              ) -> tuple[int | None, int | None]:
    """How far the machine got along the acknowledged lines' path: (the last line whose end
    it reached, the line it was on), following the reports in order so a path that crosses
    itself is not mistaken for an earlier pass."""
    cursor = 0
    done: int | None = None
    moving: int | None = None
    for _t, pos in reports:
        for k in range(cursor, len(segments)):
            n, a, b = segments[k]
            if _close(pos, b):
                done, moving, cursor = n, None, k + 1
                break
            if _on_segment(pos, a, b):
                moving, cursor = n, k
                done = segments[k - 1][0] if k else None
                break
    return done, moving


def _preamble(m: Modal, position: list[float]) -> tuple[list[str], dict[str, Any]]:
    """The lines that put grbl back in the modal state the job had (gcode.Modal), then a
    rapid to where the last executed line ended (clear Z first by hand if a tool is down)."""
    inch = m.units == "20"
    scale = 25.4 if inch else 1.0
    wco = m.wco()
    work = [round((p - w) / scale, 4) for p, w in zip(position, wco, strict=True)]
    feed = m.feed / scale if inch else m.feed
    named = {"distance": f"G{m.distance}", "units": f"G{m.units}",
             "work_offset": f"G{54 + m.coord}", "feed": round(feed, 4),
             "spindle": f"M{m.spindle}", "speed": m.speed, "plane": f"G{m.plane}",
             "position_work": work}
    lines = [f"G{m.units} G{m.plane} G{54 + m.coord} G90",
             "G0 " + " ".join(f"{a}{x:g}" for a, x in zip("XYZ", work, strict=True)),
             *([f"G{m.distance}"] if m.distance != "90" else []), f"F{feed:g}"]
    if m.spindle in (3, 4):
        lines.append(f"M{m.spindle} S{m.speed:g}")
    else:
        lines.append("M5")
    if not math.isfinite(feed):
        lines.remove(f"F{feed:g}")
    return lines, named
