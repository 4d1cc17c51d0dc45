"""A target whose traffic also goes to a capture: what a family's reference sender records
with ``conform send --record`` — host bytes when written, unit bytes when read, i.e. the host
end of the cable — on the target's clock (an emulated unit's virtual time from a fixed date,
a port's wall clock as dates).

    taped = RecordedTarget.open(target, "session.mcap", {"variant": ..., "baud": ...})
    ... taped.send(b"..."); taped.receive(deadline) ...
    taped.close({"job_lines": 120})     # finishes the capture (shielded from a second signal)
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from conform.capture.recorder import Recorder
    from conform.conformance.target import Target
    from conform.families import Family

EPOCH = 1_750_000_000.0   # an emulated session's virtual clock starts at this date (2025-06-15)
TAP = "host end of the serial cable (host bytes as sent, unit bytes as read)"


class RecordedTarget:
    """``send``/``receive``/``drain``/``now`` of the wrapped target, every byte also given to
    ``recorder``; the bytes ``Target.send`` drains before it writes are kept for the next
    ``receive``, so a sender reading through this never misses an answer."""

    def __init__(self, target: Target, recorder: Recorder | None = None, base: float = 0.0) -> None:
        self.target = target
        self.recorder = recorder
        self.base = base
        self.emulated = target.emulated
        self._held = b""

    @classmethod
    def open(cls, target: Target, path: str | None, metadata: Mapping[str, object]
             ) -> RecordedTarget:
        """Wrap ``target``; with a ``path``, record to it (the caller has checked it free)."""
        from conform.capture.recorder import Recorder, WallClock

        base = EPOCH if target.emulated else WallClock()() - target.now()
        if path is None:
            return cls(target, None, base)
        how = ", in-process emulator (virtual clock)" if target.emulated else ""
        meta = {"tap": TAP, **metadata}
        meta["capture_method"] = f"{meta.get('capture_method', 'conform send')}{how}"
        return cls(target, Recorder(path, meta, clock=lambda: base + target.now()), base)

    def close(self, summary: Mapping[str, object] | None = None) -> None:
        """Finish the capture and close the target, even when a second signal comes."""
        from conform.stops import shield

        with shield():
            try:
                if self.recorder is not None:
                    self.recorder.close(summary)
            finally:
                self.target.close()

    def now(self) -> float:
        return self.target.now()

    def _tape(self, direction: str, data: bytes, t: float, t_first: float | None = None) -> None:
        if self.recorder is not None and data:
            self.recorder.chunk(direction, data, self.base + t,
                                None if t_first is None else self.base + t_first)

    def send(self, data: bytes) -> tuple[float, bytes]:
        t, stray = self.target.send(data)
        self._tape("unit", stray, t)
        self._held += stray
        self._tape("host", data, self.target.now(), t)
        return t, b""

    def receive(self, deadline: float) -> bytes:
        if self._held:
            data, self._held = self._held, b""
            return data
        data = self.target.receive(deadline)
        self._tape("unit", data, self.target.now())
        return data

    def drain(self) -> bytes:
        data = self._held + self.target.drain()
        self._held = b""
        return data


@contextmanager
def sending_to(fam: Family, target: str, variant: str, *, job: str, job_lines: int, baud: int,
               record: str | None, allow_motion: bool, metadata: Mapping[str, object]
               ) -> Iterator[RecordedTarget]:
    """What a family's ``send_job`` does around its streamer: refuse a non-emulated target
    without ``--allow-motion`` (nothing sent), open ``target`` (``emu:`` as ``variant``'s
    emulator), record it when asked, and finish the capture however the stream ends."""
    from conform.conformance.target import parse_target
    from conform.errors import UserError

    emulated = parse_target(target)[0] == "emu"
    if not emulated and not allow_motion:
        raise UserError(f"sending {job} to {target} moves the machine: add --allow-motion "
                        "(nothing was sent)")
    tgt, _ = fam.open_target(f"emu:{variant}" if emulated else target, baud=baud,
                             permissions=None)
    try:
        taped = RecordedTarget.open(tgt, record, {
            "variant": variant, "baud": baud, "target": target, "job": Path(job).name,
            **metadata})
    except BaseException:
        tgt.close()
        raise
    try:
        yield taped
    finally:
        taped.close({"job_lines": job_lines})
