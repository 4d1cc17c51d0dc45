"""How the session ended, decided from evidence before any cause is named.

The outcome comes first because everything else depends on it: a job that ran to its end has
no stop cause (what went wrong on the way is a hazard), a job stopped by its own sender was
not lost by the link, a capture whose end is missing cannot say how the session ended.

* ``completed``: every line the host sent was answered (a line sent again and answered then
  counts), and the capture shows the end: the job's own end word answered, or the unit
  reporting itself idle after its last motion line.
* ``ended``: every line answered, but neither a program end nor the unit idle in the capture:
  a job without an end word and a sender stopped between lines look the same on the wire, so
  no stop is claimed and the resume point is offered in case.
* ``stopped``: by the sender (its own halt: a reset, an emergency stop, the family's halt
  command with no motion after it; it closed its port with lines waiting; or it went quiet
  while the unit reported itself still running and no end word came) or by the link.
* ``stalled``: lines wait for answers at the end and the unit never gives them (silent, held,
  or the lines were lost on the way).
* ``aborted``: the unit stopped the job itself (an alarm, a kill) and nothing ran after.
* ``unfinished``: the capture ended while lines still waited, too soon to call it a stall.
* ``capture-damaged``: the file is cut short or damaged; only what it holds is judged, and the
  session's end is not claimed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from conform.diagnosis.facts import Event, Exchange, Facts

OUTCOMES = {
    "completed": "the job ran to its end",
    "stopped": "the job was stopped before its end",
    "stalled": "the session stopped moving: the host waits on answers that do not come",
    "aborted": "the unit aborted the job itself",
    "unfinished": "the capture ended while lines still waited for their answers",
    "ended": "every line was answered, but the capture does not show the job's end",
    "capture-damaged": "the capture file is damaged: only what it holds is judged",
    "no-job": "the host sent no line",
    "findings-only": "the capture is longer than the diagnosis keeps line by line: only the "
                     "analysis's findings are judged",
}
STALL_LEADS = ("deadlock", "unit-busy", "buffer-overflow", "lost-line", "numbering-stopped",
               "noise", "unit-silent", "link-lost", "sender-stopped")


@dataclass
class Outcome:
    kind: str
    summary: str
    evidence: list[str] = field(default_factory=list)
    by: str | None = None           # stopped: "sender" or "link"; aborted: "unit"
    lead: str | None = None         # the cause kind that must lead (None: none does)
    measured: tuple[int, int] | None = None     # (agreed, sessions) in the labelled corpus

    @property
    def key(self) -> str:
        """Its key in the calibration table (conform/diagnosis/calibration.toml)."""
        return f"outcome/{self.kind}" + (f"/{self.by}" if self.by else "")

    def to_json(self) -> dict[str, Any]:
        out = {k: v for k, v in asdict(self).items() if v is not None and k != "measured"}
        if self.measured is not None:
            k, n = self.measured
            out["confidence"] = round(k / n, 3)
            out["measured"] = {"agreed": k, "sessions": n}
        return out

    def title(self) -> str:
        if self.kind == "stopped":
            return f"Stopped by the {self.by}"
        return {"completed": "Completed", "stalled": "Stalled", "aborted": "Aborted by the unit",
                "unfinished": "Unfinished capture", "capture-damaged": "Capture damaged",
                "no-job": "No job", "findings-only": "Not judged",
                "ended": "Ended"}[self.kind]


def _fmt(t: float) -> str:
    return f"{t:.3f} s"


def _line(e: Exchange) -> str:
    return f"line {e.n + 1} `{e.text}`"


def settled(f: Facts) -> tuple[list[Exchange], list[Exchange]]:
    """(answered lines, lines still waiting at the end): a line without an answer counts as
    settled when a line sent after it was answered (the session went on past it)."""
    ex = f.exchanges
    answered = [e for e in ex if e.t_answer is not None]
    last = max((e.n for e in answered), default=-1)
    return answered, [e for e in ex if e.t_answer is None and e.n > last]


def _terminal(f: Facts, kind: str, motion_only: bool = True) -> list[Event]:
    """Events of ``kind`` after which no accepted motion line (``motion_only`` False: no
    accepted line at all) was sent: nothing went on."""
    taken = [e.t_sent for e in f.exchanges if e.accepted and (e.motion or not motion_only)]
    last = max(taken, default=float("-inf"))
    return [ev for ev in f.events if ev.kind == kind and last <= ev.t]


def prove_losses(f: Facts) -> None:
    """The engine's own proof of a loss: the unit reported itself idle after a line was sent
    and that line is still unanswered at the end; it holds nothing of it, so the line (or
    its answer) was lost on the way. Added as ``loss`` events (``proof`` in extra)."""
    _answered, waiting = settled(f)
    if not waiting:
        return
    first = waiting[0]
    idle = [ev for ev in f.events if ev.kind == "idle" and ev.t > first.t_sent + f.answer_time]
    if idle:
        f.events.append(Event(idle[0].t, "loss", f"the unit reported itself idle at "
                              f"{_fmt(idle[0].t)} with {_line(first)} unanswered "
                              f"({len(waiting)} line(s) in all): it holds nothing of them",
                              "idle with lines unanswered", line=first.n,
                              extra={"proof": "answer missing"}))


def decide(f: Facts, causes: list[Any]) -> Outcome:
    """The outcome (see the module docstring); ``causes``: the ranked causes, for a stall's
    kind."""
    ex = f.exchanges
    if not f.lines_kept:
        return Outcome("findings-only", "The capture is too long to follow line by line: its "
                       "ending is not judged; what its analysis found is listed.",
                       ["the family's analysis kept no line table for it"])
    answered, waiting = settled(f)
    at_end = [c for c in causes if getattr(c, "at_end", False)]
    if f.damaged:   # said first, whatever the intact part holds
        return Outcome("capture-damaged", f"The capture is damaged ({f.damaged}): it is cut "
                       f"short, so how the session ended is not known; judged up to "
                       f"{_fmt(f.duration)}: {len(ex)} lines sent, {len(answered)} answered.",
                       [f"capture: {f.damaged}"])
    if not ex:
        return Outcome("no-job", "The host sent no line in the capture.",
                       [f"{len(f.host_times)} host read(s), no complete line"])
    # a halt the session went on after (lines sent and taken: a reset between probes, a
    # setting tried and the unit reset) stopped nothing
    halts = _terminal(f, "halt", motion_only=False)
    alarms = _terminal(f, "alarm")
    if halts and (not alarms or halts[0].t <= alarms[0].t + 1e-6):
        h = halts[0]
        return Outcome("stopped", f"The sender stopped the job itself at {_fmt(h.t)}: "
                       f"{h.text}.", [f"{_fmt(h.t)} {h.text}", "no motion line was sent after "
                       "it"] + ([f"{len(waiting)} line(s) sent before it were never answered "
                                 "(the unit discards them)"] if waiting else []),
                       by="sender", lead="sender-stopped")
    if alarms:
        a = alarms[0]
        return Outcome("aborted", f"The unit aborted the job at {_fmt(a.t)}: {a.text}.",
                       [f"{_fmt(a.t)} {a.text}", "no motion line was taken after it"],
                       by="unit", lead="unit-alarm")
    if waiting:
        first = waiting[0]
        ev = [f"{len(waiting)} line(s) unanswered at the end of the capture, from "
              f"{_line(first)} sent at {_fmt(first.t_sent)}"]
        closed = [e for e in f.events if e.kind == "sender-closed" and e.t >= first.t_sent]
        if closed:
            lead = next((c for c in causes if c.kind == "sender-stopped"), None)
            return Outcome("stopped", f"The sender closed its port at {_fmt(closed[0].t)} "
                           f"while {len(waiting)} line(s) still waited for their answers.",
                           [*ev, f"{_fmt(closed[0].t)} {closed[0].text}"]
                           + (lead.evidence[1:3] if lead is not None else []),
                           by="sender", lead="sender-stopped")
        stalls = at_end or [c for c in causes if getattr(c, "stall", False)]
        if stalls:
            top = next((c for c in stalls if c.kind in STALL_LEADS), stalls[0])
            if top.kind == "sender-stopped":
                return Outcome("stopped", top.summary, ev, by="sender", lead=top.kind)
            if top.kind == "link-lost":
                return Outcome("stopped", top.summary, ev, by="link", lead=top.kind)
            return Outcome("stalled", top.summary, ev, lead=top.kind)
        return Outcome("unfinished", f"The capture ended {f.duration - first.t_sent:.3f} s "
                       f"after {_line(first)} was sent, before its answer: too soon to call "
                       "it a stall.", ev)
    refused: list[Exchange] = []
    if ex[-1].accepted is False:
        taken = {e.text for e in ex if e.accepted}
        refused = [e for e in ex if e.accepted is False and e.text not in taken]
    if refused:
        anomalies = [c for c in causes if c.kind in ("noise", "lost-line", "buffer-overflow",
                                                     "protocol-misuse")]
        return Outcome("stalled", f"The unit refused the last line the host sent "
                       f"({_line(ex[-1])}, answered `{ex[-1].answer}`), and {len(refused)} "
                       "refused line(s) were never taken on a later try: the job did not run "
                       "to its end.", [f"{len(refused)} line(s) refused and never taken"],
                       lead=anomalies[0].kind if anomalies else None)
    last = max(answered, key=lambda e: e.t_answer or 0.0)
    t_last = last.t_answer or last.t_sent
    ends = [e for e in f.events if e.kind == "job-end"]
    t_motion = max((e.t_sent for e in ex if e.motion), default=ex[0].t_sent)
    idle = sorted((e for e in f.events if e.kind == "idle" and e.t >= t_motion - 1e-6),
                  key=lambda e: e.t)
    t_sent = max(e.t_sent for e in ex)
    states = sorted((e for e in f.events if e.kind in ("idle", "running") and
                     e.t >= ex[0].t_sent), key=lambda e: e.t)
    running = [states[-1]] if states and states[-1].kind == "running" else []
    head = f"all {len(ex)} lines answered, the last at {_fmt(t_last)}"
    if ends:
        e = ends[-1]
        idle = [i for i in idle if i.t >= e.t]      # idle after the end, not before it
        return Outcome("completed", f"The job ran to its end: {head}, the program end "
                       f"`{e.text.split('`')[1] if '`' in e.text else e.text}` answered"
                       + (f", the unit idle at {_fmt(idle[0].t)}." if idle else "."),
                       [head, f"{_fmt(e.t)} {e.text}"]
                       + ([f"{_fmt(idle[0].t)} {idle[0].text}"] if idle else []))
    if idle and not running:
        return Outcome("completed", f"The job ran to its end: {head}, the unit reporting "
                       f"itself idle at {_fmt(idle[0].t)} after its last motion line.",
                       [head, f"{_fmt(idle[0].t)} {idle[0].text}"])
    drops = [e for e in f.events if e.kind == "link" and e.t >= t_sent and
             e.extra.get("kind") in ("disconnect", "error", "close")]
    if drops:
        d = drops[0]
        return Outcome("stopped", f"The link dropped at {_fmt(d.t)} ({d.text}) after the "
                       "host's last line, with no program end and no idle report before it; "
                       "nothing was sent or answered after.", [head, f"{_fmt(d.t)} {d.text}"],
                       by="link", lead="link-lost")
    if running:
        r = running[-1]
        return Outcome("stopped", f"The sender sent its last line at {_fmt(t_sent)} and went "
                       f"quiet while the unit was still running ({r.text} at {_fmt(r.t)}), "
                       "with no program end and no idle report after: it left mid-job (a job "
                       "without an end word that ends there looks the same).",
                       [head, f"{_fmt(r.t)} {r.text}", "no program end, no idle report after "
                        "the last answer"], by="sender", lead="sender-stopped")
    left = [e for e in f.events if e.kind == "sender-closed" and e.t >= t_sent]
    return Outcome("ended", f"Every line was answered ({head}) and the host then went quiet"
                   + (f", closing its port at {_fmt(left[0].t)}" if left else "")
                   + ": no program end and no idle report in the capture, so whether the job "
                   "was whole it cannot tell (a job without an end word ends so; so does a "
                   "sender stopped between lines).",
                   [head, "the unit's state after the last answer is not in the capture"]
                   + ([f"{_fmt(left[0].t)} {left[0].text}"] if left else []))
