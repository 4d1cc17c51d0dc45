"""Targets a conformance run talks to: a family's reference unit in-process on a virtual clock,
or anything pyserial opens (device path, pty, ``socket://``, ``rfc2217://``) on the wall clock.

Both offer the same small interface — ``send(data)``, ``exchange(line)`` returning a
:class:`Reply` with the answer lines and timestamps, ``wait(s)``, ``reset()``, ``set_input()`` —
and keep a raw tx/rx log with timestamps. The checks never know which kind they drive, except
through ``emulated``. Nothing here knows a protocol: a family adds its framing, reset and halt in
subclasses (GVE: ``conform.families.gve.conformance.target``), and a :class:`Guard` decides what
may be sent.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from conform.conformance.results import LogEntry
from conform.errors import LinkError, UserError

if TYPE_CHECKING:
    from conform.link.endpoint import Endpoint

DEFAULT_TIMEOUT = 0.5


class HarnessError(Exception):
    """The harness or the link failed (graded ERROR, never the unit's fault)."""


class LinkSilent(HarnessError):
    """Nothing comes back any more: the link is lost (a unit would answer something)."""


class Guard(Protocol):
    """What a target asks before it sends bytes to a unit (a family's safety rules)."""

    allow_motion: bool

    def check(self, line: bytes, idle: bool = False) -> None:
        """Raise (a ``SafetyRefusal``) when ``line`` may not be sent."""

    def moves(self, line: bytes) -> bool:
        """Does ``line`` set the machine moving (the host no longer knows it idle)?"""


class Unguarded:
    """Everything may be sent (an in-process unit; a family that gates its checks itself)."""

    allow_motion = True

    def check(self, line: bytes, idle: bool = False) -> None:
        return None

    def moves(self, line: bytes) -> bool:
        return False


@dataclass
class Reply:
    """What came back for one line sent."""

    tx: bytes
    t_tx: float
    lines: list[bytes] = field(default_factory=list)  # complete lines, without their CR
    partial: bytes = b""  # bytes of an unterminated line when the wait ended
    t_rx: float | None = None
    stray: bytes = b""  # bytes that came unasked before this line was sent
    moving: bool = False  # the (reference) unit was moving when it answered

    @property
    def silent(self) -> bool:
        return not self.lines and not self.partial

    def text(self) -> str:
        """The answer as a reader sees it: ``0,5C``; ``(silence)``; a cut line with its bytes."""
        parts = [ln.decode("latin-1") for ln in self.lines]
        if self.partial:
            parts.append(f"{self.partial.decode('latin-1')} (no CR)")
        return " | ".join(parts) if parts else "(silence)"



class Target(ABC):
    """One unit behind a link (or in-process). Subclasses move the bytes and tell the time."""

    name: str = "target"
    emulated: bool = False
    baud: int = 115200

    eol = b"\r"  # what ends an answer line for ``exchange``

    def __init__(self, guard: Guard | None = None) -> None:
        self.guard: Guard = guard if guard is not None else Unguarded()
        self.log: list[LogEntry] = []
        self._buffer = b""
        self.t_log0 = 0.0
        # the host knows nothing moves and the queue is empty (read back after reaching a
        # check's state; nothing that moves sent since): G has nothing to start
        self.idle = False

    # -- what subclasses provide ------------------------------------------------------------
    @abstractmethod
    def now(self) -> float:
        """Seconds on this target's clock."""

    @abstractmethod
    def _write(self, data: bytes) -> None: ...

    @abstractmethod
    def _read(self, deadline: float) -> bytes:
        """Bytes that arrive before ``deadline`` (returns early as soon as some do)."""

    @abstractmethod
    def wait(self, seconds: float) -> None: ...

    def _fresh(self) -> None:
        """Return the unit to its power-up state (emulator: a new unit)."""
        raise HarnessError(f"{self.name}: reset is not available")

    def set_input(self, port: int, bit: int, active: bool) -> None:
        raise HarnessError(f"{self.name}: inputs can only be driven on the emulator")

    def close(self) -> None:  # noqa: B027 - nothing to release by default
        pass

    def state(self) -> dict[str, object]:
        """Internal state for reports (emulator only)."""
        return {}

    # -- shared behaviour --------------------------------------------------------------------
    def reset(self) -> None:
        self._fresh()
        self._buffer = b""

    @property
    def drives_inputs(self) -> bool:
        """Can the harness switch this unit's inputs (``set_input``)?"""
        return self.emulated

    def prepare(self, script: object) -> None:
        """Reach the state ``script`` starts from (its reset step): by default a reset."""
        self.reset()

    def ready_wait(self, seconds: float) -> float:
        """How long to wait for the unit to hear again after J (a script asked ``seconds``)."""
        return seconds

    def resync(self) -> bytes:
        """Drop whatever is pending so the next exchange starts clean; returns it."""
        return self.drain()

    def begin_log(self, keep: bool = False) -> None:
        """Times from now on count from here; ``keep`` the entries so far (negative times)."""
        t = self.now()
        if keep:
            for e in self.log:
                e.t -= t - self.t_log0
        else:
            self.log = []
        self.t_log0 = t

    def _note(self, direction: str, data: bytes) -> None:
        self.log.append(LogEntry(self.now() - self.t_log0, direction, data))

    def drain(self) -> bytes:
        """Whatever the unit sent unasked (MPG reports, late lines); logged as rx."""
        new = self._read(self.now())
        if new:
            self._note("rx", new)
        data = self._buffer + new
        self._buffer = b""
        return data

    def receive(self, deadline: float) -> bytes:
        """Bytes that arrive before ``deadline`` (as soon as some do), logged as rx: for
        families that frame the stream themselves (grbl) instead of ``exchange``."""
        data = self._read(deadline)
        if data:
            self._note("rx", data)
        return data

    def send(self, data: bytes) -> tuple[float, bytes]:
        """Send bytes without waiting for an answer; returns the time and what came unasked."""
        self.guard.check(data, idle=self.idle)
        if self.guard.moves(data):
            self.idle = False
        stray = self.drain()
        t = self.now()
        self._note("tx", data)
        self._write(data)
        return t, stray

    def exchange(self, line: bytes, timeout: float = DEFAULT_TIMEOUT, lines: int = 1,
                 linger: float = 0.05) -> Reply:
        """Send ``line``; collect ``lines`` lines (ended by ``eol``), or what came by ``timeout``.

        Once one line is in, further lines are waited for at most ``linger`` seconds.
        """
        t_tx, stray = self.send(line)
        reply = Reply(line, t_tx - self.t_log0, stray=stray)
        deadline = self.now() + timeout
        buf = b""
        while True:
            if reply.lines and len(reply.lines) < lines:
                deadline = min(deadline, self.now() + linger)
            chunk = self._read(deadline)
            if chunk:
                self._note("rx", chunk)
                buf += chunk
                while self.eol in buf and len(reply.lines) < lines:
                    head, _, buf = buf.partition(self.eol)
                    reply.lines.append(head)
                    reply.t_rx = self.now() - self.t_log0
                if len(reply.lines) >= lines:
                    break
            elif self.now() >= deadline:
                break
        if buf:
            if len(reply.lines) >= lines:
                self._buffer = buf
            else:
                reply.partial = buf
                reply.t_rx = self.now() - self.t_log0
        self.exchanged(line, reply)
        return reply

    def exchanged(self, line: bytes, reply: Reply) -> None:  # noqa: B027 - a hook
        """What the host learns from an exchange (a family tracks its framing state here)."""


class EmuTarget(Target):
    """A sans-I/O unit in-process, on a virtual clock: ``receive(data, t)``, ``poll(t)``,
    ``next_deadline()`` and, for ``set_input``, ``set_input(port, bit, active, t)``."""

    emulated = True

    def __init__(self, factory: Callable[[], Any], name: str, guard: Guard | None = None,
                 baud: int = 115200) -> None:
        super().__init__(guard)
        self.factory = factory
        self.name = name
        self.baud = baud
        self.unit = factory()
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def _wire(self, n: int) -> float:
        return n * 10.0 / self.baud

    def _fresh(self) -> None:
        self.unit = self.factory()
        self.t = 0.0

    def _write(self, data: bytes) -> None:
        self.t += self._wire(len(data))
        self.unit.receive(data, self.t)

    def _read(self, deadline: float) -> bytes:
        out = bytearray()
        idle = 0
        while True:
            for due, data in self.unit.poll(self.t):
                self.t = max(self.t, due)
                out += data
            if out:
                self.t += self._wire(len(out))
                return bytes(out)
            nxt = self.unit.next_deadline()
            if nxt is None or nxt > deadline:
                self.t = max(self.t, deadline)
                return b""
            if nxt <= self.t:
                # poll(t) at the unit's own "now" may not run what is due then: nudge time
                idle += 1
                if idle > 5:
                    raise HarnessError(f"{self.name}: unit deadline stuck at t={nxt}")
                self.t += 1e-9
                continue
            self.t = max(self.t, nxt)

    def wait(self, seconds: float) -> None:
        end = self.t + seconds
        while self.t < end:
            data = self._read(end)
            if not data:
                break
            self._note("rx", data)
            self._buffer += data
        self.t = max(self.t, end)

    def set_input(self, port: int, bit: int, active: bool) -> None:
        self.unit.set_input(port, bit, active, self.t)


class LinkTarget(Target):
    """A unit behind a serial port, pty or network URL, on the wall clock."""

    emulated = False

    def __init__(self, endpoint: Endpoint, name: str, guard: Guard | None, baud: int) -> None:
        super().__init__(guard)
        self.endpoint = endpoint
        self.name = name
        self.baud = baud
        self._t0 = time.monotonic()
        self.inputs: str | None = None  # an emulator's control socket that drives its inputs

    @property
    def drives_inputs(self) -> bool:
        return self.inputs is not None

    def set_input(self, port: int, bit: int, active: bool) -> None:
        """Inputs of an emulator behind the link, through its control socket (``inputs``)."""
        if self.inputs is None:
            return super().set_input(port, bit, active)
        from conform.emulator.control import send_control

        word = "press" if active else "release"
        try:
            reply = send_control(self.inputs, f"{word} {port}.{bit}")
        except OSError as exc:
            raise HarnessError(f"--inputs-control {self.inputs}: {exc}") from None
        self._note("note", f"input {port}.{bit} {word}: {reply}".encode())
        if not reply.startswith("ok"):
            raise HarnessError(f"--inputs-control {self.inputs}: {reply}")

    def now(self) -> float:
        return time.monotonic() - self._t0

    def _write(self, data: bytes) -> None:
        try:
            self.endpoint.write(data)
        except LinkError as exc:
            raise HarnessError(f"{self.name}: {exc}") from None

    def _read(self, deadline: float) -> bytes:
        left = max(0.0, deadline - self.now())
        try:
            return self.endpoint.read(4096, left)
        except LinkError as exc:
            raise HarnessError(f"{self.name}: {exc}") from None

    def wait(self, seconds: float) -> None:
        end = self.now() + seconds
        while self.now() < end:
            data = self._read(end)
            if data:
                self._note("rx", data)
                self._buffer += data

    def close(self) -> None:
        self.endpoint.close()


def parse_target(text: str) -> tuple[str, str | None, str | None]:
    """``emu:gve64-v10`` → ("emu", "gve64-v10", None); ``emu:gve64-v19:queue-short`` names a
    mutant (a family's deviant unit); anything else is a port (kind ``link``)."""
    if text == "emu" or text.startswith("emu:"):
        parts = text.split(":")
        variant = parts[1] if len(parts) > 1 and parts[1] else None
        mutant = parts[2] if len(parts) > 2 and parts[2] else None
        if len(parts) > 3:
            raise UserError(f"target {text!r}: expected emu:VARIANT[:MUTANT]")
        return "emu", variant, mutant
    return "link", text, None


def open_link(port: str, *, baud: int = 115200, guard: Guard | None = None,
              timeout: float = 0.1) -> LinkTarget:
    """A unit behind a device path, pty or pyserial URL."""
    from conform.link import open_port

    return LinkTarget(open_port(port, baud, timeout), port, guard, baud)
