"""One sending session against an emulated unit, optionally recorded to an MCAP capture.

This is what ``conform send JOB --target emu:VARIANT --record FILE`` runs and what made the
sample captures in ``captures/``: the in-process reference unit on a virtual clock (an hour
of machining takes seconds), the link model of :mod:`conform.families.gve.sender.links`, and the
capture ``Recorder`` fed with the virtual times.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.families.gve.sender.core import Sender
from conform.families.gve.sender.job import Item
from conform.families.gve.sender.links import LinkModel, run_emulated

EPOCH = 1_750_000_000.0  # virtual sessions start at a fixed, readable date (2025-06-15)


@dataclass
class SendResult:
    sender: Sender
    end: float
    position: tuple[int, ...]
    record: Path | None = None
    meta: dict[str, Any] = field(default_factory=dict)


class _VirtualClock:
    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def send_emulated(items: list[Item], variant: Any, dialect: Any, *, policy: str = "careful",
                  checksums: bool = False, packet: int = 1, link: LinkModel | None = None,
                  answer_delay: float = 0.0003, record: str | os.PathLike[str] | None = None,
                  timeout: float = 0.25, queue_wait: float = 0.02,
                  note: str = "", limit: float = 3600.0,
                  progress: Callable[[Sender], Callable[[float], None]] | None = None
                  ) -> SendResult:
    from conform.families.gve.unit import Unit

    link = link or LinkModel()
    clock = _VirtualClock(EPOCH)
    unit = Unit(variant, dialect, t0=EPOCH, answer_delay=answer_delay)
    sender = Sender(items, variant, policy=policy, checksums=checksums, packet=packet,
                    timeout=max(timeout, 2 * link.latency + 0.05), queue_wait=queue_wait,
                    index_every=dialect["A10"], repeat_echo=dialect["A9"] != "repeat-answer-only")
    meta = {
        "capture_method": "conform send, in-process emulator (virtual clock)",
        "variant": variant.id, "baud": link.baud, "sender_policy": policy,
        "checksums": checksums, "packet": packet, "latency_s": link.latency,
        "noise": link.noise, "seed": link.seed, "answer_delay_s": answer_delay,
        "corrupt_commands": ",".join(map(str, sorted(link.corrupt_commands))),
        "corrupt_answers": ",".join(map(str, sorted(link.corrupt_answers))),
        "tap": "host end of the serial cable (host bytes as sent, unit bytes as received)",
        "dialect": ",".join(f"{k}={v}" for k, v in dialect.changed().items()),
        "note": note,
    }
    rec = None
    path = None
    if record is not None:
        from conform.capture.recorder import Recorder

        path = Path(record)
        if path.exists():
            path.unlink()
        rec = Recorder(path, meta, clock=clock, overwrite_part=True)

    shown = progress(sender) if progress is not None else None

    def tick(t: float) -> None:
        clock.t = t
        if shown is not None:
            shown(t)

    try:
        end = run_emulated(sender, unit, link, rec, t0=EPOCH, limit=limit, on_progress=tick)
        clock.t = end
    finally:
        if rec is not None:
            rec.close({"sender_failed": sender.failed or ""})
    return SendResult(sender, end, tuple(unit.position), path, meta)
