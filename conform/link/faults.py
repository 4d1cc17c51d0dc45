"""Fault injection for a serial link: noise, lost bytes, USB-converter latency, garbled
answers and disconnects, reproducible from a seed.

The core, :class:`FaultInjector`, is sans-I/O: ``feed(direction, data, t)`` returns what
arrives at the far end and when, as a list of ``(time, bytes)``; ``disconnect_due(t)`` says
when the link should drop. The emulator uses it on the unit's side of a pty; a reference sender
can wrap its own port with :class:`FaultyEndpoint`. Directions follow the capture format:
``"host"`` is bytes from the host (sender) to the unit, ``"unit"`` the answers.

A fault spec is a comma-separated list (``--faults``)::

    corrupt=1e-3,drop=1e-4,latency=1-16,garble=0.01,disconnect=0.02,downtime=0.5

``corrupt``/``drop``: per-byte probability (a random bit flipped / the byte lost);
``latency``: ms added per transfer, ``LO-HI`` (uniform) or ``N``; ``garble``: per answer line,
probability that a run of its bytes is replaced by noise (answers only unless prefixed);
``disconnect``: mean disconnects per second; ``downtime``: seconds the link stays down.
Prefix ``host.`` or ``unit.`` to set one direction only (``unit.latency=1-16``).
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from conform.errors import UserError

DIRECTIONS = ("host", "unit")


@dataclass(frozen=True)
class DirectionFaults:
    """The faults of one direction."""

    corrupt: float = 0.0
    drop: float = 0.0
    garble: float = 0.0
    latency: tuple[float, float] = (0.0, 0.0)  # seconds

    @property
    def active(self) -> bool:
        return bool(self.corrupt or self.drop or self.garble or self.latency[1])


@dataclass(frozen=True)
class FaultConfig:
    """Faults per direction plus disconnects (rate per second, downtime in seconds)."""

    host: DirectionFaults = field(default_factory=DirectionFaults)
    unit: DirectionFaults = field(default_factory=DirectionFaults)
    disconnect: float = 0.0
    downtime: float = 0.5

    @property
    def active(self) -> bool:
        return self.host.active or self.unit.active or self.disconnect > 0

    @classmethod
    def parse(cls, text: str) -> FaultConfig:
        """Parse a fault spec (module docstring); a mistake is a one-line ``UserError``."""
        per: dict[str, dict[str, Any]] = {d: {} for d in DIRECTIONS}  # float or (lo, hi)
        top: dict[str, float] = {}
        for item in filter(None, (p.strip() for p in text.split(","))):
            key, sep, value = item.partition("=")
            if not sep:
                raise UserError(f"--faults: {item!r} is not key=value")
            key = key.strip().lower()
            prefix, dot, name = key.rpartition(".")
            dirs: tuple[str, ...] = DIRECTIONS
            if dot:
                if prefix not in DIRECTIONS:
                    raise UserError(f"--faults: {key!r}: prefix must be host. or unit.")
                dirs = (prefix,)
            if name in ("disconnect", "downtime"):
                if dot:
                    raise UserError(f"--faults: {key!r} applies to the whole link, no prefix")
                top[name] = _number(key, value, 0.0, 1e9 if name == "downtime" else 1e6)
                continue
            if name == "latency":
                parsed: object = _latency(key, value)
            elif name in ("corrupt", "drop", "garble"):
                parsed = _number(key, value, 0.0, 1.0)
                if name == "garble" and not dot:
                    dirs = ("unit",)
            else:
                raise UserError(f"--faults: unknown fault {name!r} "
                                "(corrupt, drop, latency, garble, disconnect, downtime)")
            for d in dirs:
                per[d][name] = parsed
        return cls(DirectionFaults(**per["host"]), DirectionFaults(**per["unit"]),
                   top.get("disconnect", 0.0), top.get("downtime", 0.5))


def _number(key: str, value: str, lo: float, hi: float) -> float:
    try:
        x = float(value)
    except ValueError:
        raise UserError(f"--faults: {key}={value!r} is not a number") from None
    if not lo <= x <= hi:
        raise UserError(f"--faults: {key}={value} is outside {lo:g}..{hi:g}")
    return x


def _latency(key: str, value: str) -> tuple[float, float]:
    lo_text, _, hi_text = value.removesuffix("ms").partition("-")
    lo = _number(key, lo_text, 0.0, 10_000.0)
    hi = _number(key, hi_text, 0.0, 10_000.0) if hi_text else lo
    if hi < lo:
        raise UserError(f"--faults: {key}={value}: the upper bound is below the lower")
    return (lo / 1000.0, hi / 1000.0)


class FaultInjector:
    """Apply a :class:`FaultConfig` to a byte stream, deterministically from ``seed``."""

    def __init__(self, config: FaultConfig, seed: int | None = None, t0: float = 0.0) -> None:
        self.config = config
        self.seed = seed
        self.rng = random.Random(seed)
        self._last = dict.fromkeys(DIRECTIONS, -float("inf"))
        self.counts = {"corrupted": 0, "dropped": 0, "garbled": 0, "disconnects": 0}
        self._next_drop = self._schedule(t0)
        self.down_until = -float("inf")
        self.unplugged = False   # set by unplug(), taken by a family's reopen hook

    def unplug(self, t: float, downtime: float) -> None:
        """Pull the cable at ``t`` for ``downtime`` seconds (the emulator closes the pty); the
        reopen hook sees ``unplugged`` and restarts the unit as a board that lost power."""
        self.config = FaultConfig(self.config.host, self.config.unit, self.config.disconnect,
                                  downtime)
        self._next_drop = t
        self.unplugged = True
        self.counts["unplugged"] = self.counts.get("unplugged", 0) + 1

    def _schedule(self, t: float) -> float:
        rate = self.config.disconnect
        return t + self.rng.expovariate(rate) if rate > 0 else float("inf")

    def feed(self, direction: str, data: bytes, t: float) -> list[tuple[float, bytes]]:
        """What of ``data`` (sent at ``t``) arrives, and when: a list of (time, bytes)."""
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be 'host' or 'unit', not {direction!r}")
        if not data or t < self.down_until:
            return []
        cfg = self.config.host if direction == "host" else self.config.unit
        if not cfg.active:
            return [(t, data)]
        rng = self.rng
        out = bytearray()
        if cfg.garble:
            data = self._garble(data, cfg.garble)
        for b in data:
            if cfg.drop and rng.random() < cfg.drop:
                self.counts["dropped"] += 1
                continue
            if cfg.corrupt and rng.random() < cfg.corrupt:
                b ^= 1 << rng.randrange(8)
                self.counts["corrupted"] += 1
            out.append(b)
        if not out:
            return []
        lo, hi = cfg.latency
        delay = rng.uniform(lo, hi) if hi > lo else lo
        due = t + delay
        if due < self._last[direction]:
            due = self._last[direction]  # a converter keeps the order of its transfers
        self._last[direction] = due
        return [(due, bytes(out))]

    def _garble(self, data: bytes, p: float) -> bytes:
        pieces = data.split(b"\r")
        for i, piece in enumerate(pieces[:-1] if len(pieces) > 1 else pieces):
            if piece and self.rng.random() < p:
                start = self.rng.randrange(len(piece))
                end = self.rng.randrange(start, len(piece)) + 1
                noise = bytes(self.rng.choice(b"!#%&*+-./0123456789:;?@ABCDEFXYZ\x00\x7f\xff")
                              for _ in range(end - start))
                pieces[i] = piece[:start] + noise + piece[end:]
                self.counts["garbled"] += 1
        return b"\r".join(pieces)

    def next_disconnect(self) -> float | None:
        """When the link drops next (None when disconnects are off)."""
        return None if self._next_drop == float("inf") else self._next_drop

    def disconnect_due(self, t: float) -> bool:
        """True once per scheduled disconnect, at or after its time; the link is then down
        (every byte lost) until ``t + downtime``."""
        if t < self._next_drop:
            return False
        self.counts["disconnects"] += 1
        self.down_until = t + self.config.downtime
        self._next_drop = self._schedule(self.down_until)
        return True


class FaultyEndpoint:
    """Wrap an ``Endpoint`` so that what passes through it suffers ``injector``'s faults.

    ``side`` says whose port this is: ``"host"`` (a sender's port: writes go in the host
    direction, reads are answers) or ``"unit"`` (the emulator's: the reverse). Delayed bytes
    are delivered by later ``read``/``write``/``flush`` calls, so a caller that keeps reading
    (as every sender does while it waits for an answer) sees them on time. A disconnect makes
    the link deaf for the downtime and is reported to ``on_event("disconnect"/"reconnect")``.
    """

    def __init__(self, inner, injector: FaultInjector, *, side: str = "host",
                 clock: Callable[[], float] = time.monotonic,
                 on_event: Callable[[str, str], None] | None = None) -> None:
        if side not in DIRECTIONS:
            raise ValueError(f"side must be 'host' or 'unit', not {side!r}")
        self.inner = inner
        self.injector = injector
        self.clock = clock
        self.on_event = on_event
        self._out_dir = side
        self._in_dir = "unit" if side == "host" else "host"
        self._outgoing: list[tuple[float, bytes]] = []
        self._incoming: list[tuple[float, bytes]] = []
        self._down = False

    @property
    def name(self) -> str:
        return f"{self.inner.name} (faults)"

    def _check_link(self, now: float) -> None:
        if self.injector.disconnect_due(now):
            self._down = True
            self._outgoing.clear()
            self._incoming.clear()
            if self.on_event:
                self.on_event("disconnect", "fault injection: link down")
        elif self._down and now >= self.injector.down_until:
            self._down = False
            if self.on_event:
                self.on_event("reconnect", "fault injection: link up")

    def flush(self) -> None:
        """Send the delayed outgoing bytes that are due."""
        now = self.clock()
        self._check_link(now)
        while self._outgoing and self._outgoing[0][0] <= now:
            self.inner.write(self._outgoing.pop(0)[1])

    def write(self, data: bytes) -> None:
        now = self.clock()
        self._check_link(now)
        self._outgoing.extend(self.injector.feed(self._out_dir, data, now))
        self.flush()

    def read(self, max_bytes: int = 4096, timeout: float | None = 0.1) -> bytes:
        deadline = None if timeout is None else self.clock() + timeout
        while True:
            self.flush()
            now = self.clock()
            if self._incoming and self._incoming[0][0] <= now:
                data = bytearray()
                while self._incoming and self._incoming[0][0] <= now and len(data) < max_bytes:
                    data += self._incoming.pop(0)[1]
                return bytes(data)
            wake = [deadline] if deadline is not None else []
            for q in (self._outgoing, self._incoming):
                if q:
                    wake.append(q[0][0])
            wait = max(0.0, min(wake) - now) if wake else None
            got = self.inner.read(max_bytes, wait if wait is None else min(wait, 0.05))
            now = self.clock()
            if got:
                self._incoming.extend(self.injector.feed(self._in_dir, got, now))
            elif deadline is not None and now >= deadline and not (
                    self._incoming and self._incoming[0][0] <= now):
                return b""

    def close(self) -> None:
        self.inner.close()
