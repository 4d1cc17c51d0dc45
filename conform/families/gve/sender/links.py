"""Drive a ``Sender`` against a target: the in-process unit on virtual time, or a serial port.

``run_emulated`` is an event loop over three clocks (sender timers, the unit's deadlines,
bytes in flight) that models the link: each byte takes 10 bits of the baud rate, a USB
converter adds ``latency`` seconds each way before the host sees (or the wire gets) the
bytes, and line noise flips bits. The optional recorder sees the serial line at the host's
end of the cable: host bytes as they go on the wire, unit bytes as they arrive (noise
included), so the analyser's wire/unit/host split is what the cable would show.
``run_serial`` drives a real port (any pyserial URL or a pty path) on the wall clock.
"""

from __future__ import annotations

import heapq
import random
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from conform.families.gve.sender.core import Sender

BITS = 10


@dataclass
class LinkModel:
    baud: int = 115200
    latency: float = 0.0  # per direction, converter (host side)
    noise: float = 0.0  # probability that a byte is damaged, each direction
    seed: int = 1
    corrupt_commands: set[int] = field(default_factory=set)  # host writes (0-based) to damage
    corrupt_answers: set[int] = field(default_factory=set)  # unit lines (0-based) to damage


def _damage(data: bytes, rng: random.Random, p: float, force: bool, first: bool) -> bytes:
    if not force and p <= 0:
        return data
    out = bytearray(data)
    for i in range(len(out)):
        if out[i] == 13:
            continue
        if rng.random() < p:
            out[i] ^= 1 << rng.randrange(7)
            if out[i] == 13:
                out[i] = 0x3F
    if force:
        # damage the first byte (a command the unit ignores) or a digit (a garbled answer)
        i = 0 if first else max(0, min(len(out) - 2, 0))
        out[i] = ord("?") if first else ord("x")
    return bytes(out)


def run_emulated(sender: Sender, unit: Any, link: LinkModel, recorder: Any = None,
                 t0: float = 0.0, limit: float = 3600.0,
                 on_progress: Callable[[float], None] | None = None) -> float:
    """Run until the sender is done (or ``limit`` seconds); return the end time."""
    rng = random.Random(link.seed)
    byte_t = BITS / link.baud
    events: list[tuple[float, int, str, bytes]] = []  # (time, seq, kind, data)
    seq = 0
    host_free = unit_free = t0  # when each direction of the wire is free
    writes = answers = 0
    t = t0
    sender.start(t)

    def push(at: float, kind: str, data: bytes) -> None:
        nonlocal seq
        heapq.heappush(events, (at, seq, kind, data))
        seq += 1

    while not sender.done and t - t0 < limit:
        data = sender.poll(t)
        if data:
            start = max(t + link.latency, host_free)
            end = start + len(data) * byte_t
            host_free = end
            if recorder is not None:
                recorder.chunk("host", data, end, start)
            damaged = _damage(data, rng, link.noise, writes in link.corrupt_commands, True)
            writes += 1
            push(end, "unit_rx", damaged)
            continue
        # the next thing that happens
        cands = [e[0] for e in events[:1]]
        for d in (sender.deadline(), unit.next_deadline()):
            if d is not None:
                cands.append(d)
        if not cands:
            break
        t = max(t, min(cands))
        if events and events[0][0] <= t:
            at, _s, kind, payload = heapq.heappop(events)
            if kind == "unit_rx":
                unit.receive(payload, at)
            else:
                sender.receive(payload, at)
            _drain_unit(unit, t)
        for due, out in unit.poll(t):
            for line in _split_keep(out):
                start = max(due, unit_free)
                end = start + len(line) * byte_t
                unit_free = end
                damaged = _damage(line, rng, link.noise, answers in link.corrupt_answers, False)
                answers += 1
                if recorder is not None:
                    recorder.chunk("unit", damaged, end, start)
                push(end + link.latency, "host_rx", damaged)
        if on_progress is not None:
            on_progress(t)
    return t


def _drain_unit(unit: Any, t: float) -> None:
    del unit, t


def _split_keep(data: bytes) -> list[bytes]:
    """Answer bytes per line (``>`` may give two at once), terminators kept."""
    parts = data.split(b"\r")
    out = [p + b"\r" for p in parts[:-1]]
    if parts[-1]:
        out.append(parts[-1])
    return out


def run_serial(sender: Sender, port: Any, latency: float = 0.0,
               on_progress: Callable[[float], None] | None = None,
               clock: Callable[[], float] = time.monotonic) -> float:
    """Drive ``sender`` over an open pyserial-like ``port`` on the wall clock."""
    t = clock()
    sender.start(t)
    while not sender.done:
        t = clock()
        data = sender.poll(t)
        if data:
            if latency:
                time.sleep(latency)
            port.write(data)
            continue
        dl = sender.deadline()
        wait = 0.05 if dl is None else max(0.0, min(0.05, dl - t))
        port.timeout = wait
        got = port.read(max(1, getattr(port, "in_waiting", 0) or 1))
        if got:
            more = port.read(port.in_waiting) if getattr(port, "in_waiting", 0) else b""
            if latency:
                time.sleep(latency)
            sender.receive(got + more, clock())
        if on_progress is not None:
            on_progress(t)
    return clock()


def halt_and_delete(sender: Sender, port: Any, timeout: float = 5.0) -> list[bytes]:
    """After Ctrl-C: send H (wait for its late answer), then D; return the answers."""
    answers = []
    for line in sender.interrupt_lines():
        port.write(line)
        port.timeout = timeout
        answers.append(port.read_until(b"\r"))
    return answers
