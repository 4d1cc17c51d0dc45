"""Why did it stop? A diagnosis of a capture: the cause ranked first, the lines as the unit
read them, and where a stopped job can resume.

    d = diagnose("session.mcap")
    d.headline()            # one sentence
    d.to_json()["causes"]   # most likely first

The engine names no family: the capture's family (``conform.families``) turns its own analysis
into neutral facts (``diagnosis_facts``), replays the host's bytes through its model of the
unit's reception (``reception``) and finds the resume point (``resume_state``);
:mod:`.causes` ranks the causes from the facts alone.
"""

from __future__ import annotations

import gc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from conform.diagnosis import calibration
from conform.diagnosis.causes import ADVICE, Cause, find_stalls, rank
from conform.diagnosis.facts import Event, Facts, ParsedLine, ResumePoint
from conform.diagnosis.outcome import Outcome, decide, prove_losses
from conform.errors import UserError

if TYPE_CHECKING:
    from conform.analysis.rawread import RawCapture
    from conform.families import AnalysisResult, Family

INCOMPLETE = "capture incomplete"   # the note that starts what a cut-short capture says

FORMAT = "conform-diagnosis/1"
RECEPTION_MAX = 200_000     # host lines up to which the unit's reception is replayed

__all__ = ["Diagnosis", "diagnose", "Facts", "Event", "ParsedLine", "ResumePoint", "Cause",
           "Outcome"]


@dataclass
class Diagnosis:
    path: str
    family: str
    facts: Facts
    causes: list[Cause]             # what stopped it, most likely first (none: completed)
    reception: list[ParsedLine] | None = None
    resume: ResumePoint | None = None
    notes: list[str] = field(default_factory=list)
    outcome: Outcome | None = None
    hazards: list[Cause] = field(default_factory=list)     # seen on the way, not the end

    def lead_key(self) -> str:
        """How it leads, as the calibration table names it: the stop cause's kind and rule,
        else the outcome."""
        if self.causes:
            return self.causes[0].key
        return self.outcome.key if self.outcome is not None else "outcome/none"

    def lead(self) -> Cause | None:
        """What the diagnosis puts first: the stop cause, else the first hazard."""
        return self.causes[0] if self.causes else (self.hazards[0] if self.hazards else None)

    def headline(self) -> str:
        """The diagnosis in one sentence: the outcome first, then what caused it."""
        o = self.outcome
        title = o.title() if o is not None else "Session"
        if self.causes:
            c = self.causes[0]
            text = f"{title}: most likely {c.kind} ({c.shown()}): {c.summary}"
            if o is not None and o.kind == "capture-damaged":
                text = f"{title}: {o.summary} Within it: {c.kind}: {c.summary}"
            return text
        text = f"{title}: {o.summary}" if o is not None else title + "."
        if self.hazards:
            kinds = list(dict.fromkeys(h.kind for h in self.hazards))
            text += f" Hazards on the way: {', '.join(kinds)}."
        return text

    def to_json(self) -> dict[str, object]:
        f = self.facts
        return {
            "format": FORMAT, "path": self.path, "family": f.family, "variant": f.variant,
            "headline": self.headline(),
            "outcome": None if self.outcome is None else self.outcome.to_json(),
            "lead": self._lead_json(),
            "causes": [c.to_json() for c in self.causes],
            "hazards": [c.to_json() for c in self.hazards],
            "session": {"duration_s": round(f.duration, 6), "lines": len(f.exchanges),
                        "answered": sum(1 for e in f.exchanges if e.answer is not None),
                        "rx_capacity": f.rx_capacity, "queue_capacity": f.queue_capacity,
                        "stalls": [{"t_start": round(s.t_start, 6), "t_end": round(s.t_end, 6),
                                    "at_end": s.at_end} for s in find_stalls(f)]},
            "timeline": [ev.to_json() for ev in sorted(f.events, key=lambda e: e.t)],
            "reception": None if self.reception is None else
            [p.to_json() for p in self.reception],
            "resume": None if self.resume is None else self.resume.to_json(),
            "notes": f.notes + self.notes,
        }

    def _lead_json(self) -> dict[str, object]:
        m = self.causes[0].measured if self.causes else \
            (self.outcome.measured if self.outcome is not None else None)
        return {"key": self.lead_key(), "confidence": None if m is None else round(m[0] / m[1], 3),
                "sessions": None if m is None else m[1]}


def _family_of(path: str, variant: str | None) -> Family:
    from conform.families import default_family, family
    from conform.families.peek import peek_family

    d, _meta = peek_family(path, variant)
    if d is None:
        return default_family()
    if d.family == "unknown":
        raise UserError(f"{path}: protocol unknown ({d.why}); nothing to diagnose")
    return family(d.family)


def _link_events(raw: RawCapture, t0: float) -> list[Event]:
    """The capture's own link events: the proxy's sender pty closing is the sender leaving."""
    method = str(raw.metadata.get("conform.session", {}).get("capture_method", ""))
    out = []
    for link in raw.link_events:
        kind, side = str(link.get("kind", "")), str(link.get("side", ""))
        t = float(link.get("t", t0)) - t0
        detail = str(link.get("detail", ""))
        if kind in ("open",) or (kind == "close" and side == "session"):
            continue
        if side == "host" and kind in ("disconnect", "close") and method == "proxy":
            out.append(Event(t, "sender-closed", f"the sender closed its port ({detail})",
                             "capture link event"))
            continue
        out.append(Event(t, "link", f"{kind} ({side}): {detail}".strip(),
                         "capture link event", extra={"kind": kind, "side": side}))
    return out


@contextmanager
def _no_gc() -> Iterator[None]:
    """The cyclic collector paused while records are made in bulk (it would scan them again
    and again for cycles they do not have), resumed as it was."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def diagnose(path: str, *, variant: str | None = None, analysis: AnalysisResult | None = None,
             family: str | None = None) -> Diagnosis:
    """Diagnose one capture file (``analysis``: its family's analysis, when already made;
    ``family``: its family's name, when already known)."""
    from conform.analysis.stream import read_raw
    from conform.families import family as family_named

    fam = family_named(family) if family else _family_of(path, variant)
    facts_hook = getattr(fam, "diagnosis_facts", None)
    raw = read_raw(path)
    with _no_gc():      # a long capture makes a million small records that never cycle
        facts = facts_hook(raw, path, variant=variant, analysis=analysis) if facts_hook \
            else None
    if facts is None:
        raise UserError(f"{path}: the {fam.name} family gives no diagnosis")
    if not facts.host_times:
        facts.host_times = sorted((raw.host.t_read - facts.t0).tolist())
    if not facts.unit_times:
        facts.unit_times = sorted((raw.unit.t_read - facts.t0).tolist())
    facts.events += _link_events(raw, facts.t0)
    # the capture lasts until it was closed, not until its last byte: a silent end counts
    ends = [float(x.get("t", facts.t0)) - facts.t0 for x in raw.link_events]
    facts.duration = max([facts.duration, *ends])
    if not raw.status.complete:
        facts.damaged = str(raw.status.problem or "incomplete")
        facts.notes.append(f"{INCOMPLETE}: {raw.status.problem}; diagnosed what is intact")
    with _no_gc():
        d = judge(path, fam.name, facts)
    rec = getattr(fam, "reception", None)
    if rec is not None and len(facts.exchanges) <= RECEPTION_MAX:
        d.reception = rec(raw, variant=facts.variant)
    elif rec is not None:
        d.notes.append(f"the lines as the unit read them are not replayed for a capture of "
                       f"{len(facts.exchanges)} lines (at most {RECEPTION_MAX})")
    res = getattr(fam, "resume_state", None)
    if res is not None and d.outcome is not None and d.outcome.kind != "completed":
        d.resume = res(raw, facts, variant=facts.variant)
    return d


def judge(path: str, family: str, facts: Facts) -> Diagnosis:
    """The outcome from the facts, then the causes that fit it: a completed session has no
    stop cause (what the ranking found becomes hazards, a stall at its end dropped: that is
    the host done); a damaged capture's end is not judged; otherwise the cause the outcome
    names leads."""
    d = _judged(path, family, facts)
    calibration.apply(d)
    return d


def _judged(path: str, family: str, facts: Facts) -> Diagnosis:
    prove_losses(facts)
    ranked = rank(facts)
    o = decide(facts, ranked)
    if o.kind in ("completed", "ended", "capture-damaged", "findings-only"):
        return Diagnosis(path, family, facts, [], outcome=o,
                         hazards=[c for c in ranked if not c.at_end])
    causes = list(ranked)
    if o.lead is not None:
        lead = next((c for c in causes if c.kind == o.lead), None)
        if lead is None:
            lead = Cause(o.lead, 0.8, facts.duration, facts.duration, o.evidence,
                         ADVICE[o.lead], o.summary, at_end=True, rule="outcome")
        else:
            causes.remove(lead)
            lead.confidence = max(lead.confidence, 0.8)
            if o.kind in ("stopped", "aborted"):
                lead.rule = "outcome"       # the outcome's evidence, not the rule's
                lead.summary = o.summary
                lead.evidence = [*o.evidence, *(x for x in lead.evidence
                                                if x not in o.evidence)]
        causes.insert(0, lead)
    stop = [c for c in causes if c.at_end or c is causes[0]]
    return Diagnosis(path, family, facts, stop, outcome=o,
                     hazards=[c for c in causes if c not in stop])


def headline_for(path: str, analysis: AnalysisResult, family: str | None,
                 echo: Callable[[str], object]) -> None:
    """``conform analyze``: the diagnosis in one sentence first, and kept on the analysis for
    the top of its report (``analysis.diagnosis``); a capture it cannot judge says why.
    An analysis that streamed its tables (too long to keep) is not read whole again here."""
    if getattr(analysis, "whole", True) is False:
        echo(f"diagnosis: not made for a capture this long (`conform diagnose {path}`)")
        return
    try:
        d = diagnose(path, analysis=analysis, family=family)
    except UserError as exc:
        echo(f"diagnosis: none ({exc})")
        return
    except Exception as exc:  # noqa: BLE001 - the analysis stands without its diagnosis
        echo(f"diagnosis: failed ({type(exc).__name__}: {exc}); the analysis follows")
        return
    # kept on whatever result the family made, for the top of its report
    setattr(analysis, "diagnosis", d.to_json())  # noqa: B010
    echo(f"diagnosis: {d.headline()}")
