"""The GVE analysis of a capture as the diagnosis's neutral facts.

Strictly simplex (GVE64 §13.3): one command in flight, so the bytes in flight are the
command's own; the motion queue holds ``Variant.queue`` vectors (§13.5.2). An answer digit
with bit 3 set (INTA, §13.7) to anything but the host's own halt ``H`` means an enabled
input interrupt braked the motion: the unit's alarm.
"""

from __future__ import annotations

from typing import Any

from conform.diagnosis.facts import Event, Exchange, Facts
from conform.families.gve.analysis.frames import CS_BAD, CS_MISSING

EVENT_OF = {  # GVE finding kind -> neutral event kind
    "checksum-error": "noise", "garbled-answer": "noise", "garbage-sent": "noise",
    "simplex-violation": "misuse", "blind-resend": "misuse", "double-move": "misuse",
    "lost-vector": "loss", "starvation": "starved", "queue-full-polling": "full",
    "error-code": "error-answer", "reset": "reset",
}
KEEP_LINES = 2_000_000  # command lines the diagnosis keeps whole (beyond: findings only)
MOTION = ("C", "L")
SLOW = ("H", "W")       # answered when the motion ends (§13.3)
HALT = ("H", "J")       # the host's own halt (§13.5.9) and reset (§13.5.13)
RUN_BIT = 0x40          # F's ST6 value: the motion runs (§13.5.12)


def _texts(a: Any, direction: str) -> list[str]:
    """Every line of one direction as escaped text (``Analysis.host_text``), taken out of the
    table at once (a long capture has a million of them): printable lines, nearly all of
    them, are decoded in one piece."""
    from conform.capture.session import escape_bytes

    d = a.host if direction == "host" else a.unit
    bodies = d.lines.bodies.to_pylist() if d is not None else []
    blob = b"\r".join(bodies)
    if blob.isascii() and b"\\" not in blob:
        text = blob.decode("ascii")
        texts = text.split("\r")
        if len(texts) == len(bodies) and text.replace("\r", "").isprintable():
            return texts
    return [escape_bytes(b) for b in bodies]


def analysis_facts(a: Any, path: str) -> Facts:
    """Facts from a finished ``conform.families.gve.analysis.Analysis``."""
    ex_df = a.exchanges
    notes = list(a.notes)
    exchanges: list[Exchange] = []
    events: list[Event] = []
    t0 = a.t0
    if ex_df is None:
        notes.append("capture too long to keep its tables: the diagnosis uses the findings "
                     "only")
    else:
        names = ("frame", "name", "status", "answer_frame", "answer_kind", "code", "inta",
                 "t_cmd_last", "answer_checksum", "t_ans_last", "cmd_bytes")
        host = _texts(a, "host")
        unit = _texts(a, "unit")
        in_inta = False
        for (frame, name, status, a_frame, a_kind, code, inta_bit, t_cmd, a_cs, t_ans,
             size) in zip(*(ex_df[c].tolist() for c in names), strict=True):
            answered = status == "answered"
            text = host[frame].rstrip("\\r").rstrip("\r")
            answer = unit[a_frame].rstrip("\\r") if answered else None
            code = code if answered else -1
            clean = answered and a_kind == "answer"
            motion = name in MOTION
            e = Exchange(frame, text, t_cmd - t0, t_ans - t0 if answered else None,
                         answer, (clean and code == 0) if answered else None,
                         motion, size, full=clean and code == 1 and motion)    # §13.7 code 1
            exchanges.append(e)
            # a damaged answer's digit says nothing: its checksum must hold where there is one
            inta = bool(inta_bit) and clean and a_cs not in (CS_BAD, CS_MISSING)
            if inta and not in_inta and name != "H":
                events.append(Event(e.t_answer or e.t_sent, "alarm",
                                    f"the unit answered `{answer}` to `{text}`: INTA, an "
                                    "input interrupt braked the motion",
                                    "GVE64 §13.7 (answer bit 3 INTA), §13.5.9", line=frame))
            in_inta = inta
            if name in HALT:
                events.append(Event(e.t_sent, "halt", f"the host sent `{text}` ("
                                    + ("halt the running vector" if name == "H" else "reset")
                                    + ")", "GVE64 §13.5.9, §13.5.13", line=frame))
            elif name == "F" and clean and answer and "," in answer:
                try:
                    st6 = int(answer.split(",")[1][:2], 16)
                except ValueError:
                    continue
                running = bool(st6 & RUN_BIT)
                events.append(Event(e.t_answer or e.t_sent, "running" if running else "idle",
                                    f"the unit answered `{answer}` to `{text}`: the motion "
                                    + ("runs" if running else "has ended"),
                                    "GVE64 §13.5.12 (F: ST6)", line=frame))
    first_answer = min((e.t_answer for e in exchanges if e.t_answer is not None), default=None)
    for f in a.findings:
        kind = EVENT_OF.get(f.kind)
        if f.kind == "garbage-sent" and first_answer is not None and \
                float(f.t) < first_answer:
            continue    # before the unit first answered: a sender probing the port, no noise
        if kind == "error-answer" and ("damaged on the way" in f.message or
                                       f.extra.get("code") == 2):
            kind = "noise"      # refused though sent right, or cut short: changed on the way
        if kind is None:
            continue
        line = None
        if f.frames:
            head = str(f.frames[0])
            if head.startswith("host:"):
                line = int(head[5:])
        events.append(Event(float(f.t), kind, f.message, f.clause, line=line,
                            extra={"count": int(f.count)} if f.count > 1 else {}))
    q = a.metrics.get("queue", {})
    return Facts("gve", a.variant.id, path, float(a.metrics["duration_s"]), exchanges, events,
                 t0=t0, rx_capacity=None, queue_capacity=int(q.get("capacity") or
                                                             a.variant.queue),
                 queue_unit="vectors", answer_time=0.5, notes=notes, family_data=a,
                 lines_kept=ex_df is not None)


def facts(raw: Any, path: str, *, variant: str | None = None) -> Facts:
    from conform.families.gve.analysis import analyze

    return analysis_facts(analyze(path, variant=variant, whatif_replays=False,
                                  keep_rows=KEEP_LINES), path)
