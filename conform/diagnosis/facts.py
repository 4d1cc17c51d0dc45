"""What a family tells the diagnosis about a session, in words no family owns.

A family's ``diagnosis_facts`` hook turns its own analysis of a capture into :class:`Facts`:
the lines the host sent and what came back (:class:`Exchange`), the moments that matter
(:class:`Event`, one of :data:`EVENT_KINDS`) and the sizes of the unit's receive buffer and
motion queue. The engine (conform.diagnosis.causes) reads only these, so the same rules judge
every family. Times are seconds from the start of the capture.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from conform.jsondoc import JsonObject

EVENT_KINDS = {
    "alarm": "the unit reported an alarm, an interrupt or a halt of its own",
    "error-answer": "the unit refused a line (an error answer)",
    "noise": "damaged bytes: a checksum mismatch, a garbled answer, garbage on the line",
    "misuse": "the host broke a rule of the protocol (simplex, a blind repeat, ...)",
    "starved": "the unit's motion queue ran dry while the host had more to send",
    "overflow": "more bytes in flight than the unit's receive buffer holds",
    "full": "the unit said its queue or buffer was full (the host must wait for room)",
    "hold": "the unit is holding (not executing) while work waits in it",
    "loss": "a line or byte is known lost on the way (a hazard)",
    "unguarded": "the host stopped marking its lines so that the unit can tell one lost or "
                 "damaged and ask for it again (sequence numbers, checksums): from then on "
                 "such a line goes unnoticed",
    "reset": "the unit restarted (asked or not)",
    "link": "the link dropped, failed or came back (a recorded link event)",
    "sender-closed": "the sender closed its port",
    "job-end": "the job's own end (a program end word)",
    "halt": "the sender halted the unit itself (feed hold with reset, emergency stop, the "
            "family's halt or reset command)",
    "idle": "the unit reported itself idle or ready with nothing left to run",
    "running": "the unit reported itself still running its work",
    "deaf": "the unit answered none of the host's polls over a stretch (polls it always "
            "answers at once, whatever it is doing)",
}


@dataclass(slots=True)
class Exchange:
    """One line the host sent and what the unit answered to it."""

    n: int                      # the line's index among the host's lines (from 0)
    text: str
    t_sent: float
    t_answer: float | None = None
    answer: str | None = None
    accepted: bool | None = None    # True: done/ok; False: refused; None: no answer
    motion: bool = False            # a line that moves the machine
    in_flight: int = 0              # bytes the unit had not yet taken when it was sent
    full: bool = False              # refused for want of room (send again later)


@dataclass(slots=True)
class Event:
    """Something that happened: a finding of the family's analysis in neutral words."""

    t: float
    kind: str
    text: str
    rule: str = ""              # the clause or rule that fired
    t_end: float | None = None
    line: int | None = None     # the host line it concerns
    extra: JsonObject = field(default_factory=dict)

    def to_json(self) -> dict[str, object]:
        return {k: v for k, v in asdict(self).items() if v not in (None, "", {})}


@dataclass
class Facts:
    """A session as the diagnosis sees it."""

    family: str
    variant: str
    path: str
    duration: float
    exchanges: list[Exchange]
    events: list[Event]
    t0: float = 0.0                     # the capture's start on the recorder's clock
    host_times: list[float] = field(default_factory=list)   # each host read, s
    unit_times: list[float] = field(default_factory=list)   # each unit read, s
    rx_capacity: int | None = None      # bytes the unit's receive buffer holds
    queue_capacity: int | None = None   # motion blocks its queue holds
    queue_unit: str = "blocks"
    answer_time: float = 0.5            # an answer later than this is a wait, not a reply
    notes: list[str] = field(default_factory=list)
    family_data: Any = None             # the family's own analysis, for its other hooks
    damaged: str | None = None          # what is wrong with the capture file, when it is
    lines_kept: bool = True             # False: too long, ``exchanges`` is empty


@dataclass(slots=True)
class ParsedLine:
    """A line as the unit would have read it, next to the host line(s) it came from.

    ``fate``: ``intact``, ``dropped`` (nothing of it reached the parser), ``damaged`` (bytes
    lost or changed and the unit refused it), ``damaged-valid`` (bytes lost or changed and it
    is still a valid line: executed wrong), ``merged`` (its end was lost: read with the next
    one), ``truncated`` (cut short: too long, or the line timed out)."""

    fate: str
    host: list[int]             # host line indices it came from
    sent: str                   # what the host sent (those lines joined)
    parsed: str                 # what the unit read ("" when dropped)
    t: float
    why: str = ""
    echo: str | None = None     # what the unit echoed of it, where it echoes

    def to_json(self) -> dict[str, object]:
        return {k: v for k, v in asdict(self).items() if v is not None}


@dataclass
class ResumePoint:
    """Where a stopped job can safely go on."""

    last_executed: int | None         # host line index known executed
    last_acknowledged: int | None     # host line index last answered as accepted
    uncertain: list[int]              # lines between: maybe executed, maybe not
    preamble: list[str]               # lines that restore the modal state, in order
    resume_from: int | None           # the host line to resume at
    command: str                      # how to resume
    evidence: list[str] = field(default_factory=list)
    state: dict[str, object] = field(default_factory=dict)    # the modal state, named

    def to_json(self) -> dict[str, object]:
        return asdict(self)
