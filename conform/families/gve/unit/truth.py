"""Ground truth: what a reference unit accepted and executed, recorded beside a capture.

A capture shows what crossed the wire; whether the machine moved twice or skipped a vector
is a question about the unit. ``GroundTruth(unit)`` wraps the unit's vector and queue
handlers (``C``, ``L``, ``D``, ``K``, ``R``, ``H``, ``G``, ``J``) and its motion executor's
completion log, so that after a session it can say, as facts: every vector accepted (in
order, with its kind, pulses and time), which of them finished executing, which ``D``
deleted, the interrupts, and the final position, queue and INTA/RUN. It changes nothing the
unit does; the emulator writes it as JSON next to its recording (``--truth``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.families.gve.unit.model import OK, Unit

VECTORS = ("C", "L")
EVENTS = ("D", "K", "R", "H", "G", "J")


@dataclass
class Accepted:
    """One vector the unit took into its queue."""

    index: int  # 0-based order of acceptance
    kind: str  # C or L
    vector: tuple[int, ...]
    t: float
    key: tuple[int, int]  # (executor epoch, executor sequence number)
    executed: float | None = None  # when it finished
    deleted: bool = False
    starved: bool = False  # it started from rest because the queue had run dry before it


@dataclass
class GroundTruth:
    unit: Unit
    t0: float = 0.0
    accepted: list[Accepted] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    _epoch: int = 0
    _log: list[Any] = field(default_factory=list)
    _by_key: dict[tuple[int, int], Accepted] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in VECTORS:
            self._wrap(name, self._vector)
        for name in EVENTS:
            if name in self.unit.handlers:
                self._wrap(name, self._event)
        self._attach()

    # ------------------------------------------------------------------ hooks
    def _wrap(self, name: str, hook: Any) -> None:
        inner = self.unit.handlers[name]

        def wrapped(args: tuple, t: float) -> Any:
            before = self._state()
            reply = inner(args, t)
            hook(name, args, t, reply, before)
            return reply

        self.unit.handlers[name] = wrapped

    def _attach(self) -> None:
        ex = self.unit.executor
        if ex.log is None:
            ex.log = self._log = []
        else:
            self._log = ex.log

    def _state(self) -> tuple[int, bool]:
        return self.unit.queue_len, self.unit.inta

    def _vector(self, name: str, args: tuple, t: float, reply: Any, before: Any) -> None:
        if reply != OK or not isinstance(reply, int):
            return
        seq = self.unit.executor._seq - 1  # noqa: SLF001 - the push just made
        a = Accepted(len(self.accepted), name, tuple(int(x) for x in args), t,
                     (self._epoch, seq))
        self.accepted.append(a)
        self._by_key[a.key] = a

    def _event(self, name: str, args: tuple, t: float, reply: Any, before: Any) -> None:
        code = reply if isinstance(reply, int) else (reply[0] if isinstance(reply, tuple)
                                                    else OK)
        queued, inta = before
        self.events.append({"t": round(t - self.t0, 6), "command": name, "code": int(code),
                            "queue_before": queued, "inta_before": inta})
        if code != OK:
            return
        if name in ("D", "J"):
            self.sync()
            for a in self.accepted:
                if a.executed is None:
                    a.deleted = True
        if name == "J":
            self._epoch += 1
            self._attach()

    def interrupt(self, what: str, t: float) -> None:
        """Note an input event (the control socket's ``press stop``...)."""
        self.events.append({"t": round(t - self.t0, 6), "command": what, "code": 0,
                            "queue_before": self.unit.queue_len, "inta_before": self.unit.inta})

    # ------------------------------------------------------------------ results
    def sync(self) -> None:
        """Mark the vectors the executor has finished since the last call."""
        log, self._log[:] = list(self._log), []
        for c in log:
            a = self._by_key.get((self._epoch, c.seq))
            if a is not None:
                a.executed = c.t_end
                a.starved = c.starved

    def to_dict(self) -> dict[str, Any]:
        self.sync()
        u = self.unit
        return {
            "variant": u.variant.id,
            "accepted": [{"index": a.index, "kind": a.kind, "vector": list(a.vector),
                          "t": round(a.t - self.t0, 6),
                          "executed": None if a.executed is None else round(a.executed - self.t0, 6),
                          "deleted": a.deleted, "starved": a.starved} for a in self.accepted],
            "events": self.events,
            "final": {"position": list(u.position), "queue": u.queue_len, "inta": bool(u.inta),
                      "run": bool(u.run), "checksum": bool(u.checksum_on),
                      "executed": sum(a.executed is not None for a in self.accepted),
                      "starvations": sum(a.starved for a in self.accepted)},
        }

    def write(self, path: str | os.PathLike[str]) -> Path:
        p = Path(path)
        p.write_text(dumps(self.to_dict()), encoding="utf-8")
        return p


def dumps(d: dict[str, Any]) -> str:
    """JSON with one line per accepted vector and per event (readable, diff-friendly)."""
    head = {k: v for k, v in d.items() if k not in ("accepted", "events")}
    out = [json.dumps(head)[:-1] + ","]
    for key in ("events", "accepted"):
        rows = [json.dumps(x) for x in d.get(key, [])]
        out.append(f' "{key}": [' + ("\n  " + ",\n  ".join(rows) + "\n ]" if rows else "]")
                   + ("," if key == "events" else ""))
    return "\n".join(out) + "\n}\n"
