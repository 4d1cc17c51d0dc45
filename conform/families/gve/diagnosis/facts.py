"""The GVE analysis of a capture as the diagnosis's neutral facts.

Strictly simplex (GVE64 §13.3): one command in flight, so the bytes in flight are the
command's own; the motion queue holds ``Variant.queue`` vectors (§13.5.2). An answer digit
with bit 3 set (INTA, §13.7) to anything but the host's own halt ``H`` means an enabled
input interrupt braked the motion: the unit's alarm.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa

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
    if d is None:
        return []
    bodies = d.lines.bodies
    blob = _joined(bodies)
    if blob is not None and blob.isascii() and b"\\" not in blob:
        text = blob.decode("ascii")
        texts = text.split("\r")
        if len(texts) == len(bodies) and text.replace("\r", "").isprintable():
            return texts
    return [escape_bytes(b) for b in bodies.to_pylist()]


def _joined(bodies: Any) -> bytes | None:
    """``b"\\r".join(bodies)`` straight from the array's buffers, without a million bytes
    objects on the way; None where the array is not plain (nulls, other offsets, empty)."""
    bufs = bodies.buffers()
    if not len(bodies) or bodies.null_count or bodies.type != pa.binary() or bufs[2] is None:
        return None
    offsets = np.frombuffer(bufs[1], np.int32)[bodies.offset:bodies.offset + len(bodies) + 1]
    data = np.frombuffer(bufs[2], np.uint8)[offsets[0]:offsets[-1]]
    return np.insert(data, offsets[1:-1] - offsets[0], ord("\r")).tobytes()


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
        host = _texts(a, "host")
        unit = _texts(a, "unit")
        # the columns at once (a long capture has a million lines); one pass makes the
        # exchanges, a second visits only the lines that make an event
        col = {c: ex_df[c].to_numpy() for c in ("name", "status", "answer_kind", "code",
                                                  "inta", "answer_checksum")}
        answered = col["status"] == "answered"
        clean = answered & (col["answer_kind"] == "answer")
        code = np.where(answered, col["code"], -1)
        motion = np.isin(col["name"], MOTION)
        t_sent = (ex_df["t_cmd_last"].to_numpy() - t0).tolist()
        t_ans = (ex_df["t_ans_last"].to_numpy() - t0).tolist()
        frames = ex_df["frame"].tolist()
        a_frames = ex_df["answer_frame"].tolist()
        for frame, ans_ok, a_frame, mot, ts, ta, size, ok, full in zip(
                frames, answered.tolist(), a_frames, motion.tolist(), t_sent,
                t_ans, ex_df["cmd_bytes"].tolist(), (clean & (code == 0)).tolist(),
                (clean & (code == 1) & motion).tolist(), strict=True):    # §13.7 code 1
            exchanges.append(Exchange(frame, host[frame].removesuffix("\\r").rstrip("\r"), ts,
                                      ta if ans_ok else None,
                                      unit[a_frame].removesuffix("\\r") if ans_ok else None,
                                      ok if ans_ok else None, mot, size, full=full))
        # a damaged answer's digit says nothing: its checksum must hold where there is one
        inta = col["inta"].astype(bool) & clean & \
            ~np.isin(col["answer_checksum"], (CS_BAD, CS_MISSING))
        name = col["name"]
        rise = inta & ~np.concatenate(([False], inta[:-1])) & (name != "H")
        halt = np.isin(name, HALT)
        poll = ~halt & (name == "F") & clean
        for i in np.flatnonzero(rise | halt | poll).tolist():
            e = exchanges[i]
            frame, text, answer = e.n, e.text, e.answer
            if rise[i]:
                events.append(Event(e.t_answer or e.t_sent, "alarm",
                                    f"the unit answered `{answer}` to `{text}`: INTA, an "
                                    "input interrupt braked the motion",
                                    "GVE64 §13.7 (answer bit 3 INTA), §13.5.9", line=frame))
            if halt[i]:
                events.append(Event(e.t_sent, "halt", f"the host sent `{text}` ("
                                    + ("halt the running vector" if name[i] == "H" else "reset")
                                    + ")", "GVE64 §13.5.9, §13.5.13", line=frame))
            elif poll[i] and answer and "," in answer:
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
