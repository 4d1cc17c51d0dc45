"""The causes of a session's stalls, stops and anomalies, ranked, from neutral facts.

Two passes over :class:`~conform.diagnosis.facts.Facts`:

* **stalls**: stretches where the host sent no line for much longer than it usually does
  (``stall_threshold``), including the stretch from its last line to the end of the capture.
  What each side was doing then decides the cause: the host waiting on an answer that does not
  come (``unit-silent``), the unit ready and the host silent (``sender-stopped``), both
  directions dead or a recorded link event (``link-lost``), the host polling for room the unit
  never makes (``deadlock``), an alarm just before (``unit-alarm``), a byte known lost in an
  overflow just before (``buffer-overflow``).
* **full loops**: a stall's length of tries all refused for want of room (``Exchange.full``):
  the queue does not drain while the host keeps asking, a ``deadlock``.
* **anomalies**: the family's events on their own — overflow episodes, noise bursts, misuse,
  starvation, alarms, link events — each a cause where no stall already claims it.

Confidence is a plain score in [0, 1] from the rule that fired and how much evidence backs
it; causes are listed most likely first.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import accumulate

import numpy as np

from conform.diagnosis.facts import Event, Exchange, Facts

CAUSE_KINDS = ("sender-stopped", "unit-silent", "link-lost", "buffer-overflow", "deadlock",
               "starvation", "noise", "protocol-misuse", "unit-alarm", "overflow-risk",
               "lost-line", "unit-busy", "numbering-stopped")

ADVICE = {
    "sender-stopped": "The unit was ready and waiting: look at the sender (crash, closed "
                      "program, USB suspend, its own pause or error dialog), then resume from "
                      "the resume point.",
    "unit-silent": "The host waited for an answer that never came: check the unit's power, "
                   "its reset or watchdog, the cable, and whether the line reached it "
                   "(a lost line end leaves the unit waiting for the rest).",
    "link-lost": "Both directions went dead: check the cable, the USB converter (power "
                 "saving, a loose plug, ground loops) and the port's reconnect handling; lines "
                 "sent while the link was down never arrived.",
    "buffer-overflow": "The host sent more than the unit's receive buffer holds: bytes were "
                       "lost. Count every byte sent (polls and extra commands included) "
                       "against the buffer, or send one line at a time.",
    "overflow-risk": "More bytes were in flight than the receive buffer holds, though no loss "
                     "shows on the wire (the unit took them fast enough this time): count "
                     "every byte sent against the buffer before it costs a line.",
    "unit-busy": "The unit kept saying it was working and never finished: look at what the "
                 "line waits for (a heater that never reaches its target, a wait for the user, "
                 "a very long move) before blaming the link.",
    "numbering-stopped": "The sender stopped numbering its lines (with their checks) part way: "
                         "from then on the unit cannot tell a line lost or damaged on the way, "
                         "nor ask for it again. Make the sender number every job line (queries "
                         "and emergency commands may go unnumbered beside them).",
    "lost-line": "A line or its answer was lost on the way: check the cable and the sender's "
                 "recovery (ask the unit before sending it again).",
    "deadlock": "Each side waited for the other: the unit held its work while the host "
                "waited for room. Resume the unit (or clear the condition it holds for) "
                "and make the sender stop waiting on room while the unit holds.",
    "starvation": "The unit's queue ran dry while the host was slow: send ahead (keep the "
                  "queue fed), cut per-line overhead (latency, packets), or slow the feed.",
    "noise": "Damaged bytes on the line: check the cable, shielding and ground, lower the "
             "baud rate, and use checksums where the protocol has them.",
    "protocol-misuse": "The sender broke a protocol rule: fix the sender (wait for each "
                       "answer, ask the unit before sending a line again, stay within the buffer).",
    "unit-alarm": "The unit stopped on its own alarm or interrupt: read its code, clear the "
                  "cause (limit, probe, door, e-stop), unlock or reset, and resume from the "
                  "resume point.",
}

STALL_MIN_S = 1.0           # a stall is at least this long
STALL_FACTOR = 10.0         # ... and this many times the host's median gap between lines
BEFORE_S = 2.0              # events this long before a stall may explain it
BURST_GAP_S = 1.0           # events of one kind closer than this form one burst


@dataclass
class Cause:
    kind: str
    confidence: float
    t_start: float
    t_end: float
    evidence: list[str]
    advice: str
    summary: str                # one sentence
    lines: list[int] = field(default_factory=list)
    at_end: bool = False        # the stall it explains runs to the end of the capture
    stall: bool = False         # it explains a stall (not an anomaly on its own)
    rule: str = ""              # the rule that named it (its key in the calibration table)
    measured: tuple[int, int] | None = None     # (agreed, sessions) in the labelled corpus

    @property
    def key(self) -> str:
        return f"{self.kind}/{self.rule}"

    def shown(self) -> str:
        """Its confidence as said: measured (the fraction of the labelled corpus's sessions
        led by this kind and rule whose label agreed, with their count), else the rule's own
        score, said to be one."""
        if self.measured is None:
            return f"score {self.confidence:.2f}, not measured"
        k, n = self.measured
        return f"confidence {k / n:.2f}, n={n}"

    def to_json(self) -> dict[str, object]:
        m = self.measured
        return {"kind": self.kind,
                "confidence": round(self.confidence if m is None else m[0] / m[1], 3),
                "measured": None if m is None else {"agreed": m[0], "sessions": m[1]},
                "score": round(self.confidence, 3), "rule": self.rule,
                "t_start": round(self.t_start, 6), "t_end": round(self.t_end, 6),
                "evidence": self.evidence, "advice": self.advice, "summary": self.summary,
                "lines": self.lines}


@dataclass
class Stall:
    t_start: float          # the last line sent before it
    t_end: float            # the next line sent, or the end of the capture
    last: int               # index of that last line in the exchanges
    at_end: bool


def stall_threshold(f: Facts) -> float:
    """How long the host may go without a line before it is a stall."""
    ts = np.fromiter((e.t_sent for e in f.exchanges), float, len(f.exchanges))
    gaps = np.diff(ts)
    gaps = gaps[gaps > 0]
    med = float(np.median(gaps)) if len(gaps) else 0.0    # the middle one, or the mean of two
    return max(STALL_MIN_S, STALL_FACTOR * med)


def find_stalls(f: Facts) -> list[Stall]:
    """Stretches without progress, longer than ``stall_threshold``: the host sending no line
    long after the unit was ready (a wait for answers that did come is no stall), or no answer
    to any line while the host had one outstanding (resends or not). Overlapping ones join."""
    ex = f.exchanges
    if not ex:
        return []
    limit = stall_threshold(f)
    answers = sorted(e.t_answer for e in ex if e.t_answer is not None)
    sends = [e.t_sent for e in ex]
    found: list[tuple[float, float]] = []
    # only the gaps as long as a stall are looked at one by one (a long capture has millions)
    at = np.array(sends, float)
    for i in np.flatnonzero(~(np.append(at[1:], f.duration) - at < limit)).tolist():
        e = ex[i]
        nxt = ex[i + 1].t_sent if i + 1 < len(ex) else f.duration
        k = bisect.bisect_right(answers, nxt)
        ready = max(e.t_sent, answers[k - 1] if k else e.t_sent)
        if nxt - ready >= limit:    # else: sent as soon as an answer made room, a wait
            found.append((ready, nxt))
    starts, ends = [0.0, *answers], [*answers, f.duration]
    gap = np.array(ends, float) - np.array(starts, float)
    for j in np.flatnonzero(~(gap < limit)).tolist():
        a, b = starts[j], ends[j]
        k = bisect.bisect_left(sends, b)
        start = max(a, ex[0].t_sent)    # no stall before the host's first line
        if k and b - start >= limit and any(
                x.t_answer is None or x.t_answer >= b - 1e-9 for x in ex[:k]
                if x.t_sent <= b):
            found.append((start, b))
    found.sort()
    merged: list[list[float]] = []
    for a, b in found:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    out = []
    for a, b in merged:
        last = max(bisect.bisect_right(sends, b - 1e-9) - 1, 0)
        out.append(Stall(a, b, last, b >= f.duration - 1e-9))
    return out


def pending_at(f: Facts, s: Stall) -> list[Exchange]:
    """Lines the host waited on through the stall: sent before its end, not answered before
    its end, and not given up (a later line answered before the stall superseded them)."""
    done_before = [e.n for e in f.exchanges if e.t_answer is not None and
                   e.t_answer <= s.t_start + 1e-9]
    floor = max(done_before, default=-1)
    return [e for e in f.exchanges[:s.last + 1] if e.n > floor and
            (e.t_answer is None or e.t_answer >= s.t_end - 1e-9)]


def _any_between(times: list[float], lo: float, hi: float) -> bool:
    k = bisect.bisect_right(times, lo)
    return k < len(times) and times[k] < hi


def _polled(f: Facts, t_line: float) -> bool:
    """The host sent other traffic (status polls) besides its lines in the 3 s up to
    ``t_line``."""
    reads = _count_between(f.host_times, t_line - 3.0, t_line + 1e-6)
    return reads > sum(1 for e in f.exchanges if t_line - 3.0 < e.t_sent <= t_line) + 1


def _longest_gap(times: list[float], lo: float, hi: float) -> tuple[float, float]:
    """The longest stretch in [lo, hi] without a time of ``times``: (length, start)."""
    a, b = bisect.bisect_right(times, lo), bisect.bisect_left(times, hi)
    edges = [lo, *times[a:b], hi]
    best = (0.0, lo)
    for x, y in zip(edges, edges[1:], strict=False):
        if y - x > best[0]:
            best = (y - x, x)
    return best


def _last_before(times: list[float], t: float) -> float:
    k = bisect.bisect_left(times, t)
    return times[k - 1] if k else 0.0


def _count_between(times: list[float], lo: float, hi: float) -> int:
    return bisect.bisect_left(times, hi) - bisect.bisect_right(times, lo)


def _events(f: Facts, kinds: tuple[str, ...], lo: float, hi: float) -> list[Event]:
    return [ev for ev in f.events if ev.kind in kinds and lo <= (ev.t_end or ev.t) and
            ev.t <= hi]      # an event that lasts counts where it overlaps


def _fmt(t: float) -> str:
    return f"{t:.3f} s"


def _ev(ev: Event) -> str:
    rule = f" [{ev.rule}]" if ev.rule else ""
    return f"{_fmt(ev.t)} {ev.kind}: {ev.text}{rule}"


def _line(e: Exchange) -> str:
    return f"line {e.n + 1} `{e.text}`"


def _stall_cause(f: Facts, s: Stall, claimed: set[int]) -> list[Cause]:
    """The candidate causes of one stall, each with its confidence."""
    ex = f.exchanges
    last = ex[s.last]
    wait = f.answer_time
    pending = pending_at(f, s)
    unit_quiet_from = s.t_start + wait
    unit_active = _any_between(f.unit_times, unit_quiet_from, s.t_end - 1e-6)
    host_reads = _count_between(f.host_times, s.t_start + 1e-6, s.t_end)
    span = f"{_fmt(s.t_start)} to {_fmt(s.t_end)}" + (" (the end of the capture)"
                                                       if s.at_end else "")
    gap = s.t_end - s.t_start
    before = s.t_start - BEFORE_S
    link = _events(f, ("link",), before, s.t_end)
    since = min([before, *(e.t_sent for e in pending)])    # it left while they waited
    closed = _events(f, ("sender-closed",), since, s.t_end + 0.5)
    alarms = _events(f, ("alarm",), before, s.t_end)
    lost = _events(f, ("loss",), 0.0, s.t_end)        # proven on the wire, not a risk
    risk = _events(f, ("overflow",), 0.0, s.t_end)
    noise = _events(f, ("noise",), before, s.t_end)
    holds = _events(f, ("hold", "full"), before, s.t_end)
    starved = _events(f, ("starved",), before, s.t_end)
    ends = _events(f, ("job-end",), 0.0, s.t_start + wait)
    out: list[Cause] = []

    def add(rule: str, kind: str, conf: float, summary: str, evidence: list[str],
            used: list[Event]) -> None:
        claimed.update(id(ev) for ev in used)
        out.append(Cause(kind, min(conf, 0.99), s.t_start, s.t_end,
                         [f"stall {span}: the host sent no line for {gap:.3f} s", *evidence,
                          *(_ev(ev) for ev in used[:8])], ADVICE[kind], summary,
                         sorted({e.n for e in pending} | {last.n}), s.at_end, rule=rule))

    if alarms:
        a = alarms[0]
        add("stall-after-alarm", "unit-alarm",
            0.9, f"The unit stopped the job itself: {a.text} at {_fmt(a.t)}, "
            f"after {_line(last)}.", [], alarms + starved)
    real_link = [ev for ev in link if ev.extra.get("kind") in ("disconnect", "error", "close")]
    if real_link:
        add("stall-link-event", "link-lost", 0.92, f"The link was lost at {_fmt(real_link[0].t)}: "
            f"{real_link[0].text}.", [], link)
    never = [e for e in pending if e.t_answer is None]
    deaf = _events(f, ("deaf",), before, s.t_end)
    if pending and not never and not real_link and not alarms and not holds and not deaf:
        return out      # every line it waited on was answered: the unit was working, a wait
    busy = _events(f, ("running",), s.t_start, s.t_end + 1e-6)
    if never and busy and not real_link and not deaf and not alarms and \
            busy[-1].t >= s.t_end - max(stall_threshold(f), 2.5):
        add("stall-unit-working", "unit-busy",
            0.85, f"The unit said it was working ({busy[-1].text}) up to "
            f"{_fmt(busy[-1].t)} and never answered {_line(never[0])}: it is busy, not lost.",
            [f"{len(busy)} report(s) of the unit working in the stall, the last at "
             f"{_fmt(busy[-1].t)}"], busy[-3:])
        return out
    if deaf and not real_link:
        d = deaf[0]
        if d.extra.get("back") is not None:
            add("stall-polls-unanswered-then-back", "link-lost",
                0.85, f"The link was down from {_fmt(d.t)}: the unit answered "
                f"none of the host's polls until {_fmt(d.extra['back'])} and then answered "
                "other traffic again; what was sent meanwhile was lost on the way.",
                ["polls it answers at once whatever it does went unanswered"], deaf)
        else:
            add("stall-polls-unanswered", "unit-silent",
                0.85, f"The unit went deaf at {_fmt(d.t)}: it answered none "
                "of the host's polls from then on.", [], deaf)
    if pending:
        first = never[0] if never else pending[0]
        answered_later = [e for e in ex[s.last + 1:] if e.t_answer is not None]
        if holds and unit_active and host_reads:
            add("stall-hold-polled", "deadlock",
                0.8, f"Both sides waited on each other from {_fmt(s.t_start)}: "
                f"the unit held its work and the host waited for room, polling "
                f"({host_reads} reads) without sending.",
                [f"{_line(first)} waits for its answer; the unit kept answering polls"],
                holds)
        if lost and never:
            kind = "buffer-overflow" if risk and risk[0].t <= lost[0].t else "lost-line"
            add("stall-after-proven-loss", kind,
                0.88, ("Bytes were lost in a receive-buffer overflow" if risk else
                             "A line or its answer was lost on the way")
                + f" (proof: {lost[0].text}), so {_line(first)} was never answered and the "
                f"host waited from {_fmt(s.t_start)}.",
                [f"{len(never)} line(s) never answered in the capture"],
                lost + risk[:2])
        guard = [ev for ev in _events(f, ("unguarded",), 0.0, s.t_end)
                 if never and ev.t <= never[0].t_sent <= (ev.t_end or ev.t) + 1e-9]
        if guard:
            alive = _any_between(f.unit_times, never[0].t_sent + wait, s.t_end)
            add("stall-unnumbered-line", "numbering-stopped", 0.9 if alive else 0.7,
                f"{_line(never[0])} went without a number (the host had stopped numbering "
                f"at {_fmt(guard[0].t)}) and was never answered; "
                + ("the unit went on sending, so it did not get the line whole, and without "
                   "a number it could not tell one was missing nor ask for it again."
                   if alive else "the unit sent nothing more, so whether the line was "
                   "missed or the unit stopped the wire cannot tell; without a number a "
                   "missed line is never asked for again."),
                [f"{_line(never[0])} sent at {_fmt(never[0].t_sent)} without a number",
                 "the unit sent bytes after it, none answering it" if alive else
                 "the unit sent nothing after it"], guard)
        if noise:
            add("stall-after-noise", "noise",
                0.7, f"Damaged bytes ({len(noise)} at {_fmt(noise[0].t)}) left "
                f"{_line(first)} unanswered.", [], noise)
        quiet, q_from = _longest_gap(f.unit_times, s.t_start, s.t_end)
        back = _any_between(f.unit_times, q_from + quiet, s.t_end + 1e-9)
        # the line waited on was sent into the silence (not before it: then the silence is
        # a gap between the unit's own reports, and nothing was sent "meanwhile")
        into = bool(never) and never[0].t_sent >= q_from - wait
        if unit_active and back and quiet >= stall_threshold(f) and not real_link and into:
            add("stall-unit-quiet-then-back", "link-lost",
                0.75, f"The unit went silent for {quiet:.3f} s from "
                f"{_fmt(q_from)} and then answered other traffic again, never "
                f"{_line(first)}: what was sent meanwhile was lost on the way.",
                [f"no byte from the unit from {_fmt(q_from)} to {_fmt(q_from + quiet)}",
                 f"{len(pending)} line(s) never answered"], [])
        if not unit_active and not s.at_end and answered_later and not real_link and never:
            add("stall-both-dead", "link-lost",
                0.7, f"Both directions went dead from {_fmt(s.t_start)} for "
                f"{gap:.3f} s: lines sent meanwhile were never answered, later ones were.",
                [f"no byte from the unit from {_fmt(unit_quiet_from)} to {_fmt(s.t_end)}",
                 f"{len(pending)} line(s) lost, answers resumed at "
                 f"{_fmt(answered_later[0].t_answer or 0.0)}"], [])
        t_line = last.t_sent
        polled = _polled(f, t_line)
        host_gone = bool(closed) or (
            polled and not _any_between(f.host_times, t_line + 1e-6, s.t_end))
        if host_gone and (s.at_end or closed):     # one that went on after only paused
            add("stall-host-gone", "sender-stopped", 0.95 if closed else 0.85,
                f"The sender stopped at {_fmt(t_line)} while it waited on answers: "
                + ("it closed its port." if closed else "its polls stopped with its lines."),
                [f"{len(never)} line(s) still waiting; the host sent nothing after "
                 f"{_fmt(t_line)}"], closed)
        silent_conf = 0.8 if not unit_active else 0.6
        if answered_later and not unit_active:
            silent_conf = 0.45
        if first.t_answer is not None and first.t_answer <= s.t_end + 1e-9:
            silent_conf = 0.3       # it came, late: a long motion or a full queue, maybe
        if lost or noise:
            silent_conf = min(silent_conf, 0.5)     # explained by what was lost before
        answered_in = any(e.t_answer is not None and s.t_start < e.t_answer <= s.t_end
                          for e in ex)
        if host_gone and answered_in:
            silent_conf = min(silent_conf, 0.4)     # the unit went on answering a dead host
        add("stall-no-answer", "unit-silent",
            silent_conf, f"The host waited from {_fmt(first.t_sent)} for the "
            f"answer to {_line(first)}, which "
            + (f"came only at {_fmt(first.t_answer)}" if first.t_answer is not None
               else "never came")
            + (" (the unit answered nothing more)." if not unit_active else
               " (the unit still answered other traffic)."),
            [f"{len(never)} line(s) never answered in the capture, {len(pending)} waiting "
             "in the stall",
             "the unit sent nothing after " + _fmt(_last_before(f.unit_times, s.t_end))
             if not unit_active else
             "the unit sent bytes in the stall, none answering the line"], [])
        return out
    # every line answered: the unit was ready
    if ends and s.at_end:
        return out      # the job ended by its own end word: not a stop
    conf = 0.85 if s.at_end else 0.6
    ev_text = [f"{_line(last)} was answered `{last.answer}` at "
               f"{_fmt(last.t_answer or last.t_sent)}: the unit was ready",
               f"the host sent {host_reads} read(s) in the stall, no line"]
    t_line = last.t_sent
    polled = _polled(f, t_line)
    silent_after = not _any_between(f.host_times, t_line + 1e-6, s.t_end)
    if s.at_end and polled and silent_after:
        conf = 0.9
        ev_text.append("the host's other traffic (status polls) stopped with its lines: "
                       "the sender's process ended or hung")
    elif s.at_end and not silent_after:
        conf = 0.6
        ev_text.append("the sender went on polling without sending lines: it paused, "
                       "waits on its user, or its job ended")
    elif s.at_end and not polled:
        conf = 0.65
        ev_text.append("the host never polled: a job that simply ended looks the same "
                       "unless its end word is in the capture")
    if closed:
        conf = 0.95
    if alarms:
        conf = min(conf, 0.5)       # stopping after an alarm is the sender's right answer
    add("stall-unit-ready", "sender-stopped",
        conf, f"The sender stopped: the unit had answered every line and "
        f"was ready at {_fmt(last.t_answer or last.t_sent)}, and the host sent nothing more "
        + ("until the capture ended." if s.at_end else f"for {gap:.3f} s."),
        ev_text, closed + starved)
    return out


def _bursts(events: list[Event]) -> list[list[Event]]:
    out: list[list[Event]] = []
    for ev in sorted(events, key=lambda e: e.t):
        if out and ev.t - (out[-1][-1].t_end or out[-1][-1].t) <= BURST_GAP_S:
            out[-1].append(ev)
        else:
            out.append([ev])
    return out


EVENT_CAUSE = {  # family event kind -> cause kind, base confidence, per-event step
    "overflow": ("overflow-risk", 0.5, 0.05),
    "loss": ("lost-line", 0.6, 0.1),
    "noise": ("noise", 0.45, 0.08),
    "misuse": ("protocol-misuse", 0.45, 0.05),
    "starved": ("starvation", 0.55, 0.05),
    "alarm": ("unit-alarm", 0.85, 0.0),
    "link": ("link-lost", 0.6, 0.05),
    "hold": ("deadlock", 0.3, 0.0),
    "unguarded": ("numbering-stopped", 0.5, 0.0),
}

SUMMARY = {
    "buffer-overflow": "More bytes were in flight than the unit's receive buffer holds "
                       "from {t}, and the wire shows bytes lost: {first}.",
    "overflow-risk": "More bytes were in flight than the unit's receive buffer holds, from "
                     "{t} ({n} times); no loss shows on the wire: {first}.",
    "lost-line": "A line or its answer was lost on the way at {t} ({n} in all): {first}.",
    "noise": "A burst of damaged bytes from {t} ({n} events).",
    "protocol-misuse": "The sender broke the protocol from {t} ({n} times): {first}.",
    "starvation": "The unit's queue ran dry {n} time(s) from {t} while the host was slow.",
    "unit-alarm": "The unit raised an alarm at {t}: {first}.",
    "link-lost": "The link dropped at {t}: {first}.",
    "deadlock": "The unit held its work at {t}: {first}.",
    "numbering-stopped": "The sender stopped numbering its lines at {t}: {n} job line(s) "
                         "went without a number, which the unit can neither check nor ask "
                         "for again: one lost or damaged on the way would go unnoticed.",
}


def _answered_after(f: Facts) -> Callable[[float], bool]:
    """``t`` -> whether a line sent by ``t`` was answered after ``t`` (the latest answer among
    the lines sent by then, as a running maximum)."""
    sent = [e.t_sent for e in f.exchanges]
    latest = list(accumulate((-1.0 if e.t_answer is None else e.t_answer
                              for e in f.exchanges), max))

    def after(t: float) -> bool:
        k = bisect.bisect_right(sent, t)
        return k > 0 and latest[k - 1] > t
    return after


def _anomalies(f: Facts, claimed: set[int]) -> list[Cause]:
    out = []
    for ev_kind, (kind, base, step) in EVENT_CAUSE.items():
        evs = [ev for ev in f.events if ev.kind == ev_kind and id(ev) not in claimed]
        if ev_kind == "link":
            evs = [ev for ev in evs if ev.extra.get("kind") in ("disconnect", "error", "close")]
        if ev_kind == "hold" and evs:   # a hold the unit came out of, taking the lines,
            resumed = _answered_after(f)    # held nothing
            evs = [ev for ev in evs if not resumed(ev.t)]
        if ev_kind == "overflow" and any(ev.kind == "loss" for ev in f.events):
            continue            # the proven loss's cause carries the risk that came before
        for burst in _bursts(evs):
            n = sum(int(ev.extra.get("count", 1)) for ev in burst)
            conf = base + step * min(n - 1, 4)
            risk = [ev for ev in f.events if ev.kind == "overflow" and ev.t <= burst[0].t]
            if kind == "lost-line" and risk:
                kind = "buffer-overflow"     # a proven loss after bytes over the buffer
                conf += 0.2
                burst = risk[:1] + burst
            t1 = max(ev.t_end or ev.t for ev in burst)
            summary = SUMMARY[kind].format(t=_fmt(burst[0].t), n=n, first=burst[0].text)
            out.append(Cause(kind, min(conf, 0.95), burst[0].t, t1,
                             [_ev(ev) for ev in burst[:10]], ADVICE[kind], summary,
                             sorted({ev.line for ev in burst if ev.line is not None}),
                             rule=f"event-{ev_kind}"))
    return out


def _merge(causes: list[Cause]) -> list[Cause]:
    """One cause per kind and overlapping stretch: the evidence joined, the best confidence."""
    out: list[Cause] = []
    for c in sorted(causes, key=lambda c: (c.kind, c.t_start)):
        prev = out[-1] if out and out[-1].kind == c.kind else None
        if prev is not None and c.t_start <= prev.t_end + BURST_GAP_S:
            best, other = (prev, c) if prev.confidence >= c.confidence else (c, prev)
            best.evidence += [x for x in other.evidence if x not in best.evidence]
            best.t_start, best.t_end = min(prev.t_start, c.t_start), max(prev.t_end, c.t_end)
            best.lines = sorted(set(best.lines) | set(other.lines))
            out[-1] = best
        else:
            out.append(c)
    return out


def _full_loops(f: Facts, claimed: set[int]) -> list[Cause]:
    """Stretches longer than a stall where every line was refused for want of room: the
    unit's queue did not drain (it holds) while the host kept asking: a deadlock."""
    out: list[Cause] = []
    if not any(e.full for e in f.exchanges):
        return out                      # no line refused as full: no loop
    limit = stall_threshold(f)
    run: list[Exchange] = []
    for e in [*f.exchanges, None]:
        if e is not None and e.full:
            run.append(e)
            continue
        if e is not None and e.accepted is None and run:
            continue                    # an unanswered retry does not end the loop
        if run and (run[-1].t_answer or run[-1].t_sent) - run[0].t_sent >= limit:
            t0, t1 = run[0].t_sent, run[-1].t_answer or run[-1].t_sent
            held = _events(f, ("alarm", "hold"), t0 - BEFORE_S, t1)
            claimed.update(id(ev) for ev in held)
            why = f" after {held[0].text}" if held else ""
            out.append(Cause("deadlock", 0.85 if held else 0.75, t0, t1,
                             [f"{len(run)} tries of {_line(run[0])} refused as full from "
                              f"{_fmt(t0)} to {_fmt(t1)}: the queue did not drain",
                              *(_ev(ev) for ev in held[:4])], ADVICE["deadlock"],
                             f"Both sides waited on each other from {_fmt(t0)}: the unit "
                             f"held its full queue{why} and the host kept asking for room "
                             f"for {t1 - t0:.3f} s.", sorted({x.n for x in run}),
                             rule="refused-full"))
        run = []
    return out


def rank(f: Facts) -> list[Cause]:
    """Every cause found, most likely first."""
    claimed: set[int] = set()
    found: list[Cause] = _full_loops(f, claimed)
    for s in find_stalls(f):
        found += _stall_cause(f, s, claimed)
    found += _anomalies(f, claimed)
    for c in found:
        c.stall = any(x.startswith("stall ") for x in c.evidence[:1])
    return sorted(_merge(found), key=lambda c: (-c.confidence, c.t_start))
